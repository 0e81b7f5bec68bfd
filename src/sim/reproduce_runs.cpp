#include "sim/reproduce_runs.h"

#include <fmt/format.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <exception>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>

#include "core/error.h"
#include "core/file_io.h"
#include "core/metrics.h"
#include "sim/energy.h"
#include "sim/simulator.h"

namespace edrnr::sim {

namespace fs = std::filesystem;

namespace {

// Bump when what a run's JSON holds changes: older files then run again.
constexpr const char* kRunFormat = "edrnr-reproduce-run-1";

uint64_t mix64(uint64_t x) {
  x ^= x >> 33;
  x *= 0xff51afd7ed558ccdULL;
  x ^= x >> 33;
  x *= 0xc4ceb9fe1a85ec53ULL;
  x ^= x >> 33;
  return x;
}

std::string camera_text(const Camera& c) {
  std::string s = fmt::format("{} {} {:.17g} {:.17g} {:.17g} {:.17g}", c.width, c.height, c.fx, c.fy, c.cx, c.cy);
  for (double v : c.c2w) s += fmt::format(" {:.17g}", v);
  return s;
}

// The Table I point with this clock, if any.
const PaperOperatingPoint* table1_point_at(double clock_MHz) {
  for (const PaperOperatingPoint& p : table1_operating_points())
    if (std::abs(p.point.frequency_MHz - clock_MHz) < 1e-9) return &p;
  return nullptr;
}

std::string config_yaml_text(const SimConfig& config) {
  std::ostringstream s;
  s << sim_config_to_yaml(config);
  return s.str();
}

// Simulates one run and writes its JSON (and image).
void simulate_run(const ReproScene& scene, const RunSpec& spec, const fs::path& runs_dir) {
  const ReproView& view = scene.views[spec.view];
  SimOptions options;
  options.threads = 1;
  const auto t0 = std::chrono::steady_clock::now();
  SimResult r = simulate_chip(*scene.model, view.camera, spec.config, options);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.stats->value("host.seconds", "s", "wall time of the simulation").set(seconds);
  r.stats->value("host.cycles_per_second", "cycles/s", "simulated cycles per second of wall time")
      .set(seconds > 0 ? double(r.summary.cycles) / seconds : 0.0);
  if (!view.ground_truth.data.empty())
    r.stats->value("quality.psnr_vs_ground_truth", "dB", "PSNR of the simulated image against the dataset view")
        .set(psnr(r.image, view.ground_truth));

  nlohmann::json j;
  j["format"] = kRunFormat;
  j["key"] = spec.key;
  j["scene"] = scene.name;
  j["view"] = view.index;
  j["variant"] = spec.variant.name();
  j["clock_MHz"] = spec.config.clock_MHz;
  j["model"] = scene.model_source;
  j["model_hash"] = scene.model_hash;
  const bool keep_image = spec.variant.kind == RunVariant::Kind::Full;
  j["image"] = {{"width", r.image.width},
                {"height", r.image.height},
                {"hash", run_hash(r.image.data.data(), r.image.data.size() * sizeof(float))},
                {"file", keep_image ? nlohmann::json(spec.key + ".png") : nlohmann::json(nullptr)}};
  j["stats"] = r.stats->to_json();
  j["hit_rate_series"] = r.hit_rate_series;
  j["sram_budget"] = r.sram_budget.to_json();
  if (r.energy) j["energy"] = energy_report_json(*r.energy);
  j["voltage_extrapolated"] = r.voltage_extrapolated;
  if (const PaperOperatingPoint* p = table1_point_at(spec.config.clock_MHz);
      p && !spec.config.energy.events_csv.empty()) {
    const EnergyReport e = evaluate_energy(spec.config, r.energy_run, p->point);
    j["energy_table1"] = energy_report_json(e);
  }
  j["config_yaml"] = config_yaml_text(spec.config);
  if (keep_image) write_png(run_image_path(runs_dir, spec.key), r.image);
  write_file_atomic(run_json_path(runs_dir, spec.key), j.dump(1) + "\n");
}

}  // namespace

const std::vector<std::string>& technique_names() {
  static const std::vector<std::string> names = {"zorder", "aabb", "lagfirst", "reorder", "ooo", "balanced"};
  return names;
}

const char* technique_label(const std::string& t) {
  if (t == "zorder") return "ZORG (Z-order scan)";
  if (t == "aabb") return "AABB (ABT + TSPS)";
  if (t == "lagfirst") return "LFAU (lag-first)";
  if (t == "reorder") return "RP-ROB (reordering)";
  if (t == "ooo") return "OoO-SI (out-of-order issue)";
  if (t == "balanced") return "balanced banks";
  return "?";
}

void disable_technique(ChipConfig& c, const std::string& t) {
  if (t == "zorder")
    c.switches.z_order = false;
  else if (t == "aabb")
    c.switches.aabb = false;
  else if (t == "lagfirst")
    c.switches.lag_first = false;
  else if (t == "reorder")
    c.switches.rp_reorder = false;
  else if (t == "ooo")
    c.switches.ooo_issue = false;
  else if (t == "balanced")
    c.bank_mapping = chip::BankMapping::Direct;
  else
    fail("unknown technique '{}' (known: zorder, aabb, lagfirst, reorder, ooo, balanced)", t);
}

std::string RunVariant::name() const {
  switch (kind) {
    case Kind::Full:
      return "full";
    case Kind::TechniqueOff:
      return "off_" + technique;
    case Kind::AllOff:
      return "all_off";
    case Kind::OperatingPoint:
      return fmt::format("point_{:g}MHz", clock_MHz);
  }
  return "?";
}

std::vector<RunVariant> evaluation_variants(const SimConfig& preset) {
  std::vector<RunVariant> v;
  v.push_back({RunVariant::Kind::AllOff, "", preset.clock_MHz});
  for (const std::string& t : technique_names()) v.push_back({RunVariant::Kind::TechniqueOff, t, preset.clock_MHz});
  v.push_back({RunVariant::Kind::Full, "", preset.clock_MHz});
  for (const PaperOperatingPoint& p : table1_operating_points())
    if (std::abs(p.point.frequency_MHz - preset.clock_MHz) >= 1e-9)
      v.push_back({RunVariant::Kind::OperatingPoint, "", p.point.frequency_MHz});
  return v;
}

SimConfig variant_config(const SimConfig& preset, const RunVariant& variant) {
  SimConfig c = preset;
  switch (variant.kind) {
    case RunVariant::Kind::Full:
      break;
    case RunVariant::Kind::TechniqueOff:
      disable_technique(c.chip, variant.technique);
      break;
    case RunVariant::Kind::AllOff:
      for (const std::string& t : technique_names()) disable_technique(c.chip, t);
      break;
    case RunVariant::Kind::OperatingPoint:
      c.clock_MHz = variant.clock_MHz;
      break;
  }
  return c;
}

std::string run_hash(const void* data, size_t size) {
  const auto* p = static_cast<const uint8_t*>(data);
  uint64_t fnv = 0xcbf29ce484222325ULL, mx = 0x9e3779b97f4a7c15ULL ^ size;
  for (size_t i = 0; i < size; ++i) fnv = (fnv ^ p[i]) * 0x100000001b3ULL;
  size_t i = 0;
  for (; i + 8 <= size; i += 8) {
    uint64_t w;
    std::memcpy(&w, p + i, 8);
    mx = mix64(mx ^ w) + 0x632be59bd9b4e019ULL;
  }
  uint64_t tail = 0;
  for (size_t k = 0; i + k < size; ++k) tail |= uint64_t(p[i + k]) << (8 * k);
  mx = mix64(mx ^ tail ^ (uint64_t(size) << 1));
  return fmt::format("{:016x}{:016x}", fnv, mx);
}

std::string run_key(const ReproScene& scene, const ReproView& view, const SimConfig& config) {
  std::string text = std::string(kRunFormat) + "\nmodel " + scene.model_hash + "\nview " + std::to_string(view.index) +
                     "\ncamera " + camera_text(view.camera) + "\nsize " + std::to_string(view.camera.width) + "x" +
                     std::to_string(view.camera.height) + "\nground_truth ";
  if (view.ground_truth.data.empty())
    text += "none";
  else
    text += run_hash(view.ground_truth.data.data(), view.ground_truth.data.size() * sizeof(float));
  text += "\nconfig\n" + config_identity_text(config);
  return run_hash(text.data(), text.size());
}

std::string config_identity_text(const SimConfig& config) {
  std::string text = config_yaml_text(config);
  // The config names its energy tables by path: their contents are part of
  // the key too, so an edited table (a refitted row) runs again.
  for (const std::filesystem::path& table : {config.energy.events_csv, config.energy.leakage_csv})
    text += "\ntable " + (table.empty() ? std::string("none") : read_file_text(table));
  return text;
}

std::string config_hash(const SimConfig& config) {
  const std::string text = config_identity_text(config);
  return run_hash(text.data(), text.size());
}

std::vector<RunSpec> plan_runs(const std::vector<ReproScene>& scenes, const SimConfig& preset) {
  std::vector<RunSpec> plan;
  const std::vector<RunVariant> variants = evaluation_variants(preset);
  for (size_t s = 0; s < scenes.size(); ++s)
    for (size_t v = 0; v < scenes[s].views.size(); ++v)
      for (const RunVariant& variant : variants) {
        RunSpec spec;
        spec.scene = s;
        spec.view = v;
        spec.variant = variant;
        spec.config = variant_config(preset, variant);
        try {
          validate(spec.config);
        } catch (const Error& e) {
          fail("variant {} of the chip preset: {}", variant.name(), e.what());
        }
        spec.key = run_key(scenes[s], scenes[s].views[v], spec.config);
        plan.push_back(std::move(spec));
      }
  return plan;
}

fs::path run_json_path(const fs::path& runs_dir, const std::string& key) { return runs_dir / (key + ".json"); }
fs::path run_image_path(const fs::path& runs_dir, const std::string& key) { return runs_dir / (key + ".png"); }

std::optional<nlohmann::json> load_cached_run(const fs::path& runs_dir, const std::string& key) {
  const fs::path p = run_json_path(runs_dir, key);
  std::error_code ec;
  if (!fs::is_regular_file(p, ec)) return std::nullopt;
  try {
    nlohmann::json j = nlohmann::json::parse(read_file_text(p));
    if (!j.is_object() || j.value("format", "") != kRunFormat || j.value("key", "") != key) return std::nullopt;
    if (j["image"].is_object() && j["image"]["file"].is_string() &&
        !fs::is_regular_file(runs_dir / j["image"]["file"].get<std::string>(), ec))
      return std::nullopt;
    return j;
  } catch (const std::exception&) {
    return std::nullopt;  // half-written or foreign: run it again
  }
}

ExecuteSummary execute_runs(const std::vector<ReproScene>& scenes, const std::vector<RunSpec>& plan,
                            const fs::path& runs_dir, const ExecuteOptions& options) {
  if (options.jobs < 1) fail("--jobs {}: must be at least 1", options.jobs);
  std::error_code ec;
  fs::create_directories(runs_dir, ec);
  if (ec) fail("'{}': cannot create the folder: {}", runs_dir.string(), ec.message());

  ExecuteSummary summary;
  std::map<std::string, size_t> first;  // key -> plan index
  std::vector<size_t> todo;
  for (size_t i = 0; i < plan.size(); ++i) {
    if (!first.emplace(plan[i].key, i).second) continue;
    ++summary.distinct;
    if (load_cached_run(runs_dir, plan[i].key))
      ++summary.cached;
    else
      todo.push_back(i);
  }

  const auto t0 = std::chrono::steady_clock::now();
  std::atomic<size_t> next{0};
  std::atomic<bool> stop{false};
  std::mutex mutex;  // guards done, error and the progress callback
  size_t done = 0;
  std::exception_ptr error;
  auto worker = [&] {
    for (;;) {
      const size_t n = next.fetch_add(1);
      if (n >= todo.size() || stop) return;
      const RunSpec& spec = plan[todo[n]];
      try {
        simulate_run(scenes[spec.scene], spec, runs_dir);
      } catch (...) {
        std::lock_guard<std::mutex> lock(mutex);
        if (!error) {
          try {
            throw;
          } catch (const Error& e) {
            error = std::make_exception_ptr(
                Error(fmt::format("simulating {} view {} ({}): {}", scenes[spec.scene].name,
                                  scenes[spec.scene].views[spec.view].index, spec.variant.name(), e.what())));
          } catch (...) {
            error = std::current_exception();
          }
        }
        stop = true;
        return;
      }
      std::lock_guard<std::mutex> lock(mutex);
      ++done;
      if (options.progress)
        options.progress(
            {done, todo.size(), std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()});
    }
  };
  const size_t threads = std::min(size_t(options.jobs), todo.size());
  std::vector<std::thread> pool;
  for (size_t t = 1; t < threads; ++t) pool.emplace_back(worker);
  if (threads > 0) worker();
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);
  summary.ran = done;
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return summary;
}

}  // namespace edrnr::sim
