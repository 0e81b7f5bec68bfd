#pragma once
// Cycle simulations for `edrnr serve`, run one at a time on a worker thread.
// A job simulates one view of one model on one or two chip presets (two: side
// by side). Each client (a browser tab, by its client id) has at most one job
// queued or running; the queue holds at most max_queued jobs; finished jobs
// are kept (report, image, Chrome trace) until kept_jobs newer ones finished.
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "core/image.h"
#include "data/camera.h"
#include "serve_catalog.h"

namespace edrnr::serve {

struct SimRequest {
  std::string client;                // is_client_id()
  std::string model;                 // a catalog model name
  std::vector<std::string> presets;  // 1 or 2 catalog preset names
  Camera camera;
  nlohmann::json view;                        // how the camera was chosen (echoed in the report)
  std::shared_ptr<const Image> ground_truth;  // the dataset view at the camera's size, or null
  bool allow_over_budget = false;
};

struct SimQueueOptions {
  size_t max_queued = 8;          // jobs waiting (the running one not counted)
  size_t kept_jobs = 16;          // finished jobs kept for their reports and files
  uint64_t trace_cycles = 50000;  // Chrome trace window from cycle 0
};

class SimQueue {
 public:
  SimQueue(Catalog& catalog, std::vector<std::filesystem::path> dram_dirs, SimQueueOptions options = {});
  // Cancels the running job, drops the queue and joins the worker.
  ~SimQueue();
  SimQueue(const SimQueue&) = delete;
  SimQueue& operator=(const SimQueue&) = delete;

  // Queues a job and returns its id. RequestError 429 if the client already
  // has a job queued or running (the message names it), 503 if the queue is full.
  uint64_t submit(SimRequest request);

  // {"id", "state": queued|running|done|failed|cancelled, "queue_position",
  //  "progress": {"fraction", "cycle", "rps_done", "rps_total", "preset_index"},
  //  "error", "results": [ {"preset", "report": {...}} ]}. RequestError 404 for an unknown id.
  nlohmann::json status(uint64_t id) const;
  // A finished job's image (PNG) or Chrome trace (JSON) of result `index`. 404 if absent.
  std::string image_png(uint64_t id, size_t index) const;
  std::string trace_json(uint64_t id, size_t index) const;
  // Cancels a queued or running job of `client`. 404 unknown id, 409 if another client's or finished.
  void cancel(uint64_t id, const std::string& client);

  // Jobs waiting, and whether one is running (for tests and the status line).
  size_t queued() const;

 private:
  struct Result {
    std::string preset;
    nlohmann::json report;
    std::string image_png;
    std::string trace_json;
  };
  struct Job {
    uint64_t id = 0;
    SimRequest request;
    std::string state = "queued";
    std::string error;
    std::vector<Result> results;
    std::atomic<bool> cancel{false};
    std::atomic<uint64_t> cycle{0}, rps_done{0}, rps_total{0};
    std::atomic<int> preset_index{0};
  };

  void worker();
  void run_job(Job& job);
  std::shared_ptr<Job> find(uint64_t id) const;  // 404 if unknown; caller holds mutex_

  Catalog& catalog_;
  std::vector<std::filesystem::path> dram_dirs_;
  SimQueueOptions options_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<std::shared_ptr<Job>> queue_;
  std::shared_ptr<Job> running_;
  std::map<uint64_t, std::shared_ptr<Job>> jobs_;  // every job still known, by id
  std::deque<uint64_t> finished_;                  // oldest first
  uint64_t next_id_ = 1;
  bool stopping_ = false;
  std::thread thread_;
};

}  // namespace edrnr::serve
