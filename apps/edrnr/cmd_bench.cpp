// edrnr bench render: frames per second of a render engine on dataset views
// (or orbit views), the share of time per phase of the fast renderer, and
// the speed-up over the reference renderer measured in the same process.
#include <fmt/format.h>
#include <omp.h>
#include <sys/resource.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <functional>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "commands.h"
#include "core/error.h"
#include "core/limits.h"
#include "core/stats.h"
#include "data/dataset.h"
#include "engines.h"
#include "model/model_io.h"
#include "render/cameras.h"
#include "render/fast.h"
#include "render/fast_kernels.h"
#include "render/options.h"
#include "render/reference.h"

namespace edrnr::cli {
namespace {

struct BenchOptions {
  std::string model, dataset, split = "test", views = "0,8,16", engine = "fast", vs;
  int frames = 5, warmup = 1, width = 800, threads = 0;
  float step = kDefaultStepMicro;
  float fast_transmittance = -1.f;  // not given: each path's default
  std::string form = "auto";
  CLI::Option* dataset_opt = nullptr;
  CLI::Option* views_opt = nullptr;
};

// "0,8,16" or "0-3,9": non-negative integers below `count`.
std::vector<int> parse_index_list(const std::string& text, int count, const char* flag) {
  std::vector<int> out;
  size_t start = 0;
  for (;;) {
    const size_t comma = text.find(',', start);
    const std::string part = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    auto number = [&](const std::string& s) {
      char* end = nullptr;
      const long v = std::strtol(s.c_str(), &end, 10);
      if (s.empty() || end != s.c_str() + s.size() || v < 0)
        fail("{} '{}': '{}' is not an index or a range A-B", flag, text, part);
      if (v >= count) fail("{} '{}': {} is out of range (0..{})", flag, text, v, count - 1);
      return int(v);
    };
    const size_t dash = part.find('-', 1);
    if (dash == std::string::npos) {
      out.push_back(number(part));
    } else {
      const int a = number(part.substr(0, dash)), b = number(part.substr(dash + 1));
      if (b < a) fail("{} '{}': range {} is backwards", flag, text, part);
      for (int v = a; v <= b; ++v) out.push_back(v);
    }
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

struct Timed {
  double seconds = 0;      // median wall time per frame
  double cpu_seconds = 0;  // median CPU time per frame, all threads
  RenderStats stats;
};

double process_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

using RenderFn = std::function<Image(const Camera&, RenderStats*)>;

Timed time_frames(const RenderFn& render, const Camera& cam, int warmup, int frames) {
  Timed t;
  for (int i = 0; i < warmup; ++i) render(cam, &t.stats);
  std::vector<double> s, cpu;
  for (int i = 0; i < frames; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    const double c0 = process_cpu_seconds();
    render(cam, &t.stats);
    cpu.push_back(process_cpu_seconds() - c0);
    s.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  t.seconds = median(s);
  t.cpu_seconds = median(cpu);
  return t;
}

void run_bench_render(const BenchOptions& o) {
  if (o.frames < 1 || o.frames > 1000) fail("--frames {} is outside 1..1000", o.frames);
  if (o.warmup < 0 || o.warmup > 100) fail("--warmup {} is outside 0..100", o.warmup);
  limits::check_threads(o.threads);
  if (!o.vs.empty() && o.vs != "reference") fail("--vs '{}': only 'reference' is supported", o.vs);
  const Engine& engine = find_engine(o.engine);
  RenderSettings s;
  s.step_micro = o.step;
  apply_fast_transmittance(o.fast_transmittance, s);
  s.form = parse_model_form(o.form, "--form");
  s.threads = o.threads;
  check_step_micro(o.step, 0, "--step");

  // Cameras: dataset views, or orbit views at 800x800 (--views are then azimuths in steps of 15 degrees).
  std::vector<std::pair<std::string, Camera>> cams;
  if (o.dataset_opt->count()) {
    DatasetOptions d;
    d.split = o.split;
    d.load_images = false;
    const Dataset ds = load_dataset(o.dataset, d);
    for (int v : parse_index_list(o.views, int(ds.frames.size()), "--views"))
      cams.push_back({fmt::format("{} view {}", o.split, v), ds.frames[size_t(v)].camera});
  } else {
    limits::check_image_size(o.width, o.width, "--width");
    for (int v : parse_index_list(o.views, 24, "--views"))
      cams.push_back({fmt::format("orbit {} deg", 15 * v), orbit_camera(o.width, o.width, 15.0 * v, 30, 4, 40)});
  }
  const SceneModel model = load_model(o.model);
  check_step_micro(o.step, model, "--step");

  // The fast engines keep their packed model across frames; the others go through the engine table.
  std::unique_ptr<FastRenderer> fast;
  if (o.engine == "fast" || o.engine == "fast-float")
    fast = std::make_unique<FastRenderer>(model, s.form, o.engine == "fast" ? FastPath::Auto : FastPath::Float);
  const RenderFn render = [&](const Camera& cam, RenderStats* st) {
    return fast ? fast->render(cam, s, st) : engine.render(model, cam, s, st);
  };
  const RenderFn reference = [&](const Camera& cam, RenderStats* st) { return render_reference(model, cam, s, st); };

  const ResolvedForm form = resolve_model_form(model, s.form);
  fmt::print("model {}  engine {}{}  threads {}  SIMD {}\n", o.model, engine.name,
             fast ? (fast->arithmetic() == FastArithmetic::Int8 ? " (INT8 path)" : " (float path)") : "",
             o.threads > 0 ? o.threads : omp_get_max_threads(), fast_simd_target());
  fmt::print("form: {} features, {} MLPs; {} warm-up + {} timed frames per view, median\n",
             form.quantized_features ? "INT4" : "float", form.quantized_mlps ? "INT8" : "float", o.warmup, o.frames);
  double sum_fps = 0, sum_ref_fps = 0, sum_cpu = 0, sum_ref_cpu = 0;
  FastProfile total_profile;
  RenderStats profiled_stats;
  for (const auto& [name, cam] : cams) {
    const Timed t = time_frames(render, cam, o.warmup, o.frames);
    const double fps = 1.0 / t.seconds;
    sum_fps += fps;
    fmt::print("{:<16} {}x{}  {:8.2f} FPS  {:7.1f} ms  {:6.1f} M samples/s  ({} samples; CPU {:.1f} ms/frame)\n", name,
               cam.width, cam.height, fps, 1e3 * t.seconds, 1e-6 * double(t.stats.samples) / t.seconds, t.stats.samples,
               1e3 * t.cpu_seconds);
    sum_cpu += t.cpu_seconds;
    if (fast) {
      FastProfile p;
      RenderStats ps;
      fast->render(cam, s, &ps, &p);
      profiled_stats.rays += ps.rays;
      profiled_stats.rays_hit_aabb += ps.rays_hit_aabb;
      profiled_stats.samples += ps.samples;
      profiled_stats.occupancy_checks += ps.occupancy_checks;
      total_profile.traversal_s += p.traversal_s;
      total_profile.interpolation_s += p.interpolation_s;
      total_profile.mlp_s += p.mlp_s;
      total_profile.compositing_s += p.compositing_s;
      total_profile.mlp_samples += p.mlp_samples;
    }
    if (!o.vs.empty()) {
      const Timed r = time_frames(reference, cam, 0, 1);
      sum_ref_fps += 1.0 / r.seconds;
      sum_ref_cpu += r.cpu_seconds;
      fmt::print("{:<16} reference {:8.3f} FPS  {:7.1f} ms  -> {:.1f}x  (CPU {:.1f} ms/frame -> {:.1f}x)\n", "",
                 1.0 / r.seconds, 1e3 * r.seconds, r.seconds / t.seconds, 1e3 * r.cpu_seconds,
                 r.cpu_seconds / t.cpu_seconds);
    }
  }
  const double n = double(cams.size());
  const int threads = o.threads > 0 ? o.threads : omp_get_max_threads();
  fmt::print("mean {:.2f} FPS over {} views", sum_fps / n, cams.size());
  if (!o.vs.empty()) fmt::print("; reference {:.3f} FPS; ratio {:.1f}x", sum_ref_fps / n, sum_fps / sum_ref_fps);
  fmt::print("\n");
  // On a loaded machine the wall clock counts other processes' time too; the
  // CPU time per frame gives the rate the threads would reach on idle cores.
  fmt::print("CPU time {:.1f} ms/frame: {:.2f} FPS on {} idle cores at perfect scaling", 1e3 * sum_cpu / n,
             threads * n / sum_cpu, threads);
  if (!o.vs.empty()) fmt::print("; CPU-time ratio to the reference {:.1f}x", sum_ref_cpu / sum_cpu);
  fmt::print("\n");
  if (fast) {
    const double T = total_profile.total_s();
    if (T > 0)
      fmt::print(
          "time shares (profiled frames, thread-seconds): traversal {:.1f}%  interpolation {:.1f}%  MLP {:.1f}%  "
          "compositing {:.1f}%\n",
          100 * total_profile.traversal_s / T, 100 * total_profile.interpolation_s / T, 100 * total_profile.mlp_s / T,
          100 * total_profile.compositing_s / T);
    StatsRegistry registry;
    export_fast_stats(profiled_stats, total_profile, registry);
    std::ostringstream table;
    registry.print_table(table);
    fmt::print("profiled frames, all views:\n{}", table.str());
  } else {
    fmt::print("time shares: measured for the fast engines only\n");
  }
  struct rusage ru {};
  getrusage(RUSAGE_SELF, &ru);
  fmt::print("peak memory (max RSS) {:.1f} MiB\n", double(ru.ru_maxrss) / 1024.0);
}

void register_bench_cmd(CLI::App& app) {
  CLI::App* bench = app.add_subcommand("bench", "Benchmarks: frames per second of the render engines");
  bench->require_subcommand(1);
  auto o = std::make_shared<BenchOptions>();
  CLI::App* cmd = bench->add_subcommand("render", "Frames per second of a render engine, phase shares, ratio");
  cmd->add_option("model", o->model, "the .edrnr model")->required();
  o->dataset_opt = cmd->add_option("--dataset", o->dataset, "cameras from a NeRF dataset folder");
  cmd->add_option("--split", o->split, "dataset split")->capture_default_str();
  o->views_opt = cmd->add_option("--views", o->views,
                                 "dataset views, e.g. 0,8,16 or 0-3 (without --dataset: orbit "
                                 "azimuths in 15-degree steps)")
                     ->capture_default_str();
  cmd->add_option("--engine", o->engine, "fast, fast-float, reference or chip")->capture_default_str();
  cmd->add_option("--frames", o->frames, "timed frames per view (median)")->capture_default_str();
  cmd->add_option("--warmup", o->warmup, "untimed frames per view first")->capture_default_str();
  cmd->add_option("--vs", o->vs, "also time this engine once per view and print the ratio (reference)");
  cmd->add_option("--width", o->width, "orbit image size (without --dataset)")->capture_default_str();
  cmd->add_option("--step", o->step, "sample spacing in micro voxels")->capture_default_str();
  add_fast_transmittance_option(cmd, &o->fast_transmittance);
  cmd->add_option("--form", o->form, "auto, float or quantized")->capture_default_str();
  cmd->add_option("--threads", o->threads, "threads (0: all cores)")->capture_default_str();
  cmd->callback([o] { run_bench_render(*o); });
}

Registrar reg{85, register_bench_cmd};

}  // namespace
}  // namespace edrnr::cli
