// edrnr render: renders one image of a model from a dataset view, a camera
// JSON file or an orbit around the origin.
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <system_error>

#include "commands.h"
#include "core/error.h"
#include "core/file_io.h"
#include "core/image.h"
#include "core/limits.h"
#include "data/dataset.h"
#include "engines.h"
#include "model/model_io.h"
#include "render/cameras.h"
#include "render/options.h"
#include "render/reference.h"

namespace edrnr::cli {
namespace {

struct RenderOptions {
  std::string model, output;
  std::string dataset, split = "test", camera_file;
  int view = 0;
  double orbit = 0, elevation = 30, radius = 4, fov = 40;
  int width = 0, height = 0;
  float step = kDefaultStepMicro;
  float fast_transmittance = -1.f;  // not given: each path's default
  std::string form = "auto", background = "white", engine = "reference";
  int threads = 0;
  int turntable = 0;
  CLI::Option *turntable_opt = nullptr, *dataset_opt, *camera_opt, *orbit_opt, *split_opt, *view_opt, *elev_opt,
              *radius_opt, *fov_opt, *width_opt, *height_opt;
};

// The image size: the flags if given (one alone keeps the aspect ratio), else
// the camera's own.
void pick_size(const RenderOptions& o, int w0, int h0, int& w, int& h) {
  w = w0;
  h = h0;
  if (o.width_opt->count() && o.height_opt->count()) {
    w = o.width;
    h = o.height;
  } else if (o.width_opt->count()) {
    w = o.width;
    h = int(std::clamp<double>(std::round(double(o.width) * h0 / w0), 1, 1e9));
  } else if (o.height_opt->count()) {
    h = o.height;
    w = int(std::clamp<double>(std::round(double(o.height) * w0 / h0), 1, 1e9));
  }
  limits::check_image_size(w, h, "--width/--height");
}

Camera pick_camera(const RenderOptions& o) {
  const int sources = int(o.dataset_opt->count() > 0) + int(o.camera_opt->count() > 0) + int(o.orbit_opt->count() > 0);
  if (sources != 1) fail("give exactly one of --dataset, --camera and --orbit");
  if (!o.dataset_opt->count() && (o.split_opt->count() || o.view_opt->count()))
    fail("--split and --view need --dataset");
  if (!o.orbit_opt->count() && (o.elev_opt->count() || o.radius_opt->count() || o.fov_opt->count()))
    fail("--elevation, --radius and --fov need --orbit");
  int w, h;
  if (o.orbit_opt->count()) {
    pick_size(o, 800, 800, w, h);
    return orbit_camera(w, h, o.orbit, o.elevation, o.radius, o.fov);
  }
  Camera cam;
  if (o.camera_opt->count()) {
    cam = load_camera_json(o.camera_file);
  } else {
    DatasetOptions d;
    d.split = o.split;
    d.load_images = false;
    const Dataset ds = load_dataset(o.dataset, d);
    if (o.view < 0 || size_t(o.view) >= ds.frames.size())
      fail("--view {}: the {} split of '{}' has views 0..{}", o.view, o.split, o.dataset, ds.frames.size() - 1);
    cam = ds.frames[size_t(o.view)].camera;
  }
  pick_size(o, cam.width, cam.height, w, h);
  return (w == cam.width && h == cam.height) ? cam : resize_camera(cam, w, h);
}

// The path of the first executable called `name` in a PATH folder, or "" if none.
std::string find_on_path(const std::string& name) {
  const char* path = std::getenv("PATH");
  if (!path) return "";
  std::string dirs = path;
  size_t start = 0;
  for (;;) {
    const size_t colon = dirs.find(':', start);
    const std::string dir = dirs.substr(start, colon == std::string::npos ? std::string::npos : colon - start);
    std::error_code ec;
    const std::filesystem::path exe = std::filesystem::path(dir.empty() ? "." : dir) / name;
    if (std::filesystem::is_regular_file(exe, ec) &&
        (std::filesystem::status(exe, ec).permissions() & std::filesystem::perms::owner_exec) !=
            std::filesystem::perms::none)
      return exe.string();
    if (colon == std::string::npos) return "";
    start = colon + 1;
  }
}

// --turntable N: N orbit frames around the object (azimuth 360 i / N, the
// orbit flags for elevation, radius, field of view and size) written to the
// folder -o as frame_0000.png, ...; then an MP4 with ffmpeg when it is on PATH.
void run_turntable(const RenderOptions& o, const Engine& engine, const RenderSettings& s) {
  if (o.turntable < 1 || o.turntable > 3600) fail("--turntable {} is outside 1..3600 frames", o.turntable);
  if (o.dataset_opt->count() || o.camera_opt->count() || o.orbit_opt->count())
    fail("--turntable makes its own orbit cameras: give no --dataset, --camera or --orbit");
  const std::filesystem::path dir = o.output;
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (!std::filesystem::is_directory(dir, ec))
    fail("-o '{}': cannot create this folder for the turntable frames", o.output);
  int w, h;
  pick_size(o, 800, 800, w, h);
  const SceneModel model = load_model(o.model);
  check_step_micro(o.step, model, "--step");
  const auto t0 = std::chrono::steady_clock::now();
  uint64_t samples = 0;
  for (int i = 0; i < o.turntable; ++i) {
    const Camera cam = orbit_camera(w, h, 360.0 * i / o.turntable, o.elevation, o.radius, o.fov);
    RenderStats stats;
    const Image img = engine.render(model, cam, s, &stats);
    samples += stats.samples;
    write_png(dir / fmt::format("frame_{:04d}.png", i), img);
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  fmt::print("{}: {} frames {}x{} with the {} engine, {:.2f} s ({:.2f} FPS, {:.0f} samples/s)\n", o.output, o.turntable,
             w, h, engine.name, seconds, o.turntable / seconds, double(samples) / seconds);
  const std::string ffmpeg = find_on_path("ffmpeg");
  if (ffmpeg.empty()) {
    fmt::print("ffmpeg is not installed: no video made; the frames are in {}\n", o.output);
    return;
  }
  const std::filesystem::path video = dir / "turntable.mp4";
  const std::string cmd =
      fmt::format("'{}' -loglevel error -y -framerate 30 -i '{}' -c:v libx264 -pix_fmt yuv420p '{}'", ffmpeg,
                  (dir / "frame_%04d.png").string(), video.string());
  if (o.output.find('\'') != std::string::npos)
    fail("-o '{}': a quote in the folder name cannot be passed to ffmpeg", o.output);
  if (std::system(cmd.c_str()) != 0)
    fail("ffmpeg failed to make {} from the frames (they are kept in {})", video.string(), o.output);
  fmt::print("{}: MP4 made with ffmpeg\n", video.string());
}

void run_render(const RenderOptions& o) {
  const Engine& engine = find_engine(o.engine);
  RenderSettings s;
  s.step_micro = o.step;
  apply_fast_transmittance(o.fast_transmittance, s);
  s.form = parse_model_form(o.form, "--form");
  parse_background(o.background, "--background", s.background);
  limits::check_threads(o.threads);
  s.threads = o.threads;
  check_step_micro(o.step, 0, "--step");
  if (o.turntable_opt->count()) return run_turntable(o, engine, s);
  check_output_path(o.output, "-o");
  const Camera cam = pick_camera(o);
  const SceneModel model = load_model(o.model);
  check_step_micro(o.step, model, "--step");

  RenderStats stats;
  const auto t0 = std::chrono::steady_clock::now();
  const Image img = engine.render(model, cam, s, &stats);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  write_png(o.output, img);

  const ResolvedForm form = resolve_model_form(model, s.form);
  fmt::print("{}: {}x{} with the {} engine ({} features, {} MLPs)\n", o.output, img.width, img.height, engine.name,
             form.quantized_features ? "INT4" : "float", form.quantized_mlps ? "INT8" : "float");
  fmt::print("  rays {}  (hit AABB {})\n", stats.rays, stats.rays_hit_aabb);
  fmt::print("  samples {}  ({:.2f} per ray)\n", stats.samples, stats.rays ? double(stats.samples) / stats.rays : 0.0);
  fmt::print("  occupancy checks {}\n", stats.occupancy_checks);
  fmt::print("  {:.3f} s  {:.0f} rays/s  {:.0f} samples/s\n", seconds, double(stats.rays) / seconds,
             double(stats.samples) / seconds);
}

void register_render_cmd(CLI::App& app) {
  auto o = std::make_shared<RenderOptions>();
  CLI::App* cmd = app.add_subcommand("render", "Render one image of a model");
  cmd->add_option("model", o->model, "the .edrnr model")->required();
  cmd->add_option("-o,--output", o->output, "the PNG to write (with --turntable: the folder for the frames)")
      ->required();
  o->turntable_opt = cmd->add_option("--turntable", o->turntable,
                                     "N frames around the object into the folder -o (orbit flags apply), and an MP4 "
                                     "if ffmpeg is installed");
  o->dataset_opt = cmd->add_option("--dataset", o->dataset, "camera from a NeRF dataset folder (transforms_*.json)");
  o->split_opt = cmd->add_option("--split", o->split, "dataset split")->capture_default_str();
  o->view_opt = cmd->add_option("--view", o->view, "dataset view index")->capture_default_str();
  o->camera_opt = cmd->add_option("--camera", o->camera_file, "camera from a JSON file (docs/rendering.md)");
  o->orbit_opt = cmd->add_option("--orbit", o->orbit, "camera on a circle around the origin, at this azimuth (deg)");
  o->elev_opt = cmd->add_option("--elevation", o->elevation, "orbit elevation (deg)")->capture_default_str();
  o->radius_opt = cmd->add_option("--radius", o->radius, "orbit radius (scene units)")->capture_default_str();
  o->fov_opt = cmd->add_option("--fov", o->fov, "orbit horizontal field of view (deg)")->capture_default_str();
  o->width_opt = cmd->add_option("--width", o->width, "image width (default 800, or the camera's)");
  o->height_opt = cmd->add_option("--height", o->height, "image height (default: keeps the aspect ratio)");
  cmd->add_option("--step", o->step, "sample spacing in micro voxels")->capture_default_str();
  add_fast_transmittance_option(cmd, &o->fast_transmittance);
  cmd->add_option("--form", o->form, "auto, float or quantized")->capture_default_str();
  cmd->add_option("--background", o->background, "white, black or R,G,B")->capture_default_str();
  cmd->add_option("--threads", o->threads, "threads (0: all cores)")->capture_default_str();
  cmd->add_option(
         "--engine", o->engine,
         "renderer: reference (float golden), fast (fast CPU renderer, INT8 path on quantized models), fast-float or "
         "chip (bit-accurate chip model)")
      ->capture_default_str();
  cmd->callback([o] { run_render(*o); });
}

Registrar reg{30, register_render_cmd};

}  // namespace
}  // namespace edrnr::cli
