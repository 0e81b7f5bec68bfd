// edrnr reproduce: the paper's evaluation in one command. Simulates every
// scene that has a model and data over a set of test views, with the full
// design, each technique switched off, all of them off, and at Table I's
// operating points (resumable: finished simulations are cached under
// OUT/runs/), then writes a report beside the paper's numbers: results.json,
// CSV files, report.md, and (scripts/report_figures.py, matplotlib) the
// figures and a self-contained report.html. docs/reproduction.md.
#include <fmt/format.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "commands.h"
#include "core/error.h"
#include "core/file_io.h"
#include "core/image.h"
#include "data/dataset.h"
#include "model/model_io.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "search_paths.h"
#include "sim/reproduce_figures.h"
#include "sim/reproduce_report.h"
#include "sim/reproduce_runs.h"
#include "sim/simulator.h"
#include "subprocess.h"

namespace edrnr::cli {
namespace {

namespace fs = std::filesystem;

// The Synthetic-NeRF scenes of the paper's Fig. 16, in its order.
const char* const kPaperScenes[] = {"chair", "lego", "mic", "hotdog"};
// --quick: procedural scenes, micro grid, image size and orbit positions.
const char* const kQuickScenes[] = {"several", "torus"};
constexpr int kQuickMicroRes = 64;

struct ReproduceOptions {
  std::string data, models, chip = "edr_nr_40nm", views, out, figures = "auto";
  int jobs = 0, downscale = 1, quick_size = 96;
  bool quick = false, quiet = false, allow_over_budget = false;
  CLI::Option *data_opt = nullptr, *models_opt = nullptr, *views_opt = nullptr, *jobs_opt = nullptr;
};

std::vector<int> parse_views(const std::string& text) {
  std::vector<int> views;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    size_t used = 0;
    int v = -1;
    try {
      v = std::stoi(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != item.size() || v < 0)
      fail("--views '{}': '{}' is not a view index (e.g. 0,8,16)", text, item);
    views.push_back(v);
  }
  if (views.empty()) fail("--views '{}': no view given (e.g. 0,8,16)", text);
  return views;
}

// The first existing folder of `candidates`, or none.
std::optional<fs::path> first_dir(const std::vector<fs::path>& candidates) {
  std::error_code ec;
  for (const fs::path& p : candidates)
    if (fs::is_directory(p, ec)) return p;
  return std::nullopt;
}

std::string joined(const std::vector<fs::path>& paths) {
  std::string s;
  for (const fs::path& p : paths) s += "\n  " + p.string();
  return s;
}

// A folder given by a flag must exist; a default is looked for in the working
// directory and then in the source tree.
fs::path resolve_dir(const CLI::Option* opt, const std::string& value, const fs::path& default_relative,
                     const fs::path& default_in_source, const char* what) {
  std::error_code ec;
  if (opt->count()) {
    if (!fs::is_directory(value, ec)) fail("{} '{}': no such folder", opt->get_name(), value);
    return value;
  }
  std::vector<fs::path> candidates = {default_relative};
  if (!source_tree().empty()) candidates.push_back(source_tree() / default_in_source);
  if (auto d = first_dir(candidates)) return *d;
  fail("no {} folder found (looked in:{}); give one with {}, or run with --quick", what, joined(candidates),
       opt->get_name());
}

sim::ReproScene quick_scene(const std::string& name, const std::vector<int>& views, int size) {
  ProceduralOptions po;
  po.micro_res = kQuickMicroRes;
  po.store_float = false;
  sim::ReproScene s;
  s.name = name;
  s.model_source = fmt::format("procedural '{}' (micro_res {}, make_procedural_model)", name, kQuickMicroRes);
  auto model = std::make_shared<SceneModel>(make_procedural_model(name, procedural_shapes(name), po));
  const std::vector<uint8_t> bytes = serialize_model(*model);
  s.model_hash = sim::run_hash(bytes.data(), bytes.size());
  s.model = model;
  for (int v : views) s.views.push_back({v, orbit_camera(size, size, 30.0 + 45.0 * v, 30.0, 4.0, 40.0), {}});
  return s;
}

// A Synthetic-NeRF scene: its model (checked) and its test views with their ground truth.
sim::ReproScene dataset_scene(const std::string& name, const fs::path& model_path, const fs::path& data_dir,
                              const std::vector<int>& views, const ReproduceOptions& o, const sim::SimConfig& cfg,
                              const fs::path& preset) {
  sim::ReproScene s;
  s.name = name;
  s.model_source = model_path.string();
  s.data_source = data_dir.string();
  const std::vector<uint8_t> bytes = read_file_bytes(model_path);
  s.model_hash = sim::run_hash(bytes.data(), bytes.size());
  auto model = std::make_shared<SceneModel>(parse_model(bytes.data(), bytes.size(), model_path.string()));
  try {
    check_chip_model(*model);
  } catch (const Error& e) {
    fail("model '{}' cannot be rendered by the chip: {}", model_path.string(), e.what());
  }
  const sim::SramBudget budget = sim::sram_budget_for(*model, cfg);
  if (budget.over_budget() && !o.allow_over_budget) {
    std::string why;
    for (const std::string& v : budget.violations()) why += "\n  " + v;
    fail(
        "chip preset '{}' does not fit Table I's on-chip SRAM for model '{}':{}\n(--allow-over-budget simulates it "
        "anyway)",
        preset.string(), model_path.string(), why);
  }
  s.model = model;

  DatasetOptions d;
  d.split = "test";
  d.load_images = false;
  d.downscale = o.downscale;
  for (int c = 0; c < 3; ++c) d.background[c] = cfg.chip.background[c];
  const Dataset ds = load_dataset(data_dir, d);
  for (int v : views) {
    if (size_t(v) >= ds.frames.size())
      fail("--views: {} has test views 0..{}, not {}", data_dir.string(), int(ds.frames.size()) - 1, v);
    const Frame& frame = ds.frames[size_t(v)];
    Image gt = composite_rgba(read_frame_rgba(frame, o.downscale), d.background);
    if (o.downscale > 1) gt = downscale(gt, o.downscale);
    s.views.push_back({v, frame.camera, std::move(gt)});
  }
  return s;
}

// Runs `python script args...`, where python is a name looked up in PATH or a
// path. Returns its exit status (127: python could not be started).
int run_python(const std::string& python, const fs::path& script, const std::vector<std::string>& script_args) {
  std::vector<std::string> argv = {python, script.string()};
  argv.insert(argv.end(), script_args.begin(), script_args.end());
  return run_program(argv);
}

// Draws the figures and writes report.html with scripts/report_figures.py.
// The python3 in PATH may be another installation than Debian's (which has
// python3-matplotlib), so each candidate is asked first whether it can draw.
// Returns what went wrong, or "" when everything was written.
std::string make_figures(const fs::path& results, bool plots) {
  const std::optional<fs::path> script = find_shipped_file("scripts/report_figures.py");
  if (!script) return "scripts/report_figures.py was not found beside the source tree or the executable";
  std::string python;  // the first that starts; preferably one with matplotlib
  bool has_matplotlib = false;
  for (const char* candidate : {"python3", "/usr/bin/python3"}) {
    const int rc = run_python(candidate, *script, {"--check"});
    if (rc == 0 || rc == 3) {
      if (python.empty() || rc == 0) python = candidate;
      if (rc == 0) {
        has_matplotlib = true;
        break;
      }
    }
  }
  if (python.empty()) return "python3 could not be started: install python3 and python3-matplotlib (scripts/setup.sh)";
  std::vector<std::string> args = {results.string()};
  if (!plots || !has_matplotlib) args.push_back("--no-figures");
  const int rc = run_python(python, *script, args);
  if (rc != 0) return fmt::format("{} {} failed (exit status {})", python, script->string(), rc);
  if (plots && !has_matplotlib)
    return "python3 has no matplotlib: install python3-matplotlib (scripts/setup.sh); report.html was written without "
           "figures";
  return "";
}

std::string command_line(const ReproduceOptions& o) {
  std::string s = "edrnr reproduce";
  if (o.quick) s += " --quick";
  if (o.data_opt->count()) s += " --data " + o.data;
  if (o.models_opt->count()) s += " --models " + o.models;
  s += " --chip " + o.chip;
  if (o.views_opt->count()) s += " --views " + o.views;
  if (o.downscale != 1) s += fmt::format(" --downscale {}", o.downscale);
  return s + " --out " + o.out;
}

void run_reproduce(const ReproduceOptions& o) {
  if (o.figures != "auto" && o.figures != "required" && o.figures != "none")
    fail("--figures '{}': expected auto, required or none", o.figures);
  if (o.downscale < 1) fail("--downscale {}: must be a positive whole number", o.downscale);
  if (o.quick_size < 8) fail("--quick-size {}: must be at least 8", o.quick_size);
  if (o.quick && (o.data_opt->count() || o.models_opt->count()))
    fail("--data and --models do not apply to --quick, which renders procedural scenes");
  const int jobs = o.jobs_opt->count() ? o.jobs : std::max(1, int(std::thread::hardware_concurrency()));
  if (jobs < 1) fail("--jobs {}: must be at least 1", jobs);
  const fs::path out = o.out;
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) fail("--out '{}': cannot create the folder: {}", o.out, ec.message());

  const fs::path preset = find_chip_preset_file(o.chip);
  sim::SimConfig cfg;
  try {
    cfg = sim::load_sim_config(preset, preset_dirs("dram"));
    sim::validate(cfg);
  } catch (const std::exception& e) {
    fail("--chip '{}': cannot use the preset '{}': {}", o.chip, preset.string(), e.what());
  }

  std::vector<sim::ReproScene> scenes;
  sim::ReportSettings settings;
  settings.quick = o.quick;
  settings.chip_preset = preset.string();
  settings.clock_MHz = cfg.clock_MHz;
  settings.command_line = command_line(o);
  if (o.quick) {
    const std::vector<int> views = o.views_opt->count() ? parse_views(o.views) : std::vector<int>{0, 1};
    for (const char* name : kQuickScenes) scenes.push_back(quick_scene(name, views, o.quick_size));
  } else {
    const std::vector<int> views = parse_views(o.views);
    const fs::path data = resolve_dir(o.data_opt, o.data, "../shared/data/nerf_synthetic",
                                      "../shared/data/nerf_synthetic", "Synthetic-NeRF data");
    const fs::path models = resolve_dir(o.models_opt, o.models, "assets", "assets", "model");
    for (const char* name : kPaperScenes) {
      const fs::path model = models / (std::string(name) + ".edrnr"), scene_data = data / name;
      std::string why;
      if (!fs::is_regular_file(model, ec))
        why = fmt::format("no model ({} does not exist)", model.string());
      else if (!fs::is_directory(scene_data, ec))
        why = fmt::format("no data ({} does not exist)", scene_data.string());
      if (!why.empty()) {
        fmt::print("reproduce: skipping {}: {}\n", name, why);
        settings.skipped.push_back({name, why});
        continue;
      }
      scenes.push_back(dataset_scene(name, model, scene_data, views, o, cfg, preset));
    }
    if (scenes.empty())
      fail("nothing to reproduce: none of chair, lego, mic, hotdog has both a model in '{}' and data in '{}'",
           models.string(), data.string());
  }

  const std::vector<sim::RunSpec> plan = sim::plan_runs(scenes, cfg);
  std::string names;
  for (const sim::ReproScene& s : scenes) names += (names.empty() ? "" : ", ") + s.name;
  fmt::print("reproduce: {} ({} view{} each, {}x{}), {} runs, {} on {} thread{}\n", names, scenes[0].views.size(),
             scenes[0].views.size() == 1 ? "" : "s", scenes[0].views[0].camera.width, scenes[0].views[0].camera.height,
             plan.size(), preset.filename().string(), jobs, jobs == 1 ? "" : "s");
  std::fflush(stdout);

  sim::ExecuteOptions exec;
  exec.jobs = jobs;
  const bool terminal = !o.quiet && isatty(STDERR_FILENO);
  if (terminal)
    exec.progress = [](const sim::RunProgress& p) {
      const double eta = p.done ? p.elapsed_s * double(p.to_run - p.done) / double(p.done) : 0.0;
      std::fprintf(stderr, "\r  simulating: %zu/%zu (%.0f %%), %.0f s, ETA %.0f s   ", p.done, p.to_run,
                   100.0 * double(p.done) / double(std::max<size_t>(p.to_run, 1)), p.elapsed_s, eta);
      if (p.done == p.to_run) std::fprintf(stderr, "\n");
      std::fflush(stderr);
    };
  const fs::path runs_dir = out / "runs";
  const sim::ExecuteSummary summary = sim::execute_runs(scenes, plan, runs_dir, exec);
  fmt::print("simulations: {} distinct, {} cached, {} run in {:.1f} s\n", summary.distinct, summary.cached, summary.ran,
             summary.seconds);

  for (const sim::ReproScene& s : scenes)
    for (const sim::ReproView& v : s.views)
      if (!v.ground_truth.data.empty()) {
        fs::create_directories(out / "ground_truth", ec);
        if (ec) fail("--out '{}': cannot create ground_truth/: {}", o.out, ec.message());
        write_png(out / "ground_truth" / fmt::format("{}_view{}.png", s.name, v.index), v.ground_truth);
      }

  const sim::RunTable table(scenes, plan, runs_dir);
  sim::FigureContext ctx;
  ctx.preset_clock_MHz = cfg.clock_MHz;
  ctx.quick = o.quick;
  const nlohmann::json results = sim::build_results(settings, scenes, table, summary, sim::compute_figures(table, ctx));
  sim::write_results(out, results);

  // Figures and report.html: scripts/report_figures.py (python3, matplotlib).
  const std::string figures_problem = make_figures(out / "results.json", o.figures != "none");
  write_file_atomic(out / "report.md", sim::markdown_report(results, out));
  fmt::print("wrote {0}/report.md, {0}/results.json, {0}/comparisons.csv and the other CSV files{1}\n", out.string(),
             !figures_problem.empty() ? ""
             : o.figures == "none"    ? fmt::format(", {}/report.html (no figures)", out.string())
                                      : fmt::format(", {0}/report.html, {0}/figures/", out.string()));
  std::fflush(stdout);
  if (!figures_problem.empty()) {
    if (o.figures == "required") fail("--figures required: {}", figures_problem);
    std::fprintf(stderr, "edrnr: warning: no figures: %s\n", figures_problem.c_str());
  }
}

void register_reproduce_cmd(CLI::App& app) {
  auto o = std::make_shared<ReproduceOptions>();
  o->views = "0,8,16";
  CLI::App* cmd = app.add_subcommand(
      "reproduce", "Run the paper's evaluation (Tables I-II, Figs. 3-17) on the simulator and write a report");
  o->data_opt = cmd->add_option("--data", o->data,
                                "Synthetic-NeRF folder with <scene>/transforms_test.json (default: "
                                "../shared/data/nerf_synthetic, here or beside the source tree)");
  o->models_opt = cmd->add_option("--models", o->models,
                                  "folder with <scene>.edrnr for chair, lego, mic, hotdog (default: assets/)");
  cmd->add_option("--chip", o->chip, "chip preset: a name in configs/chip/ or a YAML file")->capture_default_str();
  o->views_opt = cmd->add_option("--views", o->views, "test views, comma-separated (--quick: orbit positions, 0,1)")
                     ->capture_default_str();
  o->jobs_opt = cmd->add_option("--jobs", o->jobs, "simulations in parallel (default: the hardware's threads)");
  cmd->add_option("--downscale", o->downscale, "simulate the views at 1/N of their size (default 1: 800x800)")
      ->capture_default_str();
  cmd->add_flag("--quick", o->quick,
                "procedural scenes (several, torus) at a low resolution, orbit cameras, no ground truth: a check "
                "that takes a minute or two");
  cmd->add_option("--quick-size", o->quick_size, "--quick: image width and height")->capture_default_str();
  cmd->add_option("--out", o->out, "report folder (runs/ inside it caches every simulation)")->required();
  cmd->add_option("--figures", o->figures,
                  "auto: draw figures if python3-matplotlib is there, else warn; required: fail without them; none: "
                  "report.html without figures")
      ->capture_default_str();
  cmd->add_flag("--allow-over-budget", o->allow_over_budget,
                "simulate a preset whose buffers exceed Table I's SRAM classes");
  cmd->add_flag("-q,--quiet", o->quiet, "no progress line");
  cmd->callback([o] { run_reproduce(*o); });
}

Registrar reg{57, register_reproduce_cmd};

}  // namespace
}  // namespace edrnr::cli
