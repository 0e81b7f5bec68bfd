// edrnr eval: renders dataset views with a render engine (the reference
// renderer, or the bit-accurate chip model) and compares them with the
// ground-truth images (PSNR, SSIM). With the chip engine it also reports each
// view's PSNR against the reference renderer's image of the same model.
#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "commands.h"
#include "core/error.h"
#include "core/file_io.h"
#include "core/image.h"
#include "core/limits.h"
#include "core/metrics.h"
#include "data/dataset.h"
#include "engines.h"
#include "model/model_io.h"
#include "render/options.h"
#include "render/reference.h"

namespace edrnr::cli {
namespace {

struct EvalOptions {
  std::string model, dataset, split = "test";
  std::string views, json_path, save_dir;
  int limit = 0, downscale = 1;
  float step = kDefaultStepMicro;
  float fast_transmittance = -1.f;  // not given: each path's default
  std::string form = "auto", background = "white", engine = "reference";
  int threads = 0;
  CLI::Option *views_opt, *limit_opt;
};

constexpr int kSsimWindowPixels = 11;  // core/metrics.cpp

// "0,3,5-7" -> 0 3 5 6 7, each below `count`.
std::vector<int> parse_views(const std::string& text, size_t count) {
  std::vector<int> out;
  size_t start = 0;
  while (start <= text.size()) {
    const size_t comma = text.find(',', start);
    const std::string part = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    const size_t dash = part.find('-', 1);
    auto number = [&](const std::string& s) {
      char* end = nullptr;
      const long v = std::strtol(s.c_str(), &end, 10);
      if (s.empty() || end != s.c_str() + s.size() || v < 0)
        fail("--views '{}': '{}' is not a view index or range A-B", text, part);
      if (size_t(v) >= count) fail("--views '{}': view {} is out of range (the split has {} views)", text, v, count);
      return int(v);
    };
    if (dash == std::string::npos) {
      out.push_back(number(part));
    } else {
      const int a = number(part.substr(0, dash)), b = number(part.substr(dash + 1));
      if (b < a) fail("--views '{}': range {} is backwards", text, part);
      for (int v = a; v <= b; ++v) out.push_back(v);
    }
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

// The ground-truth image of a frame as load_dataset would give it.
Image load_ground_truth(const Frame& f, int downscale_factor, const float background[3]) {
  return downscale(composite_rgba(read_frame_rgba(f, downscale_factor), background), downscale_factor);
}

void run_eval(const EvalOptions& o) {
  if (o.views_opt->count() && o.limit_opt->count()) fail("give --views or --limit, not both");
  if (o.limit_opt->count() && o.limit < 1) fail("--limit {}: must be at least 1", o.limit);
  if (o.downscale < 1) fail("--downscale {}: must be a positive integer", o.downscale);
  limits::check_threads(o.threads);
  const Engine& engine = find_engine(o.engine);
  const bool vs_reference = std::string(engine.name) != "reference";
  RenderSettings s;
  s.step_micro = o.step;
  apply_fast_transmittance(o.fast_transmittance, s);
  s.form = parse_model_form(o.form, "--form");
  parse_background(o.background, "--background", s.background);
  s.threads = o.threads;
  check_step_micro(o.step, 0, "--step");
  if (!o.json_path.empty()) check_output_path(o.json_path, "--json");
  if (!o.save_dir.empty() && std::filesystem::exists(o.save_dir) && !std::filesystem::is_directory(o.save_dir))
    fail("--save-dir '{}': not a folder", o.save_dir);

  DatasetOptions d;
  d.split = o.split;
  d.downscale = o.downscale;
  d.load_images = false;
  const Dataset ds = load_dataset(o.dataset, d);
  std::vector<int> views;
  if (o.views_opt->count()) {
    views = parse_views(o.views, ds.frames.size());
  } else {
    const size_t n = o.limit_opt->count() ? std::min(ds.frames.size(), size_t(o.limit)) : ds.frames.size();
    for (size_t i = 0; i < n; ++i) views.push_back(int(i));
  }
  // SSIM compares 11x11 windows: smaller views are refused before any rendering.
  const Camera& first = ds.frames[0].camera;
  if (first.width < kSsimWindowPixels || first.height < kSsimWindowPixels)
    fail("{}: the {} views are {}x{} pixels{}; SSIM needs at least {}x{}", o.dataset, o.split, first.width,
         first.height, o.downscale > 1 ? fmt::format(" after --downscale {}", o.downscale) : "", kSsimWindowPixels,
         kSsimWindowPixels);
  const SceneModel model = load_model(o.model);
  check_step_micro(o.step, model, "--step");
  if (!o.save_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(o.save_dir, ec);
    if (ec) fail("--save-dir '{}': cannot create the folder: {}", o.save_dir, ec.message());
  }

  nlohmann::ordered_json per_view = nlohmann::ordered_json::array();
  double psnr_sum = 0, ssim_sum = 0, seconds_sum = 0, vs_ref_sum = 0;
  fmt::print("{:>6} {:>9} {:>8} {:>9} {:>12}{}  {}\n", "view", "PSNR dB", "SSIM", "seconds", "samples/ray",
             vs_reference ? "  vs ref dB" : "", "image");
  for (int v : views) {
    const Frame& f = ds.frames[size_t(v)];
    const Image truth = load_ground_truth(f, o.downscale, s.background);
    RenderStats stats;
    const auto t0 = std::chrono::steady_clock::now();
    const Image img = engine.render(model, f.camera, s, &stats);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double p = psnr(img, truth), q = ssim(img, truth);
    psnr_sum += p;
    ssim_sum += q;
    seconds_sum += seconds;
    double vs_ref = 0;
    if (vs_reference) {
      vs_ref = psnr(img, render_reference(model, f.camera, s));
      vs_ref_sum += vs_ref;
    }
    const double spr = stats.rays ? double(stats.samples) / double(stats.rays) : 0.0;
    fmt::print("{:>6} {:>9.3f} {:>8.4f} {:>9.2f} {:>12.2f}{}  {}\n", v, p, q, seconds, spr,
               vs_reference ? fmt::format(" {:>10.3f}", vs_ref) : "", f.image_path.filename().string());
    std::fflush(stdout);
    if (!o.save_dir.empty())
      write_png(std::filesystem::path(o.save_dir) / fmt::format("{}_{:03d}.png", o.split, v), img);
    per_view.push_back({{"view", v},
                        {"image", f.image_path.string()},
                        {"psnr_db", p},
                        {"ssim", q},
                        {"seconds", seconds},
                        {"rays", stats.rays},
                        {"samples", stats.samples}});
    if (vs_reference) per_view.back()["psnr_vs_reference_db"] = vs_ref;
  }
  const double n = double(views.size());
  fmt::print("{:>6} {:>9.3f} {:>8.4f} {:>9.2f}{}\n", "mean", psnr_sum / n, ssim_sum / n, seconds_sum / n,
             vs_reference ? fmt::format(" {:>12} {:>10.3f}", "", vs_ref_sum / n) : "");
  if (!o.json_path.empty()) {
    nlohmann::ordered_json j;
    j["model"] = o.model;
    j["dataset"] = o.dataset;
    j["split"] = o.split;
    j["downscale"] = o.downscale;
    j["step_micro"] = o.step;
    j["fast_transmittance_min"] = s.fast_transmittance_min;
    j["fast_int8_transmittance_min"] = s.fast_int8_transmittance_min;
    j["form"] = o.form;
    j["engine"] = engine.name;
    j["background"] = {s.background[0], s.background[1], s.background[2]};
    j["views"] = per_view;
    j["mean_psnr_db"] = psnr_sum / n;
    j["mean_ssim"] = ssim_sum / n;
    if (vs_reference) j["mean_psnr_vs_reference_db"] = vs_ref_sum / n;
    write_file_atomic(o.json_path, j.dump(2) + "\n");
  }
}

void register_eval_cmd(CLI::App& app) {
  auto o = std::make_shared<EvalOptions>();
  CLI::App* cmd = app.add_subcommand("eval", "Render dataset views and report PSNR and SSIM against the images");
  cmd->add_option("model", o->model, "the .edrnr model")->required();
  cmd->add_option("dataset", o->dataset, "NeRF dataset folder (transforms_<split>.json)")->required();
  cmd->add_option("--split", o->split, "dataset split")->capture_default_str();
  o->views_opt = cmd->add_option("--views", o->views, "views to render, e.g. 0,3,5-7 (default: all)");
  o->limit_opt = cmd->add_option("--limit", o->limit, "render only the first N views");
  cmd->add_option("--downscale", o->downscale, "integer image downscale factor")->capture_default_str();
  cmd->add_option("--json", o->json_path, "write the results as JSON to this file");
  cmd->add_option("--save-dir", o->save_dir, "write each rendered view as <split>_<view>.png here");
  cmd->add_option("--step", o->step, "sample spacing in micro voxels")->capture_default_str();
  add_fast_transmittance_option(cmd, &o->fast_transmittance);
  cmd->add_option("--form", o->form, "auto, float or quantized")->capture_default_str();
  cmd->add_option("--background", o->background, "white, black or R,G,B (also composites the images)")
      ->capture_default_str();
  cmd->add_option("--threads", o->threads, "threads (0: all cores)")->capture_default_str();
  cmd->add_option("--engine", o->engine,
                  "renderer: reference (float golden) or chip (bit-accurate chip model; also reports PSNR "
                  "against the reference renderer)")
      ->capture_default_str();
  cmd->callback([o] { run_eval(*o); });
}

Registrar reg{40, register_eval_cmd};

}  // namespace
}  // namespace edrnr::cli
