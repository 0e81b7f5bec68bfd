#include "sim/engine.h"

#include <fmt/format.h>

#include <algorithm>
#include <stdexcept>

#include "core/error.h"

namespace edrnr::sim::engine {

// The units' steps are inline: the cycle loop runs them every cycle.

namespace {

// With two threads, how many front-end packets the worker may build ahead.
constexpr size_t kFrontEndAheadPackets = 64;

}  // namespace

Engine::Engine(const SceneModel& model, const Camera& camera, const SimConfig& config, const SimOptions& options,
               SimResult& result)
    : model_(model),
      cfg_(config),
      t_(config.timing),
      opt_(options),
      res_(result),
      stats_(*result.stats),
      n_(config.chip.numerics),
      delta_(double(config.chip.step_micro) * double(model.scene_box.size().x) / double(model.micro_res)),
      math_(n_.traversal_float, config.chip.step_micro, model.micro_res),
      zorg_(camera.width, camera.height, config.chip.switches.z_order ? ScanOrder::ZOrder : ScanOrder::RowOrder),
      front_(model, camera, n_, math_, config.chip.switches.aabb),
      buffer_(config.chip.rp_buffer_capacity),
      ctu_(model, math_, config.chip.switches.lag_first),
      rob_(RpRobConfig{config.chip.rp_rob.entries, config.chip.rp_rob.entry_depth, config.chip.rp_rob.recent_tags,
                       config.chip.switches.rp_reorder, config.chip.rp_rob.tag_switch,
                       config.chip.rp_rob.switch_when_idle}),
      ftu_(model, math_, config.chip.switches.lag_first, 0),
      micro_lru_(size_t(config.chip.micro_grid_cache_bytes / 8)),
      ooo_(config.chip.ooo_queue_depth, config.chip.switches.ooo_issue),
      cfiu_(model, n_,
            FeatureCacheConfig{feature_cache_lines(config.chip, model.feature_channels), config.chip.mshr_entries,
                               config.chip.bank_mapping}),
      arithmetic_(model, config.chip, n_, math_, cfiu_, delta_),
      vru_(n_, config.chip.transmittance_min, config.chip.background),
      image_(camera.width, camera.height, 3),
      mlp_bytes_(model.mlp_count() ? arithmetic_.tme().mlp(0).stored_bytes : 0),
      map_(make_address_map(model, mlp_bytes_, config.memory.mlp_cache.line_bytes, zorg_.packet_count(),
                            config.memory.output_record_bytes, config.memory.dram.capacity_bytes())),
      mem_(config.memory.dram, config.clock_MHz, config.memory.max_request_bytes, map_, stats_),
      micro_cache_(make_cache_config(config.memory.micro_grid_cache, "micro_grid", config.chip.micro_grid_cache_bytes,
                                     config.hit_rate_window_cycles)),
      mlp_cache_(make_cache_config(config.memory.mlp_cache, "mlp_weights", config.chip.mlp_cache_bytes,
                                   config.hit_rate_window_cycles)),
      feature_series_(config.hit_rate_window_cycles),
      mlp_series_(config.hit_rate_window_cycles),
      activity_(std::vector<std::string>(kUnitNames, kUnitNames + kUnits), options.trace_start_cycle,
                options.trace_cycles, options.trace_max_events),
      rp_capacity_(size_t(config.chip.rp_buffer_capacity)),
      fe_out_("front_end_to_ctu", size_t(t_.front_end_latency_cycles) + 1, uint64_t(t_.front_end_latency_cycles)),
      retire_q_("retire_to_ctu", rp_capacity_, 1),
      tme_in_("cfiu_to_tme", size_t(t_.cfiu_latency_cycles + t_.cfiu_fifo_slots), uint64_t(t_.cfiu_latency_cycles)),
      vru_in_("tme_to_vru", size_t(t_.tme_latency_cycles + t_.tme_fifo_slots), uint64_t(t_.tme_latency_cycles)),
      done_q_("vru_decisions", rp_capacity_, uint64_t(t_.vru_latency_cycles)),
      batches_(size_t(config.chip.ooo_queue_depth) + 1),
      flights_(rp_capacity_),
      sequence_(rp_capacity_) {
  if (cfiu_.cache().lines() <= config.chip.ooo_queue_depth)
    fail("chip config: the feature cache's {} lines must outnumber the {} OoO-SI entries that reserve them",
         cfiu_.cache().lines(), config.chip.ooo_queue_depth);
  for (uint32_t i = 0; i < uint32_t(batches_.size()); ++i) free_slots_.push_back(i);
  front_.set_encode_directions(false);  // the batch arithmetic encodes (on its thread with threads = 2)
  mem_.set_request_observer(options.dram_request_observer);
  mlp_lines_ = ceil_div(mlp_bytes_, cfg_.memory.mlp_cache.line_bytes);
  uint64_t macs = 0, neurons = 0;
  if (model.mlp_count()) {
    for (const auto* net : {&arithmetic_.tme().mlp(0).density, &arithmetic_.tme().mlp(0).color})
      for (const TmeLayer& L : *net) {
        macs += uint64_t(L.in) * uint64_t(L.out);
        neurons += uint64_t(L.out);
      }
    // The first colour layer also requantizes its direction partial sums.
    if (!arithmetic_.tme().mlp(0).color.empty()) neurons += uint64_t(arithmetic_.tme().mlp(0).color.front().out);
  }
  macs_per_sample_ = macs;
  neurons_per_sample_ = neurons;
  tme_cycles_per_sample_ = std::max<uint64_t>(1, ceil_div(macs, uint64_t(t_.tme_macs_per_cycle)));
  if (options.threads > 1) {
    ahead_ = std::make_unique<FrontEndAhead>(zorg_, front_, vru_, kFrontEndAheadPackets);
    ftu_ahead_ = std::make_unique<FtuAhead>(model, math_, config.chip.switches.lag_first, buffer_, arithmetic_);
    worker_ = std::make_unique<Worker>(arithmetic_, buffer_, flights_, rp_capacity_, ahead_.get(), ftu_ahead_.get());
    main_arithmetic_ = std::make_unique<BatchArithmetic>(model, config.chip, n_, math_, cfiu_, delta_);
  }
}

void Engine::run() {
  if (cfg_.memory.preload_bitmaps && map_.bitmap_bytes > 0)
    mem_.read(DataType::Bitmaps, map_.base[0], uint32_t(map_.bitmap_bytes), 0, 0);
  else
    bitmaps_ready_ = true;
  uint64_t quiet = 0, next_progress = opt_.progress_interval_cycles;
  for (cycle_ = 0;; ++cycle_) {
    any_busy_ = false;
    step_vru();
    step_tme();
    step_cfiu();
    step_issue();
    step_ftu();
    step_ctu();
    step_front_end();
    completions_.clear();
    mem_.advance(cycle_, completions_);
    for (const MemoryCompletion& c : completions_) deliver(c);
    retry_fills();
    if (zorg_.done() && !fe_.holding && buffer_.in_use() == 0 && mem_.idle()) break;
    quiet = (any_busy_ || !mem_.idle()) ? 0 : quiet + 1;
    if (quiet > opt_.deadlock_cycles)
      throw std::logic_error(fmt::format(
          "cycle simulator: nothing moved for {} cycles at cycle {} ({} RPs in flight, RP-ROB {} placeholders, "
          "OoO-SI {} entries)",
          quiet, cycle_, buffer_.in_use(), rob_.placeholders(), ooo_.size()));
    if (opt_.progress && cycle_ + 1 >= next_progress) {
      opt_.progress({cycle_ + 1, rps_done_, zorg_.packet_count()});
      next_progress += opt_.progress_interval_cycles;
    }
    // Cycles in which no unit can act are counted, not run; the memory runs
    // through them and a transfer completing ends them. The deadlock and
    // progress checks still fall on the cycles they would.
    uint64_t until = opt_.skip_quiet_cycles ? quiet_until(cycle_) : cycle_ + 1;
    if (until > cycle_ + 1) {
      bool units_busy = false;
      for (UnitState q : quiet_state_) units_busy |= q == UnitState::Busy;
      const bool mem_busy = !mem_.idle();
      if (!units_busy && !mem_busy) until = std::min(until, cycle_ + 1 + (opt_.deadlock_cycles - quiet));
      if (opt_.progress) until = std::min(until, std::max(next_progress - 1, cycle_ + 1));
      if (until > cycle_ + 1) {
        const uint64_t first = cycle_ + 1;
        completions_.clear();
        const uint64_t last = mem_.advance_through(first, until - 1, completions_);
        skip(first, last + 1 - first);
        cycle_ = last;
        // Quiet cycles: those with no unit busy and no transfer in flight at their end.
        quiet = units_busy || !mem_.idle() ? 0 : mem_busy ? 1 : quiet + (last + 1 - first);
        for (const MemoryCompletion& c : completions_) deliver(c);
        retry_fills();
        if (zorg_.done() && !fe_.holding && buffer_.in_use() == 0 && mem_.idle()) break;
      }
    }
  }
  cycles_ = cycle_ + 1;
  mem_.sync();  // the DRAM's idle clocks through the last cycle
  if (opt_.progress) opt_.progress({cycles_, rps_done_, zorg_.packet_count()});
  activity_.finish();
  worker_.reset();
  finish_result();
}

inline void Engine::set_state(Unit u, UnitState s) {
  any_busy_ |= s == UnitState::Busy;
  activity_.set(u, s, cycle_);
}

// ZORG, ABT and TSPS: one RP at a time; its pointer is allocated when it leaves.
inline void Engine::step_front_end() {
  const uint64_t c = cycle_;
  UnitState st = UnitState::Idle;
  if (fe_.holding && c >= fe_.end) {
    if (!fe_.live) {  // background only: no pointer needed
      ++packets_dropped_;
      write_pixels(*fe_.packet.packet);
      write_output_record(fe_.sequence);
      ++rps_done_;
      fe_.holding = false;
    } else if (buffer_.full() || !fe_out_.can_push()) {
      st = UnitState::StallOutput;
    } else {
      const uint32_t rp = *buffer_.allocate();
      buffer_.exchange(rp, fe_.packet.packet);  // the slot's old packet is built in next
      sequence_[rp] = fe_.sequence;
      fe_out_.push(rp, c);
      fe_.holding = false;
    }
  }
  if (!fe_.holding && !zorg_.done()) {
    const PixelQuad quad = zorg_.next();
    uint64_t evals = 0;
    if (worker_) {  // built ahead on the worker thread, in the same order
      FrontEndPacket& e = fe_.packet;
      worker_->take_packet(e);
      if (e.quad.sequence != quad.sequence)
        throw std::logic_error(
            fmt::format("cycle simulator: front-end packet {} arrived for quad {}", e.quad.sequence, quad.sequence));
      evals = e.tsps_position_evals;
    } else {
      const uint64_t before = front_.tsps_position_evals();
      front_.build(quad, vru_, *fe_.packet.packet);
      evals = front_.tsps_position_evals() - before;
    }
    const uint64_t tsps_cycles = ceil_div(evals, uint64_t(t_.tsps_position_evals_per_cycle));
    fe_.end = c + std::max<uint64_t>(uint64_t(t_.zorg_cycles_per_rp), tsps_cycles);
    fe_.sequence = quad.sequence;
    fe_.live = fe_.packet.packet->live_mask() != 0;
    fe_.holding = true;
  }
  if (fe_.holding && c < fe_.end) st = UnitState::Busy;
  set_state(kFrontEnd, st);
}

// CTU: coarse traversal of one RP at a time; CV transitions first, then new RPs.
inline void Engine::step_ctu() {
  const uint64_t c = cycle_;
  UnitState st = UnitState::Idle;
  if (ctu_s_.holding && c >= ctu_s_.end) {
    if (!ctu_s_.result.found) {
      finish(ctu_s_.rp);
      ctu_s_.holding = false;
    } else if (rob_.insert(ctu_s_.rp, ctu_s_.result.cv_tag)) {
      ctu_s_.holding = false;
    } else {
      st = UnitState::StallOutput;
    }
  }
  if (!ctu_s_.holding) {
    Fifo<uint32_t>* in = retire_q_.can_pop(c) ? &retire_q_ : fe_out_.can_pop(c) ? &fe_out_ : nullptr;
    if (in && !bitmaps_ready_) {
      st = UnitState::StallMemory;
    } else if (in) {
      const uint32_t rp = in->pop(c);
      const CtuCounters before = ctu_.counters();
      ctu_s_.result = ctu_.run(buffer_[rp]);
      if (ftu_ahead_ && ctu_s_.result.found) {  // the RP's rays are final for its first FTU run in the CV
        ftu_ahead_->pend(rp, ctu_s_.result.cv_tag);
        if (ftu_ahead_->needs_job(rp)) worker_->submit_ftu(rp);
      }
      const CtuCounters& after = ctu_.counters();
      const uint64_t cycles = (after.iterations - before.iterations) * uint64_t(t_.ctu_cycles_per_iteration);
      ctu_s_.rp = rp;
      ctu_s_.end = c + std::max<uint64_t>(1, cycles);
      ctu_s_.holding = true;
      ++ctu_runs_;
    }
  }
  if (ctu_s_.holding && c < ctu_s_.end) st = UnitState::Busy;
  set_state(kCtu, st);
}

// FTU: one CCRP at a time from the RP-ROB; its micro-grid words come
// through the micro-grid cache; its batch goes to the OoO-SI, which asks the
// CFIU to prefetch the feature block.
inline void Engine::step_ftu() {
  const uint64_t c = cycle_;
  UnitState st = UnitState::Idle;
  FtuShell& s = ftu_s_;
  if (s.holding && s.output) {
    if (s.has_batch) {
      if (ooo_.full()) {
        st = UnitState::StallOutput;
      } else {
        const uint32_t block = uint32_t(batches_[s.slot].block);
        const CacheAccess a = cfiu_.cache().request(block);
        if (a == CacheAccess::Stall) {
          st = UnitState::StallMemory;  // no MSHR entry or no line free
        } else {
          feature_series_.record(c, a == CacheAccess::Hit);
          count_per_access(feature_access_, a == CacheAccess::Hit, flights_[s.rp].samples.size());
          if (a == CacheAccess::MissAllocated)
            mem_.read(DataType::Features, map_.feature_block(block), uint32_t(map_.feature_block_bytes), block, c);
          ooo_.push({s.rp, block, s.slot});
          start_batch(s.rp, s.slot);
          s.holding = false;
        }
      }
    } else {
      free_slots_.push_back(s.slot);
      leave_cv(s.rp);
      s.holding = false;
    }
  }
  if (!s.holding && bitmaps_ready_) {
    if (free_slots_.empty()) {
      if (!rob_.empty()) st = UnitState::StallOutput;
    } else if (ScheduledRp sched; rob_.schedule(sched)) {
      if (cfg_.memory.mlp_prefetch && (!prefetch_started_ || sched.tag != prefetch_tag_)) start_mlp_prefetch(sched.tag);
      s.rp = sched.rp;
      s.slot = free_slots_.back();
      free_slots_.pop_back();
      FtuRun* run = &ftu_run_;
      if (ftu_ahead_)
        run = &ftu_ahead_->take(sched.rp, sched.tag, ftu_);
      else
        run_ftu(ftu_, buffer_[sched.rp], sched.rp, sched.tag, ftu_run_);
      s.has_batch = run->has_batch;
      std::swap(batches_[s.slot], run->batch);
      // The RP's flight is free (its previous batch is complete): the batch's
      // samples, or its whole flight when the worker made its arithmetic.
      Flight& f = flights_[sched.rp];
      Flight* made = ftu_ahead_ ? ftu_ahead_->made_flight(sched.rp) : nullptr;
      if (made)
        std::swap(f, *made);
      else if (s.has_batch)
        std::swap(f.samples, batches_[s.slot].samples);
      f.made = made != nullptr;
      const FtuCounters& d = run->counts;
      ftu_counts_ += d;
      const uint64_t cycles = d.iterations * uint64_t(t_.ftu_cycles_per_iteration) +
                              ceil_div(d.leaf_checks + d.candidate_tests, uint64_t(t_.ftu_lanes));
      s.end = c + std::max<uint64_t>(1, cycles);
      s.reads.clear();
      // The micro-grid bitmap cache's hits, counted in the order the runs are scheduled.
      for (uint32_t f : run->micro_log) {
        ftu_counts_.micro_word_hits += micro_lru_.access(f);
        s.reads.push_back(map_.micro_word(uint32_t(model_.fine_to_block[f])));
      }
      s.next_read = 0;
      s.ready = c;
      s.holding = true;
      s.output = false;
      ++ftu_runs_;
      if (made && f.stay) {  // the rays are final for the RP's next run in the CV: the worker may make it now
        ftu_ahead_->pend(sched.rp, f.cv_tag);
        if (ftu_ahead_->needs_job(sched.rp)) worker_->submit_ftu(sched.rp);
      }
    }
  }
  if (s.holding && !s.output) {
    // One micro-grid word request per cycle.
    if (s.next_read < s.reads.size()) {
      const uint64_t addr = s.reads[s.next_read];
      switch (micro_cache_.access(addr, c)) {
        case CacheOutcome::Hit:
          s.ready = std::max(s.ready, c + cfg_.memory.micro_grid_cache.hit_latency_cycles);
          ++s.next_read;
          break;
        case CacheOutcome::MissIssued:
          mem_.read(DataType::MicroGrid, line_start(micro_cache_, addr),
                    uint32_t(cfg_.memory.micro_grid_cache.line_bytes), addr, c);
          [[fallthrough]];
        case CacheOutcome::MissMerged:
          micro_cache_.reserve(addr);
          s.waiting.push_back(addr);
          ++s.next_read;
          break;
        case CacheOutcome::MissStalled:
          break;
      }
    }
    const bool arrived = take_arrived(micro_cache_, s.waiting);
    if (arrived && s.next_read == s.reads.size() && c >= s.ready && c + 1 >= s.end)
      s.output = true;  // hands its result on next cycle
    st = c < s.end ? UnitState::Busy : UnitState::StallMemory;
  }
  set_state(kFtu, st);
}

// OoO-SI: issues the oldest batch whose block is on chip to the CFIU. The
// batch's work is done now; its timing follows.
inline void Engine::step_issue() {
  UnitState st = UnitState::Idle;
  if (!ooo_.empty()) {
    if (cfiu_s_.active) {
      st = UnitState::StallOutput;
    } else if (const auto pos = ooo_.select(cfiu_.cache())) {
      const LsEntry e = ooo_.take(*pos);
      issue(e);
      st = UnitState::Busy;
    } else {
      st = UnitState::StallMemory;
    }
  }
  set_state(kOooSi, st);
}

// The batch's arithmetic starts as soon as it exists: it depends only on
// the samples, the model and its RP's rays, and the RP has no other batch
// in flight. On one thread it is deferred until a batch's results are
// needed (complete_batch), so that the deferred batches of one MLP run
// through the TME together. The sample coordinates are computed here when
// the CFIU's bank reads at issue need them, else by the job (on the worker,
// with two threads: the timing thread then touches none of them).
inline void Engine::start_batch(uint32_t rp, uint32_t slot) {
  const SampleBatch& batch = batches_[slot];
  Flight& f = flights_[rp];
  f.slot = slot;
  if (worker_) count_mlp_load(batch.cv_tag);  // the worker's arithmetic counts none
  if (f.made) return;                         // its arithmetic is done
  f.block = uint32_t(batch.block);
  f.cv_tag = batch.cv_tag;
  f.coords_made = false;
  if (cfiu_.corners_can_conflict()) make_coords(math_, n_, buffer_[rp], f);
  if (worker_)
    f.job = worker_->submit(rp);
  else
    arithmetic_.defer(buffer_[rp], f);
}

// The CFIU reads the corners of each sample from the banks now; bank
// conflicts lengthen its samples.
inline void Engine::issue(const LsEntry& e) {
  Flight& f = flights_[e.rp];
  f.sample_cycles.clear();
  const bool can_conflict = cfiu_.corners_can_conflict();  // then the coordinates are made (start_batch, or made)
  for (size_t i = 0; i < f.samples.size(); ++i) {
    const int conflicts = cfiu_.read_corners(e.block, can_conflict ? f.coords[i].local : Vec3i{});
    f.sample_cycles.push_back(uint8_t(std::min(255, t_.cfiu_cycles_per_sample + conflicts)));
  }
  cfiu_s_ = {true, e.rp, 0, f.sample_cycles[0], cycle_ + 1};
  early_mlp_load(f.cv_tag);
}

// CFIU: streams the issued batch's samples into the TME's queue.
inline void Engine::step_cfiu() {
  UnitState st = UnitState::Idle;
  CfiuShell& s = cfiu_s_;
  if (s.active && cycle_ >= s.start) {
    Flight& f = flights_[s.rp];
    if (s.left > 1) {
      --s.left;
      st = UnitState::Busy;
    } else if (!tme_in_.can_push()) {
      st = UnitState::StallOutput;
    } else {
      const uint32_t n = uint32_t(f.sample_cycles.size());
      tme_in_.push({s.rp, s.next == 0, s.next + 1 == n}, cycle_);
      st = UnitState::Busy;
      if (++s.next == n) {
        cfiu_.cache().release(f.block);
        free_slots_.push_back(f.slot);
        s.active = false;
      } else {
        s.left = f.sample_cycles[s.next];
      }
    }
  }
  set_state(kCfiu, st);
}

// TME: the MLP of the batch's CV must be in the MAC array. A load copies it
// from the MLP cache (missing lines from DRAM) into a weight buffer. With one
// buffer the load starts when the batch reaches the head of the TME's queue
// and stops the TME; with two, it starts into the shadow buffer as soon as
// the OoO-SI issues the batch, and the buffers swap when the batch arrives.
inline void Engine::step_tme() {
  const uint64_t c = cycle_;
  UnitState st = UnitState::Idle;
  TmeShell& s = tme_s_;
  issue_mlp_prefetch(c);
  if (s.holding && s.left == 0) {
    if (vru_in_.can_push()) {
      vru_in_.push(s.token, c);
      s.holding = false;
    } else {
      st = UnitState::StallOutput;
    }
  }
  bool waiting_for_weights = false;
  if (!s.holding && tme_in_.can_pop(c)) {
    const SampleToken& next = tme_in_.front();
    const uint32_t tag = flights_[next.rp].cv_tag;
    bool ready = true;
    if (next.first && (!s.active || s.active_tag != tag)) {
      if (s.shadow_ready && s.shadow_tag == tag) {
        s.active = true;  // swap: the loaded buffer becomes the active one
        s.active_tag = tag;
        s.shadow_ready = false;
        count_mlp_batch(next, s.shadow_on_chip);
      } else {
        if (!s.loading) start_mlp_load(tag, c);
        ready = false;  // wait for the load (of this tag, or the one under way)
      }
    } else if (next.first) {
      count_mlp_batch(next, true);  // its MLP is in the MAC array
    }
    if (ready) {
      s.token = tme_in_.pop(c);
      s.holding = true;
      s.left = tme_cycles_per_sample_;
    } else {
      waiting_for_weights = true;
    }
  }
  if (s.loading) {
    while (s.next_line < s.lines.size()) {
      const uint64_t addr = s.lines[s.next_line];
      const CacheOutcome o = mlp_cache_.access(addr, c);
      if (o == CacheOutcome::MissStalled) break;
      if (o == CacheOutcome::MissIssued)
        mem_.read(DataType::MlpWeights, addr, uint32_t(cfg_.memory.mlp_cache.line_bytes), addr, c);
      if (o != CacheOutcome::Hit) {
        mlp_cache_.reserve(addr);
        s.waiting.push_back(addr);
      }
      ++s.next_line;
    }
    const bool arrived = take_arrived(mlp_cache_, s.waiting);
    if (arrived && s.next_line == s.lines.size() && c + 1 >= s.load_end) {
      s.loading = false;
      s.shadow_ready = true;
      s.shadow_tag = s.load_tag;
      s.shadow_on_chip = s.load_on_chip;
    }
    if (waiting_for_weights) st = c < s.load_end ? UnitState::Busy : UnitState::StallMemory;
  }
  if (s.holding && s.left > 0) {
    --s.left;
    st = UnitState::Busy;
    if (s.left == 0 && vru_in_.can_push()) {
      vru_in_.push(s.token, c);
      s.holding = false;
    }
  }
  set_state(kTme, st);
}

inline void Engine::count_mlp_load(uint32_t cv_tag) {
  const int32_t m = arithmetic_.tme().mlp_of(cv_tag);
  if (m == loaded_mlp_) return;
  loaded_mlp_ = m;
  ++mlp_loads_;
  mlp_load_bytes_ += arithmetic_.tme().mlp(size_t(m)).stored_bytes;
}

// A batch reaching the TME: the per-batch and per-access MLP hit rates.
inline void Engine::count_mlp_batch(const SampleToken& first, bool on_chip) {
  mlp_series_.record(cycle_, on_chip);
  count_per_access(mlp_access_, on_chip, flights_[first.rp].samples.size());
}

// VRU: composites one sample per vru_cycles_per_sample; after a batch's last
// sample the RP is rescheduled or leaves its CV.
inline void Engine::step_vru() {
  const uint64_t c = cycle_;
  UnitState st = UnitState::Idle;
  VruShell& s = vru_s_;
  if (!s.holding && vru_in_.can_pop(c)) {
    s.token = vru_in_.pop(c);
    s.holding = true;
    s.left = uint64_t(t_.vru_cycles_per_sample);
  }
  if (s.holding) {
    st = UnitState::Busy;
    if (--s.left == 0) {
      if (s.token.last) done_q_.push(s.token.rp, c);
      s.holding = false;
    }
  }
  while (done_q_.can_pop(c)) complete_batch(done_q_.pop(c));
  set_state(kVru, st);
}

inline void Engine::complete_batch(uint32_t rp) {
  Flight& f = flights_[rp];
  if (worker_) {
    if (!f.made) worker_->wait(f.job, rp, main_arithmetic_.get(), &ftu_);
  } else if (f.deferred)
    arithmetic_.flush();
  if (f.stay) {
    ++fine_reschedules_;
    rob_.reschedule(rp);
  } else {
    leave_cv(rp);
  }
}

// Retire from the RP-ROB: back to the CTU (pointer kept) or finished.
inline void Engine::leave_cv(uint32_t rp) {
  rob_.retire(rp);
  if (buffer_[rp].live_mask()) {
    ++cv_transitions_;
    retire_q_.push(rp, cycle_);
  } else {
    finish(rp);
  }
}

inline void Engine::finish(uint32_t rp) {
  write_pixels(buffer_[rp]);
  write_output_record(sequence_[rp]);
  buffer_.release(rp);
  ++rps_finished_;
  ++rps_done_;
}

inline void Engine::write_pixels(const RayPacket& p) {
  for (int r = 0; r < kRaysPerPacket; ++r) {
    if (!(p.pixels.valid_mask >> r & 1)) continue;
    const auto px = vru_.pixel(p.rays[size_t(r)]);
    float* out = image_.at(p.pixels.x[size_t(r)], p.pixels.y[size_t(r)]);
    for (int ch = 0; ch < 3; ++ch) out[ch] = px[size_t(ch)];
  }
}

inline void Engine::write_output_record(uint64_t sequence) {
  if (cfg_.memory.write_output)
    mem_.write(DataType::RpOutput, map_.output_record(sequence), uint32_t(map_.output_record_bytes), cycle_);
}

// Lines a unit waits for are reserved when they miss, so that no other fill
// evicts them before the unit has read them; once resident they are read
// (copied into the unit), released and dropped from `waiting`. True when
// none is left.
inline bool Engine::take_arrived(Cache& cache, std::vector<uint64_t>& waiting) {
  std::erase_if(waiting, [&](uint64_t a) {
    if (!cache.lookup(a)) return false;
    cache.release(a);
    return true;
  });
  return waiting.empty();
}

inline uint64_t Engine::line_start(const Cache& cache, uint64_t addr) {
  return addr / cache.config().line_bytes * cache.config().line_bytes;
}

}  // namespace edrnr::sim::engine
