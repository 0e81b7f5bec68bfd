#include "sim/simulator.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "chip/chip_ray.h"
#include "chip/front_end.h"
#include "chip/rp_buffer.h"
#include "chip/zorg.h"
#include "core/error.h"
#include "sim/batch_worker.h"
#include "sim/cache.h"
#include "sim/chrome_trace.h"
#include "sim/fifo.h"
#include "sim/memory_system.h"

namespace edrnr::sim {

namespace {

using namespace chip;

enum Unit : uint32_t { kFrontEnd, kCtu, kFtu, kOooSi, kCfiu, kTme, kVru, kUnits };
const char* const kUnitNames[kUnits] = {"front_end", "ctu", "ftu", "ooo_si", "cfiu", "tme", "vru"};

// The RP state a traversal unit reads and writes back per visit: four rays of
// origin and direction (3 x 25-bit traversal floats each) and two 22-bit
// candidate indices, 776 bits, in 64-bit words of the "others" SRAM.
constexpr uint64_t kRpTraversalStateWords = 13;

// With two threads, how many front-end packets the worker may build ahead.
constexpr size_t kFrontEndAheadPackets = 64;

uint64_t ceil_div(uint64_t a, uint64_t b) { return (a + b - 1) / b; }

double ratio(double a, double b) { return b > 0 ? a / b : 0.0; }

// One sample on its way from the CFIU through the TME to the VRU.
struct SampleToken {
  uint32_t rp = 0;
  bool first = false;  // first sample of its batch
  bool last = false;   // last sample of its batch
};

class HitSeries {
 public:
  explicit HitSeries(uint64_t window) : window_(window) {}
  void record(uint64_t cycle, bool hit) {
    const size_t w = size_t(cycle / window_);
    while (series_.size() <= w) series_.push_back({uint64_t(series_.size()) * window_, 0, 0});
    ++series_[w].accesses;
    series_[w].hits += hit;
  }
  const std::vector<HitRateWindow>& series() const { return series_; }

 private:
  uint64_t window_;
  std::vector<HitRateWindow> series_;
};

CacheConfig cache_config(const SimCacheConfig& s, const char* name, int64_t size_bytes, uint64_t window) {
  CacheConfig c;
  c.name = name;
  c.size_bytes = uint64_t(size_bytes);
  c.line_bytes = s.line_bytes;
  c.ways = s.ways;
  c.replacement = s.replacement;
  c.random_seed = s.random_seed;
  c.mshr_entries = s.mshr_entries;
  c.hit_latency_cycles = s.hit_latency_cycles;
  c.hit_rate_window_cycles = window;
  return c;
}

class Engine {
 public:
  Engine(const SceneModel& model, const Camera& camera, const SimConfig& config, const SimOptions& options,
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
        ftu_(model, math_, config.chip.switches.lag_first, size_t(config.chip.micro_grid_cache_bytes / 8)),
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
        micro_cache_(cache_config(config.memory.micro_grid_cache, "micro_grid", config.chip.micro_grid_cache_bytes,
                                  config.hit_rate_window_cycles)),
        mlp_cache_(cache_config(config.memory.mlp_cache, "mlp_weights", config.chip.mlp_cache_bytes,
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
    ftu_.set_micro_read_log(&micro_log_);
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
      worker_ = std::make_unique<Worker>(arithmetic_, buffer_, flights_, rp_capacity_, ahead_.get());
    }
  }

  void run() {
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
      fe_out_.sample(cycle_);
      retire_q_.sample(cycle_);
      tme_in_.sample(cycle_);
      vru_in_.sample(cycle_);
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
      // Cycles in which nothing can change are counted, not run. The deadlock
      // and progress checks still fall on the cycles they would.
      uint64_t until = opt_.skip_quiet_cycles ? quiet_until(cycle_) : cycle_ + 1;
      if (until > cycle_ + 1) {
        bool busy = false;
        for (UnitState q : quiet_state_) busy |= q == UnitState::Busy;
        busy |= !mem_.idle();
        if (!busy) until = std::min(until, cycle_ + 1 + (opt_.deadlock_cycles - quiet));
        if (opt_.progress) until = std::min(until, std::max(next_progress - 1, cycle_ + 1));
        if (until > cycle_ + 1) {
          skip(cycle_ + 1, until - cycle_ - 1);
          quiet = busy ? 0 : quiet + (until - cycle_ - 1);
          cycle_ = until - 1;
        }
      }
    }
    cycles_ = cycle_ + 1;
    if (opt_.progress) opt_.progress({cycles_, rps_done_, zorg_.packet_count()});
    activity_.finish();
    worker_.reset();
    finish_result();
  }

 private:
  // ------------------------------------------------------------ skipping

  // After cycle c has run: the first later cycle in which any unit, FIFO or
  // the memory system may act differently from c (a countdown ending, an
  // item becoming visible). In the cycles between, every unit reports c's
  // state, and the only side effects are the per-cycle counts that skip()
  // adds in bulk. c + 1 when that cannot be shown.
  uint64_t quiet_until(uint64_t c) {
    // The most frequent reasons to step the next cycle are tested first.
    const uint64_t next = c + 1;
    // OoO-SI, CFIU, TME and VRU: quiet only when empty.
    if (!ooo_.empty() || tme_s_.holding || vru_s_.holding || !tme_in_.empty() || !vru_in_.empty()) return next;
    if (tme_s_.loading || (cfiu_s_.active && c >= cfiu_s_.start)) return next;
    if (!retry_micro_.empty() || !retry_mlp_.empty()) return next;
    if (prefetch_next_ < prefetch_lines_.size() || !bitmaps_ready_) return next;
    uint64_t u = UINT64_MAX;
    auto until = [&](uint64_t t) { u = std::min(u, std::max(t, next)); };
    if (cfiu_s_.active) until(cfiu_s_.start);
    until(done_q_.head_visible_cycle());
    UnitState* st = quiet_state_;
    st[kOooSi] = st[kCfiu] = st[kTme] = st[kVru] = UnitState::Idle;
    // Front end: a packet counting down, or a hand-over waiting for room
    // that only another unit's action makes, or the frame done.
    if (fe_.holding) {
      if (c < fe_.end) until(fe_.end);
      st[kFrontEnd] = next < fe_.end ? UnitState::Busy : UnitState::StallOutput;
    } else if (!zorg_.done()) {
      return next;
    } else {
      st[kFrontEnd] = UnitState::Idle;
    }
    // CTU: counting down, an insert the RP-ROB keeps refusing, or waiting
    // for its FIFOs' next item.
    if (ctu_s_.holding) {
      if (c < ctu_s_.end)
        until(ctu_s_.end);
      else if (!ctu_s_.result.found || !rob_.insert_known_refused(ctu_s_.rp, ctu_s_.result.cv_tag))
        return next;
      st[kCtu] = next < ctu_s_.end ? UnitState::Busy : UnitState::StallOutput;
    } else if (retire_q_.can_pop(c) || fe_out_.can_pop(c)) {
      return next;
    } else {
      st[kCtu] = UnitState::Idle;
    }
    until(retire_q_.head_visible_cycle());
    until(fe_out_.head_visible_cycle());
    // FTU: its result waiting for a full OoO-SI; or all its micro-grid words
    // read and its run counting down; or free with nothing to schedule.
    const FtuShell& f = ftu_s_;
    if (f.holding) {
      if (f.output) {
        if (!f.has_batch || !ooo_.full()) return next;
        st[kFtu] = UnitState::StallOutput;
      } else {
        if (f.next_read < f.reads.size() || !f.waiting.empty()) return next;
        until(std::max(f.ready, f.end - 1));  // the cycle it decides to hand over
        if (c < f.end) until(f.end);          // busy until then, waiting after
        st[kFtu] = next < f.end ? UnitState::Busy : UnitState::StallMemory;
      }
    } else if (free_slots_.empty()) {
      st[kFtu] = rob_.empty() ? UnitState::Idle : UnitState::StallOutput;
    } else if (!rob_.schedule_known_empty()) {
      return next;
    } else {
      st[kFtu] = UnitState::Idle;
    }
    until(mem_.quiet_until(c));  // no transfer completes before
    return u;
  }

  // Counts cycles [first, first + n) as quiet_until() found them: each unit
  // in its state, the FIFOs sampled, the memory clocks run, refused RP-ROB
  // inserts repeated.
  void skip(uint64_t first, uint64_t n) {
    for (uint32_t u = 0; u < kUnits; ++u) activity_.repeat(u, quiet_state_[u], first, n);
    fe_out_.sample_repeat(first, n);
    retire_q_.sample_repeat(first, n);
    tme_in_.sample_repeat(first, n);
    vru_in_.sample_repeat(first, n);
    if (ctu_s_.holding && first > ctu_s_.end) rob_.repeat_refused_insert(n);
    completions_.clear();
    mem_.advance(first + n - 1, completions_);  // the DRAM clocks, ticking only where it must
    if (!completions_.empty()) throw std::logic_error("cycle simulator: a memory completion in skipped cycles");
    skipped_cycles_ += n;
  }

  // ------------------------------------------------------------ units

  void set_state(Unit u, UnitState s) {
    any_busy_ |= s == UnitState::Busy;
    activity_.set(u, s, cycle_);
  }

  // ZORG, ABT and TSPS: one RP at a time; its pointer is allocated when it leaves.
  void step_front_end() {
    const uint64_t c = cycle_;
    UnitState st = UnitState::Idle;
    if (fe_.holding && c >= fe_.end) {
      if (!fe_.packet.live_mask()) {  // background only: no pointer needed
        ++packets_dropped_;
        write_pixels(fe_.packet);
        write_output_record(fe_.sequence);
        ++rps_done_;
        fe_.holding = false;
      } else if (buffer_.full() || !fe_out_.can_push()) {
        st = UnitState::StallOutput;
      } else {
        const uint32_t rp = *buffer_.allocate();
        buffer_[rp] = std::move(fe_.packet);
        sequence_[rp] = fe_.sequence;
        fe_out_.push(rp, c);
        fe_.holding = false;
      }
    }
    if (!fe_.holding && !zorg_.done()) {
      const PixelQuad quad = zorg_.next();
      uint64_t evals = 0;
      if (worker_) {  // built ahead on the worker thread, in the same order
        FrontEndPacket e = worker_->take_packet();
        if (e.quad.sequence != quad.sequence)
          throw std::logic_error(
              fmt::format("cycle simulator: front-end packet {} arrived for quad {}", e.quad.sequence, quad.sequence));
        fe_.packet = std::move(e.packet);
        evals = e.tsps_position_evals;
      } else {
        const uint64_t before = front_.tsps_position_evals();
        fe_.packet = front_.build(quad, vru_);
        evals = front_.tsps_position_evals() - before;
      }
      const uint64_t tsps_cycles = ceil_div(evals, uint64_t(t_.tsps_position_evals_per_cycle));
      fe_.end = c + std::max<uint64_t>(uint64_t(t_.zorg_cycles_per_rp), tsps_cycles);
      fe_.sequence = quad.sequence;
      fe_.holding = true;
    }
    if (fe_.holding && c < fe_.end) st = UnitState::Busy;
    set_state(kFrontEnd, st);
  }

  // CTU: coarse traversal of one RP at a time; CV transitions first, then new RPs.
  void step_ctu() {
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
  void step_ftu() {
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
            count_per_access(feature_access_, a == CacheAccess::Hit, batches_[s.slot].samples.size());
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
      } else if (const auto sched = rob_.schedule()) {
        if (cfg_.memory.mlp_prefetch && (!prefetch_started_ || sched->tag != prefetch_tag_))
          start_mlp_prefetch(sched->tag);
        s.rp = sched->rp;
        s.slot = free_slots_.back();
        free_slots_.pop_back();
        micro_log_.clear();
        const FtuCounters before = ftu_.counters();
        s.has_batch = ftu_.run(buffer_[sched->rp], sched->rp, sched->tag, batches_[s.slot]);
        const FtuCounters& after = ftu_.counters();
        const uint64_t lane_cycles =
            after.leaf_checks - before.leaf_checks + after.candidate_tests - before.candidate_tests;
        const uint64_t cycles = (after.iterations - before.iterations) * uint64_t(t_.ftu_cycles_per_iteration) +
                                ceil_div(lane_cycles, uint64_t(t_.ftu_lanes));
        s.end = c + std::max<uint64_t>(1, cycles);
        s.reads.clear();
        for (uint32_t f : micro_log_) s.reads.push_back(map_.micro_word(uint32_t(model_.fine_to_block[f])));
        s.next_read = 0;
        s.ready = c;
        s.holding = true;
        s.output = false;
        ++ftu_runs_;
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
  void step_issue() {
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
  // in flight. The sample coordinates are computed here, for the CFIU's bank
  // reads at issue.
  void start_batch(uint32_t rp, uint32_t slot) {
    const SampleBatch& batch = batches_[slot];
    Flight& f = flights_[rp];
    f.slot = slot;
    f.block = uint32_t(batch.block);
    f.cv_tag = batch.cv_tag;
    f.coords.clear();
    f.rays.clear();
    const RayPacket& p = buffer_[rp];
    for (const SampleRef& sref : batch.samples) {
      f.coords.push_back(sample_coordinate(math_, p.rays[sref.ray].ray, sref.k, n_.interp_fraction_bits, n_.rounding));
      f.rays.push_back(sref.ray);
    }
    if (worker_)
      f.job = worker_->submit(rp);
    else
      arithmetic_.run(buffer_[rp], f);
  }

  // The CFIU reads the corners of each sample from the banks now; bank
  // conflicts lengthen its samples.
  void issue(const LsEntry& e) {
    Flight& f = flights_[e.rp];
    f.sample_cycles.clear();
    for (const SampleCoord& sc : f.coords) {
      const int conflicts = cfiu_.read_corners(e.block, sc);
      f.sample_cycles.push_back(uint8_t(std::min(255, t_.cfiu_cycles_per_sample + conflicts)));
    }
    cfiu_s_ = {true, e.rp, 0, f.sample_cycles[0], cycle_ + 1};
    early_mlp_load(f.cv_tag);
  }

  // CFIU: streams the issued batch's samples into the TME's queue.
  void step_cfiu() {
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
  void step_tme() {
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

  // Starts copying the MLP of CV `tag` into the free weight buffer.
  void start_mlp_load(uint32_t tag, uint64_t c) {
    TmeShell& s = tme_s_;
    if (t_.tme_weight_buffers == 1) s.active = false;  // the single buffer is overwritten
    s.loading = true;
    s.shadow_ready = false;
    s.load_tag = tag;
    s.load_end = c + ceil_div(mlp_bytes_, uint64_t(t_.tme_weight_load_bytes_per_cycle));
    s.next_line = 0;
    s.waiting.clear();
    const uint32_t mlp = uint32_t(model_.coarse_to_mlp[tag]);
    s.lines.clear();
    bool on_chip = true;
    for (uint64_t i = 0; i < mlp_lines_; ++i) {
      s.lines.push_back(map_.mlp(mlp) + i * cfg_.memory.mlp_cache.line_bytes);
      on_chip = on_chip && mlp_cache_.lookup(s.lines.back());
    }
    s.load_on_chip = on_chip;
    ++mlp_switches_;
  }

  // With a shadow buffer: the OoO-SI issued a batch of CV `tag`; load its MLP
  // now unless it is active, loaded, or the shadow buffer is taken.
  void early_mlp_load(uint32_t tag) {
    TmeShell& s = tme_s_;
    if (t_.tme_weight_buffers < 2 || s.loading || s.shadow_ready) return;
    if (s.active && s.active_tag == tag) return;
    start_mlp_load(tag, cycle_);
  }

  // A batch reaching the TME: the per-batch and per-access MLP hit rates.
  void count_mlp_batch(const SampleToken& first, bool on_chip) {
    mlp_series_.record(cycle_, on_chip);
    count_per_access(mlp_access_, on_chip, flights_[first.rp].coords.size());
  }

  // VRU: composites one sample per vru_cycles_per_sample; after a batch's last
  // sample the RP is rescheduled or leaves its CV.
  void step_vru() {
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

  void complete_batch(uint32_t rp) {
    Flight& f = flights_[rp];
    if (worker_) worker_->wait(f.job);
    if (f.stay) {
      ++fine_reschedules_;
      rob_.reschedule(rp);
    } else {
      leave_cv(rp);
    }
  }

  // Retire from the RP-ROB: back to the CTU (pointer kept) or finished.
  void leave_cv(uint32_t rp) {
    rob_.retire(rp);
    if (buffer_[rp].live_mask()) {
      ++cv_transitions_;
      retire_q_.push(rp, cycle_);
    } else {
      finish(rp);
    }
  }

  void finish(uint32_t rp) {
    write_pixels(buffer_[rp]);
    write_output_record(sequence_[rp]);
    buffer_.release(rp);
    ++rps_finished_;
    ++rps_done_;
  }

  void write_pixels(const RayPacket& p) {
    for (int r = 0; r < kRaysPerPacket; ++r) {
      if (!(p.pixels.valid_mask >> r & 1)) continue;
      const auto px = vru_.pixel(p.rays[size_t(r)]);
      float* out = image_.at(p.pixels.x[size_t(r)], p.pixels.y[size_t(r)]);
      for (int ch = 0; ch < 3; ++ch) out[ch] = px[size_t(ch)];
    }
  }

  void write_output_record(uint64_t sequence) {
    if (cfg_.memory.write_output)
      mem_.write(DataType::RpOutput, map_.output_record(sequence), uint32_t(map_.output_record_bytes), cycle_);
  }

  // The RP-ROB switched to `tag`: its MLP's lines are fetched ahead of the TME.
  void start_mlp_prefetch(uint32_t tag) {
    prefetch_started_ = true;
    prefetch_tag_ = tag;
    prefetch_lines_.clear();
    prefetch_next_ = 0;
    const int32_t mlp = model_.coarse_to_mlp[tag];
    if (mlp < 0) return;
    for (uint64_t i = 0; i < mlp_lines_; ++i)
      prefetch_lines_.push_back(map_.mlp(uint32_t(mlp)) + i * cfg_.memory.mlp_cache.line_bytes);
  }

  // One prefetch request per cycle, while MSHR entries are free.
  void issue_mlp_prefetch(uint64_t c) {
    if (prefetch_next_ >= prefetch_lines_.size()) return;
    const uint64_t addr = prefetch_lines_[prefetch_next_];
    const CacheOutcome o = mlp_cache_.prefetch(addr, c);
    if (o == CacheOutcome::MissStalled) return;
    if (o == CacheOutcome::MissIssued)
      mem_.read(DataType::MlpWeights, addr, uint32_t(cfg_.memory.mlp_cache.line_bytes), addr, c);
    ++prefetch_next_;
  }

  struct AccessCount {
    uint64_t hits = 0, misses = 0;
  };
  static void count_per_access(AccessCount& a, bool hit, size_t samples) {
    if (samples == 0) return;
    a.hits += hit ? samples : samples - 1;
    a.misses += hit ? 0 : 1;
  }

  // ------------------------------------------------------------ memory

  // Lines a unit waits for are reserved when they miss, so that no other fill
  // evicts them before the unit has read them; once resident they are read
  // (copied into the unit), released and dropped from `waiting`. True when
  // none is left.
  static bool take_arrived(Cache& cache, std::vector<uint64_t>& waiting) {
    std::erase_if(waiting, [&](uint64_t a) {
      if (!cache.lookup(a)) return false;
      cache.release(a);
      return true;
    });
    return waiting.empty();
  }

  static uint64_t line_start(const Cache& cache, uint64_t addr) {
    return addr / cache.config().line_bytes * cache.config().line_bytes;
  }

  void deliver(const MemoryCompletion& m) {
    switch (m.type) {
      case DataType::Bitmaps:
        bitmaps_ready_ = true;
        break;
      case DataType::MicroGrid:
        if (!micro_cache_.fill(m.tag, cycle_).filled) retry_micro_.push_back(m.tag);
        fill_words_micro_ += cfg_.memory.micro_grid_cache.line_bytes / 8;
        break;
      case DataType::MlpWeights:
        if (!mlp_cache_.fill(m.tag, cycle_).filled) retry_mlp_.push_back(m.tag);
        fill_words_mlp_ += cfg_.memory.mlp_cache.line_bytes / 8;
        break;
      case DataType::Features:
        cfiu_.cache().fill(uint32_t(m.tag));
        ++feature_fills_;
        break;
      case DataType::RpOutput:
        break;
    }
  }

  // Fills refused because every way of the set was reserved.
  void retry_fills() {
    for (auto* pair : {&retry_micro_, &retry_mlp_}) {
      if (pair->empty()) continue;
      Cache& cache = pair == &retry_micro_ ? micro_cache_ : mlp_cache_;
      std::vector<uint64_t> still;
      for (uint64_t a : *pair)
        if (!cache.fill(a, cycle_).filled) still.push_back(a);
      pair->swap(still);
    }
  }

  // ------------------------------------------------------------ results

  ChipCounters chip_counters() const {
    ChipCounters c;
    c.packets = zorg_.packet_count();
    c.rays = front_.counters().rays;
    c.rays_dropped_abt = front_.counters().rays_dropped_abt;
    c.rays_dropped_tsps = front_.counters().rays_dropped_tsps;
    c.packets_dropped = packets_dropped_;
    c.tsps_position_evals = front_.tsps_position_evals();
    c.zorg_skipped_quads = zorg_.skipped_quads();
    c.ctu = ctu_.counters();
    c.ftu = ftu_.counters();
    c.rp_rob = rob_.counters();
    c.ooo = ooo_.counters();
    c.feature_cache = cfiu_.cache().counters();
    c.cfiu = cfiu_.counters();
    c.tme = arithmetic_.tme().counters();
    c.vru = arithmetic_.vru().counters();
    c.cv_transitions = cv_transitions_;
    c.fine_reschedules = fine_reschedules_;
    c.rps_finished = rps_finished_;
    c.fill_waits = ooo_.counters().waits;
    c.peak_rp_buffer = uint64_t(buffer_.peak_in_use());
    c.feature_cache_lines = cfiu_.cache().lines();
    for (int b = 0; b < kFeatureBanks; ++b) c.bank_depth_rows[size_t(b)] = cfiu_.cache().layout().bank_depth(b);
    c.mlp_bytes = mlp_bytes_;
    return c;
  }

  EnergyRun energy_run(const ChipCounters& c) const {
    EnergyRun run;
    run.cycles = cycles_;
    run.pixels = uint64_t(image_.width) * uint64_t(image_.height);
    auto& e = run.event_counts;
    const uint64_t F = uint64_t(model_.feature_channels);
    const uint64_t position_evals = c.tsps_position_evals + c.ctu.position_evals + c.ftu.position_evals;
    // Ray generation: a rotation (9 multiplies, 6 adds) and a normalisation
    // (6 multiplies, 3 adds); ABT: a slab test, 6 multiply-adds and 6 compares
    // per ray. Position evaluations: one fused multiply-add in the traversal float.
    e["fp32_mult"] = c.rays * (15 + 6) + position_evals;
    e["fp32_add"] = c.rays * (9 + 6) + position_evals;
    e["int32_compare"] = c.rays * 6 + c.ctu.coarse_checks + c.ftu.leaf_checks + c.ftu.micro_checks;
    // Interpolation: per corner and channel one multiply-accumulate; the TME:
    // one INT8 multiply and INT20 add per MAC, one 16-bit requantization
    // multiply per neuron; the VRU: 5 multiplies and 4 adds per sample.
    e["int8_mult"] = c.tme.macs;
    e["int20_add"] = c.tme.macs + c.cfiu.samples * 8 * F;
    e["int16_mult"] = c.cfiu.samples * 8 * F + c.tme.samples * neurons_per_sample_ + c.vru.samples * 5;
    e["int16_add"] = c.vru.samples * 4;
    // SRAMs, per 64-bit word.
    e["micro_grid_sram_read"] = c.ftu.micro_word_reads;
    e["micro_grid_sram_write"] = fill_words_micro_;
    e["feature_sram_read"] = c.cfiu.corner_reads;
    e["feature_sram_write"] = feature_fills_ * ceil_div(map_.feature_block_bytes, 8);
    e["mlp_sram_read"] = mlp_switches_ * ceil_div(mlp_bytes_, 8);
    e["mlp_sram_write"] = fill_words_mlp_;
    // Others: the fine bitmap, the RP buffer (traversal state per CTU/FTU
    // visit; transmittance and colour per sample) and the computation SRAM
    // (one sample position per half word, written by the FTU, read by the SCC).
    e["other_sram_read"] = c.ftu.fine_checks + (ctu_runs_ + ftu_runs_) * kRpTraversalStateWords + c.vru.samples +
                           ceil_div(c.ftu.samples, 2);
    e["other_sram_write"] = (uint64_t(zorg_.packet_count()) + ctu_runs_ + ftu_runs_) * kRpTraversalStateWords +
                            c.vru.samples + ceil_div(c.ftu.samples, 2);
    // Clock distribution, control and pipeline registers, which the
    // per-operation rows leave out: one event per core cycle (its energy is
    // fitted, docs/energy.md).
    e["core_cycle"] = cycles_;
    // Registers: the MLP copied into the MAC array; each sample's interpolated
    // feature (CFIU -> TME) and its alpha and colour (TME -> VRU).
    e["register_bit"] = mlp_switches_ * mlp_bytes_ * 8 +
                        c.cfiu.samples * (F * uint64_t(n_.interp_feature_bits) + 4 * uint64_t(n_.alpha_bits));
    const uint64_t dram_bytes = uint64_t(stats_.get("dram.read_bytes")) + uint64_t(stats_.get("dram.write_bytes"));
    if (cfg_.energy.dram == DramEnergySource::Events) {
      e["dram_bit"] = dram_bytes * 8;
    } else if (cfg_.energy.dram == DramEnergySource::Model) {
      run.dram_model_energy_pJ = mem_.dram().energy().total_pJ();
    } else {
      const DramEnergy d = mem_.dram().energy();
      run.dram_model_energy_pJ = d.activate_pJ + d.read_pJ + d.write_pJ;
      e["dram_io_bit"] = dram_bytes * 8;
    }
    return run;
  }

  void finish_result() {
    mem_.update_stats();
    res_.image = std::move(image_);
    res_.chip = chip_counters();
    const ChipCounters& cc = res_.chip;
    SimSummary& s = res_.summary;
    s.cycles = cycles_;
    s.clock_MHz = cfg_.clock_MHz;
    s.frame_time_s = double(cycles_) / (cfg_.clock_MHz * 1e6);
    s.fps = 1.0 / s.frame_time_s;
    s.pixels = uint64_t(res_.image.width) * uint64_t(res_.image.height);
    s.samples = cc.cfiu.samples;
    s.samples_per_cycle = ratio(double(s.samples), double(cycles_));
    const uint64_t slowest = std::max<uint64_t>(
        {uint64_t(t_.cfiu_cycles_per_sample), tme_cycles_per_sample_, uint64_t(t_.vru_cycles_per_sample)});
    s.peak_samples_per_cycle = 1.0 / double(slowest);
    s.micro_grid_hit_rate = micro_cache_.stats().hit_rate();
    uint64_t fhits = 0, faccesses = 0;
    for (const HitRateWindow& w : feature_series_.series()) fhits += w.hits, faccesses += w.accesses;
    s.feature_hit_rate = ratio(double(fhits), double(faccesses));
    uint64_t mhits = 0, maccesses = 0;
    for (const HitRateWindow& w : mlp_series_.series()) mhits += w.hits, maccesses += w.accesses;
    s.mlp_hit_rate = ratio(double(mhits), double(maccesses));
    s.feature_hit_rate_per_access =
        ratio(double(feature_access_.hits), double(feature_access_.hits + feature_access_.misses));
    s.mlp_hit_rate_per_access = ratio(double(mlp_access_.hits), double(mlp_access_.hits + mlp_access_.misses));
    s.dram_read_bytes = uint64_t(stats_.get("dram.read_bytes"));
    s.dram_write_bytes = uint64_t(stats_.get("dram.write_bytes"));
    s.coarse_rays_per_iteration = cc.coarse_rays_per_iteration();
    s.fine_rays_per_iteration = cc.fine_rays_per_iteration();
    s.rps_per_tag_switch = cc.rps_per_tag_switch();

    StatsRegistry& r = stats_;
    auto cnt = [&](const std::string& name, const char* unit, const char* what, uint64_t v) {
      r.counter(name, unit, what).value = v;
    };
    auto val = [&](const std::string& name, const char* unit, const char* what, double v) {
      r.value(name, unit, what).set(v);
    };
    cnt("sim.cycles", "cycles", "core cycles to render the frame", s.cycles);
    val("sim.clock_MHz", "MHz", "core clock", s.clock_MHz);
    val("sim.frame_time_s", "s", "frame time at the core clock", s.frame_time_s);
    val("sim.fps", "frames/s", "frames per second at the core clock", s.fps);
    cnt("sim.pixels", "pixels", "pixels in the frame", s.pixels);
    cnt("sim.samples", "samples", "samples interpolated", s.samples);
    val("sim.samples_per_cycle", "samples", "samples per cycle, averaged over the frame", s.samples_per_cycle);
    val("sim.peak_samples_per_cycle", "samples", "samples per cycle the slowest of CFIU, TME and VRU allows",
        s.peak_samples_per_cycle);
    val("sim.coarse_rays_per_iteration", "rays", "rays advancing together per RP in coarse traversal (paper 3.89)",
        s.coarse_rays_per_iteration);
    val("sim.fine_rays_per_iteration", "rays", "rays advancing together per RP in fine traversal (paper 3.48)",
        s.fine_rays_per_iteration);
    val("sim.rps_per_tag_switch", "CCRPs", "CCRPs scheduled per CV tag switch", s.rps_per_tag_switch);
    cnt("sim.mlp_switches", "switches", "MLPs copied into the TME's MAC array", mlp_switches_);
    cnt("sim.tme_cycles_per_sample", "cycles", "TME cycles per sample (MACs per sample / MACs per cycle)",
        tme_cycles_per_sample_);
    cnt("sim.macs_per_sample", "MACs", "multiply-accumulates per sample of one MLP", macs_per_sample_);
    cnt("host.skipped_cycles", "cycles", "cycles counted in bulk, not stepped: no unit could act in them",
        skipped_cycles_);
    for (uint32_t u = 0; u < kUnits; ++u)
      for (int st = 0; st < kUnitStates; ++st) {
        const std::string name =
            std::string("sim.unit.") + kUnitNames[u] + "." + unit_state_name(UnitState(st)) + "_cycles";
        static const char* const what[kUnitStates] = {
            "cycles working", "cycles holding a result the next unit cannot take",
            "cycles waiting for data from memory (or a feature cache MSHR entry)", "cycles with nothing to do"};
        cnt(name, "cycles", what[st], activity_.cycles(u, UnitState(st)));
      }
    fe_out_.export_stats(r, "sim.fifo.front_end_to_ctu");
    retire_q_.export_stats(r, "sim.fifo.retire_to_ctu");
    tme_in_.export_stats(r, "sim.fifo.cfiu_to_tme");
    vru_in_.export_stats(r, "sim.fifo.tme_to_vru");
    micro_cache_.export_stats(r, "cache.micro_grid");
    mlp_cache_.export_stats(r, "cache.mlp_weights");
    const FeatureCacheCounters& fc = cfiu_.cache().counters();
    cnt("cache.features.accesses", "requests", "block requests served (retries after a stall excluded)", faccesses);
    cnt("cache.features.hits", "requests", "requests whose block was on chip", fhits);
    cnt("cache.features.misses", "requests", "requests whose block was not (fetched or merged)", faccesses - fhits);
    val("cache.features.hit_rate", "ratio", "hits / accesses", s.feature_hit_rate);
    cnt("cache.features.misses_issued", "blocks", "blocks fetched from DRAM", fc.misses);
    cnt("cache.features.misses_merged", "requests", "misses merged by the MSHR", fc.merged_misses);
    cnt("cache.features.stall_cycles", "cycles", "requests refused: no MSHR entry or no unreserved line", fc.stalls);
    cnt("cache.features.evictions", "lines", "lines evicted", fc.evictions);
    cnt("cache.mlp.batches", "batches", "batches reaching the TME", maccesses);
    cnt("cache.mlp.batch_hits", "batches", "batches whose MLP was on chip (in the MAC array or the MLP cache)", mhits);
    val("cache.mlp.hit_rate", "ratio", "batch_hits / batches (the MLP hit rate of the report)", s.mlp_hit_rate);
    for (auto [name, a] : {std::pair{"features", feature_access_}, std::pair{"mlp", mlp_access_}}) {
      const std::string p = std::string("cache.") + name + ".per_access.";
      cnt(p + "accesses", "samples", "samples reading the data (a missed batch: its first sample misses)",
          a.hits + a.misses);
      cnt(p + "hits", "samples", "samples that found the data on chip", a.hits);
      cnt(p + "misses", "samples", "samples that waited for it", a.misses);
      val(p + "hit_rate", "ratio", "hits / accesses, per sample (the paper's Fig. 8 counts per access)",
          ratio(double(a.hits), double(a.hits + a.misses)));
    }
    res_.sram_budget = compute_sram_budget(cfg_, {model_.micro_res, model_.feature_channels, mlp_bytes_});
    for (const SramBuffer& b : res_.sram_budget.buffers)
      cnt("sram." + b.name + "_bytes", "bytes", "on-chip buffer size (docs/simulator.md, SRAM budget)", b.bytes);
    for (int k = 0; k < kSramClasses; ++k)
      cnt(std::string("sram.class.") + sram_class_name(SramClass(k)) + "_bytes", "bytes",
          "buffers of this Table I class", res_.sram_budget.class_bytes[k]);
    cnt("cache.features.bank_reads", "reads", "vertex vectors read from the 8 banks", cc.cfiu.corner_reads);
    cnt("cache.features.bank_conflict_cycles", "cycles", "extra CFIU cycles from two corners in one bank",
        cc.cfiu.conflict_cycles);
    export_chip_stats(cc, r, "chip");

    res_.hit_rate_series = {
        {"micro_grid", hit_rate_series_json(micro_cache_.hit_rate_series(), cfg_.hit_rate_window_cycles)},
        {"features", hit_rate_series_json(feature_series_.series(), cfg_.hit_rate_window_cycles)},
        {"mlp_weights", hit_rate_series_json(mlp_series_.series(), cfg_.hit_rate_window_cycles)},
        {"mlp_weight_lines", hit_rate_series_json(mlp_cache_.hit_rate_series(), cfg_.hit_rate_window_cycles)}};
    if (opt_.trace_cycles > 0) res_.trace = activity_.chrome_trace(cfg_.clock_MHz);
    res_.energy_run = energy_run(cc);
    if (!cfg_.energy.events_csv.empty()) {
      const OperatingPoint point = operating_point_at(cfg_, cfg_.clock_MHz, &res_.voltage_extrapolated);
      res_.energy = evaluate_energy(cfg_, res_.energy_run, point);
      export_stats(*res_.energy, r, "energy");
      val("energy.voltage_V", "V", "core supply at the configured clock (from the operating points)", point.voltage_V);
    }
  }

  // ------------------------------------------------------------ state

  struct FrontEndShell {
    bool holding = false;
    uint64_t end = 0;
    uint64_t sequence = 0;
    RayPacket packet;
  };
  struct CtuShell {
    bool holding = false;
    uint64_t end = 0;
    uint32_t rp = 0;
    CtuResult result;
  };
  struct FtuShell {
    bool holding = false;
    bool output = false;  // the run is done; handing its result on
    bool has_batch = false;
    uint32_t rp = 0, slot = 0;
    uint64_t end = 0, ready = 0;
    std::vector<uint64_t> reads;  // micro-word addresses of the run, in order
    size_t next_read = 0;
    std::vector<uint64_t> waiting;  // missed words (their lines reserved)
  };
  struct CfiuShell {
    bool active = false;
    uint32_t rp = 0;
    uint32_t next = 0;   // sample being read
    uint32_t left = 0;   // cycles left for it
    uint64_t start = 0;  // first cycle of the batch
  };
  struct TmeShell {
    bool holding = false;
    SampleToken token;
    uint64_t left = 0;
    bool active = false;  // the active weight buffer holds active_tag's MLP
    uint32_t active_tag = 0;
    bool shadow_ready = false;  // a finished load waits to become active
    uint32_t shadow_tag = 0;
    bool shadow_on_chip = false;
    bool loading = false;  // a load into the free buffer is under way
    uint32_t load_tag = 0;
    bool load_on_chip = false;  // its lines were all in the MLP cache when it started
    uint64_t load_end = 0;
    std::vector<uint64_t> lines;
    size_t next_line = 0;
    std::vector<uint64_t> waiting;
  };
  struct VruShell {
    bool holding = false;
    SampleToken token;
    uint64_t left = 0;
  };

  const SceneModel& model_;
  const SimConfig& cfg_;
  const SimTiming& t_;
  const SimOptions& opt_;
  SimResult& res_;
  StatsRegistry& stats_;
  ChipNumerics n_;
  double delta_;
  RayMath math_;
  Zorg zorg_;
  FrontEnd front_;
  RpBuffer buffer_;
  Ctu ctu_;
  RpRob rob_;
  Ftu ftu_;
  OooSi ooo_;
  Cfiu cfiu_;
  BatchArithmetic arithmetic_;
  Vru vru_;  // ray start and pixels (the arithmetic composites with its own)
  Image image_;
  uint64_t mlp_bytes_;
  AddressMap map_;
  MemorySystem mem_;
  Cache micro_cache_;
  Cache mlp_cache_;
  HitSeries feature_series_;  // per batch request
  HitSeries mlp_series_;      // per batch at the TME: its MLP on chip (MAC array or MLP cache)
  ActivityRecorder activity_;
  size_t rp_capacity_;
  Fifo<uint32_t> fe_out_, retire_q_;
  Fifo<SampleToken> tme_in_, vru_in_;
  Fifo<uint32_t> done_q_;
  std::vector<SampleBatch> batches_;  // the computation SRAM: OoO-SI entries plus the batch the CFIU reads
  std::vector<uint32_t> free_slots_;
  std::vector<Flight> flights_;     // by RP pointer
  std::vector<uint64_t> sequence_;  // by RP pointer: ZORG issue index
  std::vector<uint32_t> micro_log_;
  std::vector<MemoryCompletion> completions_;
  std::vector<uint64_t> retry_micro_, retry_mlp_;
  std::unique_ptr<FrontEndAhead> ahead_;  // with threads = 2: the front end runs on the worker
  std::unique_ptr<Worker> worker_;

  FrontEndShell fe_;
  CtuShell ctu_s_;
  FtuShell ftu_s_;
  CfiuShell cfiu_s_;
  TmeShell tme_s_;
  VruShell vru_s_;

  uint64_t cycle_ = 0, cycles_ = 0, skipped_cycles_ = 0;
  UnitState quiet_state_[kUnits] = {};  // each unit's state in the cycles quiet_until() found
  bool bitmaps_ready_ = false;
  bool any_busy_ = false;
  uint64_t mlp_lines_ = 0, macs_per_sample_ = 0, neurons_per_sample_ = 0, tme_cycles_per_sample_ = 1;
  uint64_t rps_done_ = 0, packets_dropped_ = 0, rps_finished_ = 0, cv_transitions_ = 0, fine_reschedules_ = 0;
  uint64_t ctu_runs_ = 0, ftu_runs_ = 0, mlp_switches_ = 0, feature_fills_ = 0;
  uint64_t fill_words_micro_ = 0, fill_words_mlp_ = 0;
  bool prefetch_started_ = false;
  uint32_t prefetch_tag_ = 0;
  std::vector<uint64_t> prefetch_lines_;
  size_t prefetch_next_ = 0;
  AccessCount feature_access_, mlp_access_;
};

}  // namespace

EnergyReport evaluate_energy(const SimConfig& config, const EnergyRun& run, const OperatingPoint& point) {
  if (config.energy.events_csv.empty()) fail("simulator.energy.events: no energy table configured");
  EnergyModel model(EnergyTable::load(config.energy.events_csv),
                    config.energy.leakage_csv.empty() ? LeakageTable{} : LeakageTable::load(config.energy.leakage_csv),
                    config.energy.leakage_voltage_exponent);
  return model.evaluate(run, point);
}

SramBudget sram_budget_for(const SceneModel& model, const SimConfig& config) {
  check_chip_model(model);
  uint64_t mlp_bytes = 0;
  if (model.mlp_count()) {
    const double delta = double(config.chip.step_micro) * double(model.scene_box.size().x) / double(model.micro_res);
    Tme tme(model, config.chip.numerics, delta, size_t(config.chip.mlp_cache_bytes));
    mlp_bytes = tme.mlp(0).stored_bytes;
  }
  return compute_sram_budget(config, {model.micro_res, model.feature_channels, mlp_bytes});
}

SimResult simulate_chip(const SceneModel& model, const Camera& camera, const SimConfig& config,
                        const SimOptions& options) {
  validate(config);
  check_chip_model(model);
  if (camera.width < 1 || camera.height < 1) fail("camera image size {}x{} is empty", camera.width, camera.height);
  if (options.threads < 1 || options.threads > 2) fail("simulator threads {} must be 1 or 2", options.threads);
  SimResult result;
  result.stats = std::make_unique<StatsRegistry>();
  Engine engine(model, camera, config, options, result);
  engine.run();
  return result;
}

std::string format_sim_report(const SimResult& r) {
  const SimSummary& s = r.summary;
  const StatsRegistry& st = *r.stats;
  std::ostringstream o;
  o << fmt::format("frame       {}x{}: {} cycles at {:.0f} MHz = {:.3f} ms, {:.2f} FPS\n", r.image.width,
                   r.image.height, s.cycles, s.clock_MHz, s.frame_time_s * 1e3, s.fps);
  // The paper's figures are for 800x800 frames of the Synthetic NeRF scenes.
  const bool paper_frame = r.image.width == 800 && r.image.height == 800;
  for (const PaperOperatingPoint& p : table1_operating_points())
    if (paper_frame && std::abs(p.point.frequency_MHz - s.clock_MHz) < 1e-9)
      o << fmt::format("            paper (800x800, Synthetic NeRF) at {:.0f} MHz: {:.1f} FPS; ratio {:.3f}\n",
                       p.point.frequency_MHz, p.fps, s.fps / p.fps);
  o << fmt::format("samples     {} ({:.3f} per cycle, peak {:.3f}); {:.2f} per pixel\n", s.samples, s.samples_per_cycle,
                   s.peak_samples_per_cycle, ratio(double(s.samples), double(s.pixels)));
  o << fmt::format("rays/RP     coarse {:.2f} (paper 3.89), fine {:.2f} (paper 3.48); CCRPs per CV tag switch {:.1f}\n",
                   s.coarse_rays_per_iteration, s.fine_rays_per_iteration, s.rps_per_tag_switch);
  o << "units       busy  stall_out  stall_mem   idle   (% of cycles)\n";
  for (uint32_t u = 0; u < kUnits; ++u) {
    double v[kUnitStates];
    for (int k = 0; k < kUnitStates; ++k)
      v[k] = 100.0 *
             ratio(st.get(std::string("sim.unit.") + kUnitNames[u] + "." + unit_state_name(UnitState(k)) + "_cycles"),
                   double(s.cycles));
    o << fmt::format("  {:<9} {:5.1f}  {:9.1f}  {:9.1f}  {:5.1f}\n", kUnitNames[u], v[0], v[1], v[2], v[3]);
  }
  o << fmt::format(
      "caches      micro grid {:.2f} % (paper 96.27), features {:.2f} % (paper 98.65), MLP {:.2f} % "
      "(paper 96.38); bank conflict cycles {}\n",
      100 * s.micro_grid_hit_rate, 100 * s.feature_hit_rate, 100 * s.mlp_hit_rate,
      uint64_t(st.get("cache.features.bank_conflict_cycles")));
  o << fmt::format("            per access (sample): features {:.2f} %, MLP {:.2f} %\n",
                   100 * s.feature_hit_rate_per_access, 100 * s.mlp_hit_rate_per_access);
  {
    const SramBudget& b = r.sram_budget;
    o << "SRAM        ";
    for (int k = 0; k < kSramClasses; ++k)
      o << fmt::format("{}{} {:.1f} of {:.1f} KB{}", k ? ", " : "", sram_class_name(SramClass(k)),
                       double(b.class_bytes[k]) / 1024, double(b.class_budget[k]) / 1024,
                       b.class_bytes[k] > b.class_budget[k] ? " (OVER)" : "");
    o << "\n";
  }
  o << "memory      read bytes   writes bytes  (as requested, by data type)\n";
  for (int t = 0; t < kDataTypes; ++t) {
    const std::string p = std::string("mem.") + data_type_name(DataType(t));
    o << fmt::format("  {:<11} {:>11.0f}  {:>11.0f}\n", data_type_name(DataType(t)), st.get(p + ".read_bytes"),
                     st.get(p + ".write_bytes"));
  }
  o << fmt::format(
      "  DRAM        {:.1f} MB read, {:.1f} MB written ({:.1f} B/pixel); {:.2f} GB/s of {:.2f}; row hits "
      "{:.1f} %\n",
      double(s.dram_read_bytes) / 1e6, double(s.dram_write_bytes) / 1e6,
      ratio(double(s.dram_read_bytes + s.dram_write_bytes), double(s.pixels)), st.get("dram.bandwidth_GBps"),
      st.get("dram.peak_bandwidth_GBps"), 100 * st.get("dram.row_hit_rate"));
  if (r.energy) {
    const EnergyReport& e = *r.energy;
    o << fmt::format(
        "energy      {:.2f} nJ/pixel, {:.1f} mW at {:.0f} MHz / {:.2f} V{} (core {:.1f}, off-chip {:.1f}, "
        "leakage {:.1f} nJ/pixel)\n",
        e.nJ_per_pixel, e.average_power_W * 1e3, e.point.frequency_MHz, e.point.voltage_V,
        r.voltage_extrapolated ? " (voltage of the highest operating point)" : "",
        e.core_dynamic_pJ / 1e3 / double(e.pixels), e.offchip_pJ / 1e3 / double(e.pixels),
        e.static_pJ / 1e3 / double(e.pixels));
    for (const PaperOperatingPoint& p : table1_operating_points())
      if (paper_frame && std::abs(p.point.frequency_MHz - e.point.frequency_MHz) < 1e-9)
        o << fmt::format("            paper: {:.1f} nJ/pixel, {:.1f} mW; ratio {:.2f} / {:.2f}\n", p.nJ_per_pixel,
                         p.power_mW, e.nJ_per_pixel / p.nJ_per_pixel, e.average_power_W * 1e3 / p.power_mW);
  }
  return o.str();
}

}  // namespace edrnr::sim
