#include "serve_sim.h"

#include <fmt/format.h>

#include <chrono>

#include "core/error.h"
#include "core/metrics.h"
#include "render/options.h"
#include "serve_image.h"
#include "serve_validate.h"
#include "sim/sim_config.h"
#include "sim/simulator.h"

namespace edrnr::serve {

namespace {

// Thrown from the progress callback to stop a cancelled simulation.
struct Cancelled {};

}  // namespace

SimQueue::SimQueue(Catalog& catalog, std::vector<std::filesystem::path> dram_dirs, SimQueueOptions options)
    : catalog_(catalog), dram_dirs_(std::move(dram_dirs)), options_(options) {
  thread_ = std::thread([this] { worker(); });
}

SimQueue::~SimQueue() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
    if (running_) running_->cancel = true;
    for (auto& j : queue_) j->state = "cancelled";
    queue_.clear();
  }
  wake_.notify_all();
  thread_.join();
}

uint64_t SimQueue::submit(SimRequest request) {
  std::lock_guard lock(mutex_);
  auto active = [&](const std::shared_ptr<Job>& j) { return j && j->request.client == request.client; };
  if (active(running_))
    reject(429, "client",
           fmt::format("this client already has simulation {} running; wait for it or cancel it", running_->id));
  for (const auto& j : queue_)
    if (active(j))
      reject(429, "client",
             fmt::format("this client already has simulation {} queued; wait for it or cancel it", j->id));
  if (queue_.size() >= options_.max_queued)
    reject(503, "", fmt::format("the simulation queue is full ({} jobs waiting); try again later", queue_.size()));
  auto job = std::make_shared<Job>();
  job->id = next_id_++;
  job->request = std::move(request);
  jobs_[job->id] = job;
  queue_.push_back(job);
  wake_.notify_all();
  return job->id;
}

std::shared_ptr<SimQueue::Job> SimQueue::find(uint64_t id) const {
  auto it = jobs_.find(id);
  if (it == jobs_.end())
    reject(404, "job", fmt::format("simulation {}: no such job (finished jobs are kept for a while)", id));
  return it->second;
}

nlohmann::json SimQueue::status(uint64_t id) const {
  std::lock_guard lock(mutex_);
  const std::shared_ptr<Job> job = find(id);
  nlohmann::json j = {{"id", job->id},
                      {"state", job->state},
                      {"model", job->request.model},
                      {"presets", job->request.presets},
                      {"view", job->request.view}};
  if (job->state == "queued")
    for (size_t i = 0; i < queue_.size(); ++i)
      if (queue_[i] == job) j["queue_position"] = i + 1;  // 1: next
  const double total = double(job->rps_total.load()), done = double(job->rps_done.load());
  const int index = job->preset_index.load();
  const double count = double(job->request.presets.size());
  double fraction = job->state == "done" ? 1.0 : (index + (total > 0 ? done / total : 0.0)) / count;
  j["progress"] = {{"fraction", fraction},
                   {"cycle", job->cycle.load()},
                   {"rps_done", job->rps_done.load()},
                   {"rps_total", job->rps_total.load()},
                   {"preset_index", index}};
  if (!job->error.empty()) j["error"] = job->error;
  nlohmann::json results = nlohmann::json::array();
  for (size_t i = 0; i < job->results.size(); ++i)
    results.push_back({{"preset", job->results[i].preset},
                       {"report", job->results[i].report},
                       {"image_url", fmt::format("/api/sim/{}/image/{}", job->id, i)},
                       {"trace_url", fmt::format("/api/sim/{}/trace/{}", job->id, i)}});
  j["results"] = results;
  return j;
}

std::string SimQueue::image_png(uint64_t id, size_t index) const {
  std::lock_guard lock(mutex_);
  const std::shared_ptr<Job> job = find(id);
  if (job->state != "done" || index >= job->results.size())
    reject(404, "index", fmt::format("simulation {}: no image {} (state {})", id, index, job->state));
  return job->results[index].image_png;
}

std::string SimQueue::trace_json(uint64_t id, size_t index) const {
  std::lock_guard lock(mutex_);
  const std::shared_ptr<Job> job = find(id);
  if (job->state != "done" || index >= job->results.size() || job->results[index].trace_json.empty())
    reject(404, "index", fmt::format("simulation {}: no trace {} (state {})", id, index, job->state));
  return job->results[index].trace_json;
}

void SimQueue::cancel(uint64_t id, const std::string& client) {
  std::lock_guard lock(mutex_);
  const std::shared_ptr<Job> job = find(id);
  if (job->request.client != client) reject(409, "client", fmt::format("simulation {} belongs to another client", id));
  if (job->state != "queued" && job->state != "running")
    reject(409, "job", fmt::format("simulation {} is already {}", id, job->state));
  job->cancel = true;
  if (job->state == "queued") {
    std::erase(queue_, job);
    job->state = "cancelled";
    finished_.push_back(id);
  }
}

size_t SimQueue::queued() const {
  std::lock_guard lock(mutex_);
  return queue_.size();
}

void SimQueue::worker() {
  for (;;) {
    std::shared_ptr<Job> job;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      job = queue_.front();
      queue_.pop_front();
      job->state = "running";
      running_ = job;
    }
    std::string state = "done", error;
    try {
      run_job(*job);
    } catch (const Cancelled&) {
      state = "cancelled";
    } catch (const std::exception& e) {
      state = "failed";
      error = e.what();
    }
    std::lock_guard lock(mutex_);
    job->state = state;
    job->error = error;
    running_.reset();
    finished_.push_back(job->id);
    while (finished_.size() > options_.kept_jobs) {
      jobs_.erase(finished_.front());
      finished_.pop_front();
    }
  }
}

void SimQueue::run_job(Job& job) {
  const SimRequest& rq = job.request;
  const std::shared_ptr<const SceneModel> model = catalog_.model(rq.model);
  for (size_t i = 0; i < rq.presets.size(); ++i) {
    job.preset_index = int(i);
    job.rps_done = 0;
    job.cycle = 0;
    const ChipPresetEntry& preset = catalog_.preset(rq.presets[i]);
    sim::SimConfig cfg = sim::load_sim_config(preset.path, dram_dirs_);
    sim::validate(cfg);
    check_step_micro(cfg.chip.step_micro, model->micro_res, "chip config render.step_micro");
    const sim::SramBudget budget = sim::sram_budget_for(*model, cfg);
    if (budget.over_budget() && !rq.allow_over_budget) {
      std::string why;
      for (const std::string& v : budget.violations()) why += "; " + v;
      fail("chip preset '{}' does not fit Table I's on-chip SRAM{} (allow_over_budget simulates it anyway)",
           preset.name, why);
    }
    sim::SimOptions opt;
    opt.threads = 1;
    opt.trace_start_cycle = 0;
    opt.trace_cycles = options_.trace_cycles;
    opt.progress_interval_cycles = uint64_t(1) << 15;
    opt.progress = [&job](const sim::SimProgress& p) {
      job.cycle = p.cycle;
      job.rps_done = p.rps_done;
      job.rps_total = p.rps_total;
      if (job.cancel) throw Cancelled{};
    };
    const auto t0 = std::chrono::steady_clock::now();
    sim::SimResult r = sim::simulate_chip(*model, rq.camera, cfg, opt);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    r.stats->value("host.seconds", "s", "wall time of the simulation").set(seconds);

    nlohmann::json report;
    report["model"] = rq.model;
    report["preset"] = preset.name;
    report["view"] = rq.view;
    report["image"] = {{"width", r.image.width}, {"height", r.image.height}};
    report["summary"] = {{"cycles", r.summary.cycles},
                         {"clock_MHz", r.summary.clock_MHz},
                         {"frame_time_s", r.summary.frame_time_s},
                         {"fps", r.summary.fps},
                         {"samples", r.summary.samples},
                         {"samples_per_cycle", r.summary.samples_per_cycle},
                         {"dram_read_bytes", r.summary.dram_read_bytes},
                         {"dram_write_bytes", r.summary.dram_write_bytes},
                         {"micro_grid_hit_rate", r.summary.micro_grid_hit_rate},
                         {"feature_hit_rate", r.summary.feature_hit_rate},
                         {"mlp_hit_rate", r.summary.mlp_hit_rate},
                         {"host_seconds", seconds},
                         {"voltage_extrapolated", r.voltage_extrapolated}};
    if (r.energy) {
      report["summary"]["nJ_per_pixel"] = r.energy->nJ_per_pixel;
      report["summary"]["power_mW"] = r.energy->average_power_W * 1e3;
      report["energy"] = sim::energy_report_json(*r.energy);
    }
    if (rq.ground_truth && rq.ground_truth->width == r.image.width && rq.ground_truth->height == r.image.height)
      report["summary"]["psnr_vs_ground_truth_dB"] = psnr(r.image, *rq.ground_truth);
    report["stats"] = r.stats->to_json();
    report["hit_rate_series"] = r.hit_rate_series;
    report["sram_budget"] = r.sram_budget.to_json();
    report["sram_budget"]["allowed_over_budget"] = budget.over_budget();
    report["text"] = sim::format_sim_report(r);

    Result res;
    res.preset = preset.name;
    res.image_png = encode_png(r.image);
    if (!r.trace.is_null()) res.trace_json = r.trace.dump();
    res.report = std::move(report);
    std::lock_guard lock(mutex_);
    job.results.push_back(std::move(res));
  }
}

}  // namespace edrnr::serve
