#include "sim/sim_worker.h"

namespace edrnr::sim {

namespace {
// Polls `ready` a few hundred times (a few microseconds) before giving up.
template <class Ready>
bool spin_until(Ready ready) {
  for (int i = 0; i < 256; ++i) {
    if (ready()) return true;
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#endif
  }
  return ready();
}
}  // namespace

SimWorker::SimWorker(Runner run, size_t capacity, PacketAhead* ahead)
    : run_(std::move(run)), arithmetic_(capacity), traversal_(capacity), ahead_(ahead) {
  thread_ = std::thread([this] { loop(); });
}

SimWorker::~SimWorker() {
  stop_.store(true);
  signal_.fetch_add(1);
  signal_.notify_one();
  thread_.join();
}

uint64_t SimWorker::submit_arithmetic(uint32_t rp) {
  const uint64_t seq = submitted_.load();
  arithmetic_[seq % arithmetic_.size()] = {WorkerJob::Arithmetic, rp};
  submitted_.store(seq + 1);
  wake();
  return seq;
}

void SimWorker::submit_traversal(uint32_t rp) {
  const uint64_t seq = traversal_submitted_.load();
  traversal_[seq % traversal_.size()] = {WorkerJob::Traversal, rp};
  traversal_submitted_.store(seq + 1);
  wake();
}

void SimWorker::wait(uint64_t seq) {
  auto done = [&] { return completed_.load() > seq; };
  while (ahead_ && !done() && ahead_->build_one()) {
  }
  if (!spin_until(done)) {
    main_sleeping_.store(true);
    for (uint64_t d = completed_.load(); d <= seq; d = completed_.load()) completed_.wait(d);
    main_sleeping_.store(false);
  }
  if (error_) std::rethrow_exception(error_);
}

void SimWorker::wake() {
  signal_.fetch_add(1);
  if (worker_sleeping_.load()) signal_.notify_one();
}

// One packet ahead; an error stops the worker's building (the timing thread
// meets it when it builds the packets itself).
bool SimWorker::build_ahead() {
  try {
    return ahead_->build_one();
  } catch (...) {
    worker_builds_ = false;
    return false;
  }
}

void SimWorker::run(const WorkerJob& job) {
  try {
    if (!error_) run_(job);
  } catch (...) {
    error_ = std::current_exception();
  }
}

void SimWorker::loop() {
  uint64_t next = 0, next_traversal = 0;
  for (;;) {
    const uint64_t signal = signal_.load();
    if (next_traversal < traversal_submitted_.load()) {
      const WorkerJob job = traversal_[next_traversal % traversal_.size()];
      traversal_taken_.store(++next_traversal);
      run(job);
      continue;
    }
    if (next < submitted_.load()) {
      run(arithmetic_[next % arithmetic_.size()]);
      completed_.store(++next);
      if (main_sleeping_.load()) completed_.notify_one();
      continue;
    }
    if (stop_.load()) return;
    if (ahead_ && worker_builds_ && build_ahead()) continue;
    if (!spin_until([&] { return signal_.load() != signal; })) {
      worker_sleeping_.store(true);
      if (signal_.load() == signal) signal_.wait(signal);
      worker_sleeping_.store(false);
    }
  }
}

}  // namespace edrnr::sim
