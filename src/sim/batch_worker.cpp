#include "sim/batch_worker.h"

#include <fmt/format.h>

#include <algorithm>
#include <stdexcept>
#include <utility>

namespace edrnr::sim {

using namespace chip;

namespace {

// A live ray of the packet whose current candidate lies in CV `cv_tag`.
bool has_live_ray_in(const RayMath& math, const SceneModel& model, const RayPacket& p, uint32_t cv_tag) {
  for (const RayState& r : p.rays) {
    if (!r.live()) continue;
    const Vec3i c = math.cell_at(r.ray, r.k, kCoarseCellMicro);
    if (linear_index(c.x, c.y, c.z, model.coarse_res()) == cv_tag) return true;
  }
  return false;
}

// Polls `ready` for up to `budget`, yielding the core between rounds; true
// as soon as it holds. The worker
// waits long (jobs come every few microseconds while a frame runs, and a
// wake-up through the kernel costs about as much as a small job); the main
// thread waits briefly.
template <class Ready>
bool spin_until(Ready ready, std::chrono::microseconds budget) {
  const auto deadline = std::chrono::steady_clock::now() + budget;
  for (;;) {
    for (int i = 0; i < 64; ++i) {
      if (ready()) return true;
#if defined(__x86_64__) || defined(__i386__)
      __builtin_ia32_pause();
#endif
    }
    if (std::chrono::steady_clock::now() >= deadline) return ready();
    // On a busy machine the thread being waited for may need this core.
    std::this_thread::yield();
  }
}

constexpr std::chrono::microseconds kMainSpin{100}, kWorkerSpin{2000};

}  // namespace

// ------------------------------------------------------------ BatchArithmetic

void make_coords(const RayMath& math, const ChipNumerics& n, const RayPacket& p, Flight& f) {
  f.coords.clear();
  for (const SampleRef& s : f.samples)
    f.coords.push_back(sample_coordinate(math, p.rays[s.ray].ray, s.k, n.interp_fraction_bits, n.rounding));
  f.coords_made = true;
}

BatchArithmetic::BatchArithmetic(const SceneModel& model, const ChipConfig& config, const ChipNumerics& n,
                                 const RayMath& math, const Cfiu& cfiu, double delta)
    : model_(model),
      n_(n),
      math_(math),
      cfiu_(cfiu),
      tme_(model, n, delta, size_t(config.mlp_cache_bytes)),
      vru_(n, config.transmittance_min, config.background) {}

TmeDirection* BatchArithmetic::direction_of(RayState& ray) {
  if (ray.dir_input.x.empty()) {
    // The front end leaves the encoding to this thread; the inputs made
    // from the codes are kept with the ray for its next batches.
    const std::vector<int32_t>* code = &ray.dir_code;
    if (code->empty()) {  // encoded into a scratch buffer: only the inputs stay with the ray
      Tme::encode_direction(ray.world_dir, model_.mlp_arch.dir_frequencies, n_, dir_code_);
      code = &dir_code_;
    }
    tme_.direction_input(*code, ray.dir_input);
  }
  return &ray.dir_input;
}

void BatchArithmetic::finish(RayPacket& p, Flight& f, size_t first) {
  for (size_t i = 0; i < f.samples.size(); ++i)
    vru_.composite(p.rays[f.samples[i].ray], outputs_[first + i].alpha, outputs_[first + i].rgb);
  f.stay = has_live_ray_in(math_, model_, p, f.cv_tag);
}

void BatchArithmetic::run(RayPacket& p, Flight& f) {
  if (!f.coords_made) make_coords(math_, n_, p, f);
  f.deferred = true;
  deferred_.push_back({&p, &f, tme_.mlp_of(f.cv_tag)});
  flush();
}

void BatchArithmetic::defer(RayPacket& p, Flight& f) {
  if (!f.coords_made) make_coords(math_, n_, p, f);
  tme_.load(f.cv_tag);
  f.deferred = true;
  deferred_.push_back({&p, &f, tme_.current_mlp()});
}

void BatchArithmetic::flush() {
  if (deferred_.empty()) return;
  const int32_t loaded = tme_.current_mlp();
  order_.resize(deferred_.size());
  for (uint32_t j = 0; j < order_.size(); ++j) order_[j] = j;
  std::stable_sort(order_.begin(), order_.end(),
                   [&](uint32_t a, uint32_t b) { return deferred_[a].mlp < deferred_[b].mlp; });
  const size_t F = size_t(model_.feature_channels);
  for (size_t g0 = 0; g0 < order_.size();) {
    const int32_t mlp = deferred_[order_[g0]].mlp;
    size_t g1 = g0, n = 0;
    for (; g1 < order_.size() && deferred_[order_[g1]].mlp == mlp; ++g1)
      n += deferred_[order_[g1]].flight->samples.size();
    if (features_.size() < n * F) features_.resize(n * F);
    if (outputs_.size() < n) {
      outputs_.resize(n);
      dir_of_sample_.resize(n);
    }
    size_t s = 0;
    for (size_t j = g0; j < g1; ++j) {
      const Deferred& d = deferred_[order_[j]];
      const Flight& f = *d.flight;
      for (size_t i = 0; i < f.samples.size(); ++i, ++s) {
        dir_of_sample_[s] = direction_of(d.packet->rays[f.samples[i].ray]);
        cfiu_.weighted_sum(f.block, f.coords[i], &features_[s * F]);
      }
    }
    tme_.select(mlp);
    tme_.eval_batch(n, features_.data(), dir_of_sample_.data(), outputs_.data());
    s = 0;
    for (size_t j = g0; j < g1; ++j) {
      const Deferred& d = deferred_[order_[j]];
      finish(*d.packet, *d.flight, s);
      s += d.flight->samples.size();
      d.flight->deferred = false;
    }
    g0 = g1;
  }
  if (loaded >= 0) tme_.select(loaded);  // run() loads none
  deferred_.clear();
}

// ------------------------------------------------------------ FrontEndAhead

FrontEndAhead::FrontEndAhead(const Zorg& zorg, FrontEnd& front_end, const Vru& vru, size_t depth)
    : zorg_(zorg), front_(front_end), vru_(vru), ring_(depth) {}

bool FrontEndAhead::can_produce() const {
  const uint64_t produced = produced_.load(std::memory_order_relaxed);
  return !zorg_.done() && produced - consumed_shared_.load(std::memory_order_acquire) < ring_.size();
}

bool FrontEndAhead::running_low() const {
  const uint64_t produced = produced_.load(std::memory_order_relaxed);
  return !zorg_.done() && produced - consumed_shared_.load(std::memory_order_acquire) < ring_.size() / 4;
}

bool FrontEndAhead::produce_one() {
  if (!can_produce()) return false;
  const uint64_t produced = produced_.load(std::memory_order_relaxed);
  FrontEndPacket& e = ring_[produced % ring_.size()];
  e.quad = zorg_.next();
  const uint64_t evals = front_.tsps_position_evals();
  front_.build(e.quad, vru_, *e.packet);
  e.tsps_position_evals = front_.tsps_position_evals() - evals;
  produced_.store(produced + 1, std::memory_order_release);
  return true;
}

void FrontEndAhead::take(FrontEndPacket& e) {
  FrontEndPacket& next = ring_[consumed_ % ring_.size()];
  e.quad = next.quad;
  e.tsps_position_evals = next.tsps_position_evals;
  e.packet.swap(next.packet);
  ++consumed_;
  consumed_shared_.store(consumed_, std::memory_order_release);
}

// ------------------------------------------------------------ FtuAhead

void run_ftu(Ftu& ftu, RayPacket& p, uint32_t rp, uint32_t cv_tag, FtuRun& out) {
  const FtuCounters before = ftu.counters();
  out.micro_log.clear();
  ftu.set_micro_read_log(&out.micro_log);
  out.has_batch = ftu.run(p, rp, cv_tag, out.batch);
  ftu.set_micro_read_log(nullptr);
  out.counts = ftu.counters();
  out.counts -= before;
}

FtuAhead::FtuAhead(const SceneModel& model, const RayMath& math, bool lag_first, RpBuffer& buffer,
                   BatchArithmetic& arithmetic)
    : buffer_(buffer),
      arithmetic_(arithmetic),
      ftu_(model, math, lag_first, 0),
      slots_(new Slot[size_t(buffer.capacity())]) {}

// The state and queued flags are sequentially consistent: when the engine
// finds a job still queued after pend(), that job's try_run() comes later in
// the single order of those operations and so sees the pending run.
void FtuAhead::pend(uint32_t rp, uint32_t cv_tag) {
  Slot& s = slots_[rp];
  s.cv_tag = cv_tag;
  s.state.store(kPending);
}

bool FtuAhead::needs_job(uint32_t rp) { return !slots_[rp].queued.exchange(true); }

void FtuAhead::job_started(uint32_t rp) { slots_[rp].queued.store(false); }

void FtuAhead::run_slot(Slot& s, uint32_t rp, Ftu& ftu, BatchArithmetic* arithmetic) {
  s.flight_made = false;
  try {
    run_ftu(ftu, buffer_[rp], rp, s.cv_tag, s.run);
    if (arithmetic && s.run.has_batch) {
      Flight& f = s.flight;
      f.block = uint32_t(s.run.batch.block);
      f.cv_tag = s.run.batch.cv_tag;
      std::swap(f.samples, s.run.batch.samples);
      f.coords_made = false;
      arithmetic->run(buffer_[rp], f);
      s.flight_made = true;
    }
  } catch (...) {
    s.error = std::current_exception();
  }
  s.state.store(kDone, std::memory_order_release);
}

bool FtuAhead::run_any_pending(Ftu& ftu) {
  const uint32_t n = uint32_t(buffer_.capacity());
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t rp = (steal_from_ + i) % n;
    Slot& s = slots_[rp];
    if (s.state.load(std::memory_order_relaxed) != kPending) continue;
    uint8_t expected = kPending;
    if (!s.state.compare_exchange_strong(expected, kRunning)) continue;
    run_slot(s, rp, ftu, nullptr);
    steal_from_ = rp + 1;
    return true;
  }
  return false;
}

void FtuAhead::try_run(uint32_t rp) {
  Slot& s = slots_[rp];
  uint8_t expected = kPending;
  if (s.state.compare_exchange_strong(expected, kRunning)) run_slot(s, rp, ftu_, &arithmetic_);
}

Flight* FtuAhead::made_flight(uint32_t rp) { return slots_[rp].flight_made ? &slots_[rp].flight : nullptr; }

FtuRun& FtuAhead::take(uint32_t rp, uint32_t cv_tag, Ftu& ftu) {
  Slot& s = slots_[rp];
  uint8_t expected = kPending;
  if (s.state.compare_exchange_strong(expected, kRunning, std::memory_order_acquire)) {
    run_slot(s, rp, ftu, nullptr);
  } else if (expected == kNone) {
    throw std::logic_error(fmt::format("cycle simulator: RP {} scheduled with no FTU run pending", rp));
  } else {
    // The worker is making it (a run takes microseconds): make other pending
    // runs meanwhile, then spin.
    while (s.state.load(std::memory_order_acquire) != kDone && run_any_pending(ftu)) {
    }
    spin_until([&] { return s.state.load(std::memory_order_acquire) == kDone; }, std::chrono::hours(1));
  }
  s.state.store(kNone, std::memory_order_relaxed);
  if (s.error) std::rethrow_exception(std::exchange(s.error, nullptr));
  if (s.cv_tag != cv_tag)
    throw std::logic_error(
        fmt::format("cycle simulator: RP {} scheduled in CV {}, its FTU run was for CV {}", rp, cv_tag, s.cv_tag));
  return s.run;
}

// ------------------------------------------------------------ Worker

Worker::Worker(BatchArithmetic& arithmetic, RpBuffer& buffer, std::vector<Flight>& flights, size_t capacity,
               FrontEndAhead* ahead, FtuAhead* ftu_ahead)
    : arithmetic_(arithmetic),
      buffer_(buffer),
      flights_(flights),
      ahead_(ahead),
      ftu_ahead_(ftu_ahead),
      queue_(2 * capacity),
      ftu_queue_(capacity),
      claimed_(new Claim[capacity]) {
  thread_ = std::thread([this] { loop(); });
}

Worker::~Worker() {
  stop_.store(true);
  signals_.fetch_add(1);
  signals_.notify_one();
  thread_.join();
}

// The work was published (a seq_cst store) before this reads worker_sleeping_:
// either the worker sees the work before it sleeps, or this sees it asleep.
void Worker::signal() {
  if (!worker_sleeping_.load()) return;
  signals_.fetch_add(1);
  signals_.notify_one();
}

// FtuAhead::needs_job keeps one FTU job per RP queued: a full FTU queue is
// a logic error. The batch queue holds one job per RP in flight (the engine
// waits for an RP's arithmetic job before the RP moves on) and the entries
// of jobs the engine made itself until the worker passes them: when full,
// the engine waits for the worker to take one.
uint64_t Worker::push(std::vector<uint32_t>& queue, std::atomic<uint64_t>& submitted,
                      const std::atomic<uint64_t>& taken, uint32_t rp, const char* what, bool wait_when_full) {
  const uint64_t seq = submitted.load();
  if (seq - taken.load() >= queue.size()) {
    if (!wait_when_full)
      throw std::logic_error(fmt::format("cycle simulator: more than {} {} jobs queued", queue.size(), what));
    main_wait(taken, seq - queue.size());
    rethrow_failure();
  }
  queue[seq % queue.size()] = rp;
  submitted.store(seq + 1);
  signal();
  return seq;
}

uint64_t Worker::submit(uint32_t rp) {
  // Released: the worker that claims it sees the flight, even from an
  // older queue entry of rp whose job the engine made.
  claimed_[rp].taken.store(false);
  return push(queue_, submitted_, completed_, rp, "batch", true);
}

void Worker::submit_ftu(uint32_t rp) { push(ftu_queue_, ftu_submitted_, ftu_started_, rp, "FTU", false); }

void Worker::main_wait(const std::atomic<uint64_t>& counter, uint64_t above) {
  if (spin_until([&] { return counter.load() > above; }, kMainSpin)) return;
  main_sleeping_.store(true);
  for (uint64_t v = counter.load(); v <= above; v = counter.load()) counter.wait(v);
  main_sleeping_.store(false);
}

void Worker::fail_with(std::exception_ptr e) {
  error_ = std::move(e);
  failed_.store(true, std::memory_order_release);
}

void Worker::rethrow_failure() const {
  if (failed_.load(std::memory_order_acquire)) std::rethrow_exception(error_);
}

bool Worker::pend_next_run(uint32_t rp) {
  if (!ftu_ahead_ || !flights_[rp].stay) return false;
  ftu_ahead_->pend(rp, flights_[rp].cv_tag);
  return true;
}

void Worker::wait(uint64_t seq, uint32_t rp, BatchArithmetic* own, Ftu* ftu) {
  // A job the worker has not claimed is made here rather than waited for
  // (the worker is busy with work queued before it, or made ahead).
  if (own && completed_.load() <= seq && !claimed_[rp].taken.exchange(true)) {
    rethrow_failure();
    own->run(buffer_[rp], flights_[rp]);
    if (pend_next_run(rp) && ftu_ahead_->needs_job(rp)) submit_ftu(rp);
    return;
  }
  if (ftu && ftu_ahead_)
    while (completed_.load() <= seq && ftu_ahead_->run_any_pending(*ftu)) {
    }
  main_wait(completed_, seq);
  rethrow_failure();
}

void Worker::take_packet(FrontEndPacket& e) {
  if (!ahead_->ready()) {
    signal();  // the worker may be asleep with a full ring that just emptied
    main_wait(ahead_->produced(), ahead_->consumed());
  }
  rethrow_failure();
  ahead_->take(e);
  signal();  // room in the ring
}

void Worker::loop() {
  uint64_t next = 0;
  auto has_work = [&] {
    return stop_.load() || submitted_.load() != next || ftu_submitted_.load() != ftu_started_.load() ||
           (ahead_ && ahead_->can_produce());
  };
  for (;;) {
    const uint64_t seen = signals_.load();
    if (!has_work() && !spin_until(has_work, kWorkerSpin)) {
      worker_sleeping_.store(true);
      if (!has_work()) signals_.wait(seen);
      worker_sleeping_.store(false);
      continue;
    }
    if (stop_.load()) return;
    const bool jobs = submitted_.load() != next, ftu_jobs = ftu_submitted_.load() != ftu_started_.load();
    // Packets first while the engine's supply runs low; then FTU runs (the
    // FTU may take one within cycles of its CTU run), batch jobs (wanted when
    // the batch leaves the VRU) and packets.
    if (ahead_ && ahead_->can_produce() && (ahead_->running_low() || (!jobs && !ftu_jobs))) {
      try {
        if (!error_) ahead_->produce_one();
      } catch (...) {
        fail_with(std::current_exception());
        ahead_->produced().fetch_add(1);  // releases a waiting take_packet(), which rethrows
      }
      if (main_sleeping_.load()) ahead_->produced().notify_one();
      continue;
    }
    if (ftu_jobs) {
      const uint64_t seq = ftu_started_.load();
      const uint32_t rp = ftu_queue_[seq % ftu_queue_.size()];
      ftu_started_.store(seq + 1);
      ftu_ahead_->job_started(rp);
      ftu_ahead_->try_run(rp);  // a run's failure is rethrown by FtuAhead::take
      continue;
    }
    if (!jobs) continue;
    const uint32_t rp = queue_[next % queue_.size()];
    bool next_run = false;
    try {
      if (!error_ && !claimed_[rp].taken.exchange(true)) {  // else the engine made it
        arithmetic_.run(buffer_[rp], flights_[rp]);
        next_run = pend_next_run(rp);
      }
    } catch (...) {
      fail_with(std::current_exception());
    }
    completed_.store(++next);
    if (main_sleeping_.load()) completed_.notify_one();
    if (next_run) ftu_ahead_->try_run(rp);
  }
}

}  // namespace edrnr::sim
