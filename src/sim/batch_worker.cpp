#include "sim/batch_worker.h"

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

BatchArithmetic::BatchArithmetic(const SceneModel& model, const ChipConfig& config, const ChipNumerics& n,
                                 const RayMath& math, const Cfiu& cfiu, double delta)
    : model_(model),
      n_(n),
      math_(math),
      cfiu_(cfiu),
      tme_(model, n, delta, size_t(config.mlp_cache_bytes)),
      vru_(n, config.transmittance_min, config.background) {}

void BatchArithmetic::run(RayPacket& p, Flight& f) {
  tme_.load(f.cv_tag);
  const size_t n = f.coords.size(), F = size_t(model_.feature_channels);
  if (features_.size() < n * F) features_.resize(n * F);
  if (outputs_.size() < n) {
    outputs_.resize(n);
    dir_of_sample_.resize(n);
  }
  if (dirs_.size() < p.rays.size()) {
    dirs_.resize(p.rays.size());
    dir_batch_.resize(p.rays.size(), 0);
  }
  ++batch_;
  for (size_t i = 0; i < n; ++i) {
    const uint8_t r = f.rays[i];
    if (dir_batch_[r] != batch_) {
      RayState& ray = p.rays[r];
      if (ray.dir_input.empty()) {
        // The front end leaves the encoding to this thread; both the codes and
        // the inputs made from them are kept with the ray for its next batches.
        if (ray.dir_code.empty())
          ray.dir_code = Tme::encode_direction(ray.world_dir, model_.mlp_arch.dir_frequencies, n_);
        tme_.direction_input(ray.dir_code, dirs_[r]);
        ray.dir_input = dirs_[r].x;
        ray.dir_input_saturations = dirs_[r].saturations;
      } else {
        dirs_[r].x.assign(ray.dir_input.begin(), ray.dir_input.end());
        dirs_[r].saturations = ray.dir_input_saturations;
      }
      dir_batch_[r] = batch_;
    }
    dir_of_sample_[i] = &dirs_[r];
    cfiu_.weighted_sum(f.block, f.coords[i], &features_[i * F]);
  }
  tme_.eval_batch(n, features_.data(), dir_of_sample_.data(), outputs_.data());
  for (size_t i = 0; i < n; ++i) vru_.composite(p.rays[f.rays[i]], outputs_[i].alpha, outputs_[i].rgb);
  f.stay = has_live_ray_in(math_, model_, p, f.cv_tag);
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
  e.packet = front_.build(e.quad, vru_);
  e.tsps_position_evals = front_.tsps_position_evals() - evals;
  produced_.store(produced + 1, std::memory_order_release);
  return true;
}

FrontEndPacket FrontEndAhead::take() {
  FrontEndPacket e = std::move(ring_[consumed_ % ring_.size()]);
  ++consumed_;
  consumed_shared_.store(consumed_, std::memory_order_release);
  return e;
}

// ------------------------------------------------------------ Worker

Worker::Worker(BatchArithmetic& arithmetic, RpBuffer& buffer, std::vector<Flight>& flights, size_t capacity,
               FrontEndAhead* ahead)
    : arithmetic_(arithmetic), buffer_(buffer), flights_(flights), ahead_(ahead), queue_(capacity) {
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

uint64_t Worker::submit(uint32_t rp) {
  const uint64_t seq = submitted_.load();
  queue_[seq % queue_.size()] = rp;
  submitted_.store(seq + 1);
  signal();
  return seq;
}

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

void Worker::wait(uint64_t seq) {
  main_wait(completed_, seq);
  rethrow_failure();
}

FrontEndPacket Worker::take_packet() {
  if (!ahead_->ready()) {
    signal();  // the worker may be asleep with a full ring that just emptied
    main_wait(ahead_->produced(), ahead_->consumed());
  }
  rethrow_failure();
  FrontEndPacket e = ahead_->take();
  signal();  // room in the ring
  return e;
}

void Worker::loop() {
  uint64_t next = 0;
  auto has_work = [&] { return stop_.load() || submitted_.load() != next || (ahead_ && ahead_->can_produce()); };
  for (;;) {
    const uint64_t seen = signals_.load();
    if (!has_work() && !spin_until(has_work, kWorkerSpin)) {
      worker_sleeping_.store(true);
      if (!has_work()) signals_.wait(seen);
      worker_sleeping_.store(false);
      continue;
    }
    if (stop_.load()) return;
    // Packets first while the engine's supply runs low, else jobs first.
    if (ahead_ && ahead_->can_produce() && (ahead_->running_low() || submitted_.load() == next)) {
      try {
        if (!error_) ahead_->produce_one();
      } catch (...) {
        fail_with(std::current_exception());
        ahead_->produced().fetch_add(1);  // releases a waiting take_packet(), which rethrows
      }
      if (main_sleeping_.load()) ahead_->produced().notify_one();
      continue;
    }
    if (submitted_.load() == next) continue;
    const uint32_t rp = queue_[next % queue_.size()];
    try {
      if (!error_) arithmetic_.run(buffer_[rp], flights_[rp]);
    } catch (...) {
      fail_with(std::current_exception());
    }
    completed_.store(++next);
    if (main_sleeping_.load()) completed_.notify_one();
  }
}

}  // namespace edrnr::sim
