#pragma once
// The simulator's second thread (SimOptions::threads = 2): it runs the jobs
// the timing model hands it, and builds front-end packets ahead when it has
// none. Which work may move there, and why the statistics stay the same, is
// the simulator's business (docs/simulator.md, Host speed).
#include <atomic>
#include <cstdint>
#include <exception>
#include <functional>
#include <thread>
#include <vector>

#include "sim/packet_ahead.h"

namespace edrnr::sim {

// A job for the second thread: the arithmetic of an RP's batch, or the fine
// traversal of an RP waiting in the RP-ROB.
struct WorkerJob {
  enum Kind : uint32_t { Arithmetic, Traversal };
  Kind kind = Arithmetic;
  uint32_t rp = 0;
};

// Runs jobs on a second thread: traversal jobs first, then arithmetic jobs,
// each kind in submission order; between jobs, and while the timing thread
// waits for one, both threads build front-end packets ahead (`ahead`,
// optional). Each side spins briefly before it sleeps, and wakes the other
// only when that one sleeps, so that a job costs no system call while both
// are busy. Submissions and waits come from one thread (the timing model's).
class SimWorker {
 public:
  using Runner = std::function<void(const WorkerJob&)>;
  // run: does a job (on the worker thread); capacity: the most jobs of each
  // kind outstanding.
  SimWorker(Runner run, size_t capacity, PacketAhead* ahead);
  ~SimWorker();  // stops and joins the thread (jobs left queued are dropped)
  SimWorker(const SimWorker&) = delete;
  SimWorker& operator=(const SimWorker&) = delete;

  // Queues an arithmetic job (at most `capacity` outstanding); returns its
  // sequence number for wait().
  uint64_t submit_arithmetic(uint32_t rp);
  // Whether submit_traversal() may be called: fewer than `capacity` queued.
  bool traversal_room() const { return traversal_submitted_.load() - traversal_taken_.load() < traversal_.size(); }
  // Queues a traversal job. Precondition: traversal_room().
  void submit_traversal(uint32_t rp);
  // Waits until arithmetic job `seq` is done (its results are then visible);
  // rethrows the first error a job raised.
  void wait(uint64_t seq);

 private:
  void wake();
  bool build_ahead();
  void run(const WorkerJob& job);
  void loop();

  Runner run_;
  std::vector<WorkerJob> arithmetic_, traversal_;  // rings
  PacketAhead* ahead_;
  bool worker_builds_ = true;                                          // worker thread only
  std::atomic<uint64_t> submitted_{0}, completed_{0};                  // arithmetic jobs
  std::atomic<uint64_t> traversal_submitted_{0}, traversal_taken_{0};  // traversal jobs
  std::atomic<uint64_t> signal_{0};                                    // bumped by every submission
  std::atomic<bool> stop_{false}, worker_sleeping_{false}, main_sleeping_{false};
  std::exception_ptr error_;
  std::thread thread_;
};

}  // namespace edrnr::sim
