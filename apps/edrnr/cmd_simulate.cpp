// edrnr simulate: renders one frame through the cycle simulator of the EDR-NR
// chip and reports its frame rate, per-unit activity, memory traffic, hit
// rates and energy; writes the image, the statistics, the resolved config and
// a Chrome trace into an output folder.
#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "commands.h"
#include "core/error.h"
#include "core/file_io.h"
#include "core/image.h"
#include "core/limits.h"
#include "core/metrics.h"
#include "data/dataset.h"
#include "model/model_io.h"
#include "render/cameras.h"
#include "render/options.h"
#include "sim/dram_trace.h"
#include "sim/reproduce_runs.h"
#include "sim/simulator.h"

namespace edrnr::cli {
namespace {

namespace fs = std::filesystem;

struct SimulateOptions {
  std::string model, chip = "edr_nr_40nm", dataset, split = "test", disable, output, trace_window = "0:50000";
  std::string dram_trace;  // --dram-trace FILE: the frame's DRAM requests
  int view = 0, width = 0, height = 0, threads = 1;
  double orbit = 30, elevation = 30, radius = 4, fov = 40, clock = 0;
  bool all_points = false, quiet = false, table = false, allow_over_budget = false, sram = false;
  CLI::Option *view_opt, *orbit_opt, *width_opt, *height_opt, *clock_opt, *elev_opt, *radius_opt, *fov_opt;
};

// Where presets of `kind` (chip, dram) are looked for: the working directory,
// beside the executable (build or install tree), and the source tree this
// binary was built from.
std::vector<fs::path> config_dirs(const char* kind) {
  std::vector<fs::path> dirs = {fs::path("configs") / kind};
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const fs::path dir = exe.parent_path();
    dirs.push_back(dir / "configs" / kind);
    dirs.push_back(dir.parent_path() / "configs" / kind);
    dirs.push_back(dir.parent_path() / "share" / "edrnr" / "configs" / kind);
  }
  const fs::path source_root = fs::path(__FILE__).parent_path().parent_path().parent_path();
  if (source_root.is_absolute()) dirs.push_back(source_root / "configs" / kind);
  return dirs;
}

fs::path find_chip_preset(const std::string& name) {
  if (fs::is_regular_file(name)) return name;
  std::string searched;
  for (const fs::path& d : config_dirs("chip")) {
    const fs::path p = d / (name + ".yaml");
    if (fs::is_regular_file(p)) return p;
    searched += "\n  " + d.string();
  }
  fail("--chip '{}': no such file, and no preset {}.yaml in:{}", name, name, searched);
}

void apply_disable(const std::string& list, ChipConfig& c) {
  size_t start = 0;
  while (start <= list.size()) {
    const size_t comma = list.find(',', start);
    const std::string item = list.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    try {
      sim::disable_technique(c, item);
    } catch (const Error& e) {
      fail("--disable '{}': {}", list, e.what());
    }
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
}

// "START:CYCLES" -> the trace window.
void parse_trace_window(const std::string& text, uint64_t& start, uint64_t& cycles) {
  const size_t colon = text.find(':');
  try {
    if (colon == std::string::npos) throw std::invalid_argument(text);
    size_t used = 0;
    start = std::stoull(text.substr(0, colon), &used);
    if (used != colon) throw std::invalid_argument(text);
    const std::string rest = text.substr(colon + 1);
    cycles = std::stoull(rest, &used);
    if (used != rest.size() || rest.empty() || rest[0] == '-' || text[0] == '-') throw std::invalid_argument(text);
  } catch (const std::exception&) {
    fail("--trace-window '{}': expected START:CYCLES, two whole numbers (e.g. 0:50000)", text);
  }
}

struct View {
  Camera camera;
  Image ground_truth;  // empty without a dataset
};

View pick_view(const SimulateOptions& o, const ChipConfig& chip) {
  View v;
  if (o.dataset.empty()) {
    if (o.view_opt->count()) fail("--view needs --dataset");
    const int w = o.width_opt->count() ? o.width : 800;
    const int h = o.height_opt->count() ? o.height : w;
    v.camera = orbit_camera(w, h, o.orbit, o.elevation, o.radius, o.fov);
    return v;
  }
  if (o.orbit_opt->count() || o.elev_opt->count() || o.radius_opt->count() || o.fov_opt->count())
    fail("--orbit, --elevation, --radius and --fov cannot be combined with --dataset (use --view)");
  DatasetOptions d;
  d.split = o.split;
  d.load_images = false;
  const Dataset cams = load_dataset(o.dataset, d);
  if (o.view < 0 || size_t(o.view) >= cams.frames.size())
    fail("--view {}: the {} split of '{}' has views 0..{}", o.view, o.split, o.dataset, int(cams.frames.size()) - 1);
  const Camera& full = cams.frames[size_t(o.view)].camera;
  // The ground truth scales down only by whole factors.
  auto whole = [](int full_size, int wanted) { return wanted > 0 && full_size % wanted == 0 ? full_size / wanted : 0; };
  const int fw = o.width_opt->count() ? whole(full.width, o.width) : -1;
  const int fh = o.height_opt->count() ? whole(full.height, o.height) : -1;
  const int factor = fw < 0 && fh < 0 ? 1 : fw >= 0 ? fw : fh;
  if (factor < 1 || (fw >= 0 && fh >= 0 && fw != fh))
    fail("--width/--height: the dataset's {}x{} views scale down by whole factors only (e.g. {}x{})", full.width,
         full.height, full.width / 2, full.height / 2);
  // Only this view's image is decoded (as load_dataset would give it).
  Frame frame = cams.frames[size_t(o.view)];
  frame.camera = full.downscaled(factor);
  float background[3];
  for (int c = 0; c < 3; ++c) background[c] = chip.background[c];
  v.camera = frame.camera;
  v.ground_truth = downscale(composite_rgba(read_frame_rgba(frame, factor), background), factor);
  return v;
}

// Progress on a terminal: done/total RPs, simulated cycles, rate and ETA.
struct ProgressLine {
  std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now();
  void operator()(const sim::SimProgress& p) const {
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const double f = p.rps_total ? double(p.rps_done) / double(p.rps_total) : 1.0;
    const double eta = f > 0 ? s * (1 - f) / f : 0;
    std::fprintf(stderr, "\r  simulating: %llu/%llu RPs (%.0f %%), %llu cycles, %.1f s, %.2f M cycles/s, ETA %.0f s   ",
                 (unsigned long long)p.rps_done, (unsigned long long)p.rps_total, 100 * f, (unsigned long long)p.cycle,
                 s, s > 0 ? double(p.cycle) / s / 1e6 : 0.0, eta);
    if (p.rps_done == p.rps_total) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  }
};

void run_simulate(const SimulateOptions& o) {
  if (o.threads < 1 || o.threads > 2) fail("--threads {}: must be 1 or 2", o.threads);
  // Two threads hand work to each other thousands of times a frame; on cores
  // kept busy by other work each hand-over waits for the scheduler.
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  if (double load[1]; o.threads == 2 && getloadavg(load, 1) == 1 && load[0] > double(cores))
    std::fprintf(stderr,
                 "edrnr: warning: load average %.1f on %u cores: --threads 2 can be many times slower than 1 on busy "
                 "cores\n",
                 load[0], cores);
  if (o.width_opt->count() || o.height_opt->count())
    limits::check_image_size(o.width_opt->count() ? o.width : 800,
                             o.height_opt->count() ? o.height : (o.width_opt->count() ? o.width : 800),
                             "--width/--height");
  if (o.clock_opt->count()) limits::check_range(o.clock, limits::kMinClockMHz, limits::kMaxClockMHz, "--clock", "MHz");
  if (std::error_code ec; !o.output.empty() && fs::exists(o.output, ec) && !fs::is_directory(o.output, ec))
    fail("-o '{}': not a folder (simulate writes image.png, stats.json, config.yaml and trace.json into a folder)",
         o.output);
  if (!o.dram_trace.empty()) check_output_path(o.dram_trace, "--dram-trace");
  const fs::path preset = find_chip_preset(o.chip);
  sim::SimConfig cfg = sim::load_sim_config(preset, config_dirs("dram"));
  if (!o.disable.empty()) apply_disable(o.disable, cfg.chip);
  if (o.clock_opt->count()) cfg.clock_MHz = o.clock;
  sim::validate(cfg);
  const View view = pick_view(o, cfg.chip);
  const SceneModel model = load_model(o.model);
  check_step_micro(cfg.chip.step_micro, model, "chip config render.step_micro");
  // Table I's SRAM budget: a preset whose buffers do not fit is refused
  // before any simulation, unless the user asks to go over (the report says so).
  const sim::SramBudget budget = sim::sram_budget_for(model, cfg);
  if (o.sram)
    std::cout << "SRAM budget of " << preset.filename().string() << " for " << o.model << "\n" << budget.format();
  if (budget.over_budget()) {
    std::string why;
    for (const std::string& v : budget.violations()) why += "\n  " + v;
    if (!o.allow_over_budget)
      fail(
          "chip preset '{}' does not fit Table I's on-chip SRAM:{}\n(--sram prints every buffer; "
          "--allow-over-budget simulates it anyway)",
          preset.string(), why);
    fmt::print("WARNING     over Table I's SRAM budget (--allow-over-budget):{}\n", why);
  }

  sim::SimOptions opt;
  opt.threads = o.threads;
  if (!o.output.empty()) parse_trace_window(o.trace_window, opt.trace_start_cycle, opt.trace_cycles);
  if (!o.quiet && isatty(STDERR_FILENO)) opt.progress = ProgressLine{};
  std::string dram_trace;
  if (!o.dram_trace.empty()) {
    dram_trace = fmt::format("# DRAM requests of one frame of {} through edrnr simulate ({}, DRAM {})\n", o.model,
                             preset.filename().string(), cfg.memory.dram.name);
    dram_trace += "# address type cycle (DRAM clocks; one burst a line)\n";
    const uint64_t burst_bytes = cfg.memory.dram.burst_bytes();
    opt.dram_request_observer = [&dram_trace, burst_bytes](uint64_t cycle, sim::DramOp op, uint64_t address,
                                                           uint32_t bytes) {
      sim::append_dram_trace(dram_trace, address, bytes, op, cycle, burst_bytes);
    };
  }
  const auto t0 = std::chrono::steady_clock::now();
  sim::SimResult r = sim::simulate_chip(model, view.camera, cfg, opt);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.stats->value("host.seconds", "s", "wall time of the simulation").set(seconds);
  r.stats->value("host.cycles_per_second", "cycles/s", "simulated cycles per second of wall time")
      .set(double(r.summary.cycles) / seconds);

  std::optional<double> gt_psnr;
  if (!view.ground_truth.data.empty()) {
    gt_psnr = psnr(r.image, view.ground_truth);
    r.stats->value("quality.psnr_vs_ground_truth", "dB", "PSNR of the simulated image against the dataset view")
        .set(*gt_psnr);
  }

  // The Table I operating points, each simulated at its own clock.
  nlohmann::json points = nlohmann::json::array();
  std::string points_table;
  if (o.all_points) {
    points_table =
        "operating points (each simulated at its clock; paper figures for 800x800 Synthetic NeRF)\n"
        "   MHz     V     FPS  paper      mW  paper   nJ/px  paper\n";
    sim::SimOptions quiet = opt;
    quiet.trace_cycles = 0;
    quiet.dram_request_observer = nullptr;
    quiet.progress = nullptr;
    for (const sim::PaperOperatingPoint& p : sim::table1_operating_points()) {
      sim::SimConfig c = cfg;
      c.clock_MHz = p.point.frequency_MHz;
      if (!o.quiet && isatty(STDERR_FILENO))
        std::fprintf(stderr, "  operating point %.0f MHz ...\n", p.point.frequency_MHz);
      const sim::SimResult rp = sim::simulate_chip(model, view.camera, c, quiet);
      const sim::EnergyReport e = sim::evaluate_energy(c, rp.energy_run, p.point);
      points_table += fmt::format("  {:4.0f}  {:4.2f}  {:6.2f} {:6.1f}  {:6.1f} {:6.1f}  {:6.2f} {:6.1f}\n",
                                  p.point.frequency_MHz, p.point.voltage_V, rp.summary.fps, p.fps,
                                  e.average_power_W * 1e3, p.power_mW, e.nJ_per_pixel, p.nJ_per_pixel);
      points.push_back({{"clock_MHz", p.point.frequency_MHz},
                        {"voltage_V", p.point.voltage_V},
                        {"cycles", rp.summary.cycles},
                        {"fps", rp.summary.fps},
                        {"power_mW", e.average_power_W * 1e3},
                        {"nJ_per_pixel", e.nJ_per_pixel},
                        {"paper", {{"fps", p.fps}, {"power_mW", p.power_mW}, {"nJ_per_pixel", p.nJ_per_pixel}}}});
    }
  }

  std::ostringstream config_yaml;
  config_yaml << "# Fully resolved chip config of this simulation (preset " << preset.string() << ")\n"
              << sim::sim_config_to_yaml(cfg) << "\n";
  if (!o.output.empty()) {
    const fs::path dir = o.output;
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) fail("-o '{}': cannot create the folder: {}", o.output, ec.message());
    write_png(dir / "image.png", r.image);
    write_file_atomic(dir / "config.yaml", config_yaml.str());
    nlohmann::json j;
    j["model"] = o.model;
    j["chip_preset"] = preset.string();
    j["image"] = {{"width", r.image.width}, {"height", r.image.height}};
    j["stats"] = r.stats->to_json();
    j["hit_rate_series"] = r.hit_rate_series;
    j["sram_budget"] = r.sram_budget.to_json();
    j["sram_budget"]["allowed_over_budget"] = budget.over_budget();
    if (r.energy) j["energy"] = sim::energy_report_json(*r.energy);
    if (!points.empty()) j["operating_points"] = points;
    j["config_yaml"] = config_yaml.str();
    write_file_atomic(dir / "stats.json", j.dump(1) + "\n");
    if (!r.trace.is_null()) write_file_atomic(dir / "trace.json", r.trace.dump() + "\n");
  }

  if (!o.dram_trace.empty()) write_file_atomic(o.dram_trace, dram_trace);

  fmt::print("{} through the EDR-NR cycle simulator ({}), {} thread{}, {:.1f} s ({:.2f} M cycles/s)\n", o.model,
             preset.filename().string(), o.threads, o.threads > 1 ? "s" : "", seconds,
             double(r.summary.cycles) / seconds / 1e6);
  std::cout << sim::format_sim_report(r);
  if (gt_psnr) fmt::print("quality     PSNR against the ground truth (view {}): {:.2f} dB\n", o.view, *gt_psnr);
  std::cout << points_table;
  if (o.table) r.stats->print_table(std::cout);
  if (!o.output.empty())
    fmt::print("wrote       {0}/image.png, {0}/stats.json, {0}/config.yaml{1}\n", o.output,
               r.trace.is_null() ? "" : fmt::format(", {}/trace.json (cycles {})", o.output, o.trace_window));
  if (!o.dram_trace.empty()) fmt::print("wrote       {} (DRAM requests, edrnr dram --trace format)\n", o.dram_trace);
}

void register_simulate_cmd(CLI::App& app) {
  auto o = std::make_shared<SimulateOptions>();
  CLI::App* cmd = app.add_subcommand("simulate", "Render one frame through the cycle simulator of the EDR-NR chip");
  cmd->add_option("model", o->model, "the .edrnr model (its INT4 features and INT8 MLPs are used)")->required();
  cmd->add_option("--chip", o->chip, "chip preset: a name in configs/chip/ or a YAML file")->capture_default_str();
  cmd->add_option("--dataset", o->dataset, "camera and ground truth from a NeRF dataset folder");
  cmd->add_option("--split", o->split, "dataset split")->capture_default_str();
  o->view_opt = cmd->add_option("--view", o->view, "dataset view index")->capture_default_str();
  o->orbit_opt =
      cmd->add_option("--orbit", o->orbit, "without --dataset: orbit camera azimuth (deg)")->capture_default_str();
  o->elev_opt = cmd->add_option("--elevation", o->elevation, "orbit elevation (deg)")->capture_default_str();
  o->radius_opt = cmd->add_option("--radius", o->radius, "orbit radius (scene units)")->capture_default_str();
  o->fov_opt = cmd->add_option("--fov", o->fov, "orbit horizontal field of view (deg)")->capture_default_str();
  o->width_opt = cmd->add_option("--width", o->width, "image width (orbit: default 800; dataset: a whole fraction)");
  o->height_opt = cmd->add_option("--height", o->height, "image height (default: square / the view's aspect)");
  cmd->add_option("--disable", o->disable,
                  "techniques to switch off, comma-separated: zorder, aabb, lagfirst, reorder, ooo, balanced");
  o->clock_opt = cmd->add_option("--clock", o->clock, "core clock in MHz (default: the preset's)");
  cmd->add_option("-o,--output", o->output, "folder for image.png, stats.json, config.yaml and trace.json");
  cmd->add_option("--trace-window", o->trace_window, "cycles of the Chrome trace, START:CYCLES")->capture_default_str();
  cmd->add_option("--threads", o->threads, "1, or 2: the batch arithmetic on a second thread")->capture_default_str();
  cmd->add_flag("--all-points", o->all_points, "also simulate at each of Table I's five operating points");
  cmd->add_flag("--table", o->table, "also print every statistic (name, value, unit, description)");
  cmd->add_flag("--sram", o->sram, "print every on-chip buffer's size against Table I's SRAM budget");
  cmd->add_flag("--allow-over-budget", o->allow_over_budget,
                "simulate a preset whose buffers exceed Table I's SRAM classes (the report is marked)");
  cmd->add_option("--dram-trace", o->dram_trace,
                  "also write the frame's DRAM requests to this file, in the trace format of edrnr dram --trace");
  cmd->add_flag("-q,--quiet", o->quiet, "no progress line");
  cmd->callback([o] { run_simulate(*o); });
}

Registrar reg{55, register_simulate_cmd};

}  // namespace
}  // namespace edrnr::cli
