// Throughput of the reference renderer on the procedural "several" scene at
// micro resolution 256: a 200x200 view from an orbit camera. Arguments: model
// form (0 float, 1 quantized), tier skipping (1 on, 0 off) and threads (0: all
// cores).
#include <benchmark/benchmark.h>

#include "model/procedural.h"
#include "render/cameras.h"
#include "render/reference.h"

namespace {

const edrnr::SceneModel& several_256() {
  static const edrnr::SceneModel model = [] {
    edrnr::ProceduralOptions o;
    o.micro_res = 256;
    return edrnr::make_procedural_model("several", edrnr::procedural_shapes("several"), o);
  }();
  return model;
}

void BM_RenderReference(benchmark::State& state) {
  const edrnr::SceneModel& model = several_256();
  const edrnr::Camera camera = edrnr::orbit_camera(200, 200, 30, 30, 4, 40);
  edrnr::RenderSettings settings;
  settings.form = state.range(0) ? edrnr::ModelForm::Quantized : edrnr::ModelForm::Float;
  settings.use_occupancy_tiers = state.range(1) != 0;
  settings.threads = int(state.range(2));
  edrnr::RenderStats stats;
  uint64_t rays = 0, samples = 0, checks = 0;
  for (auto _ : state) {
    edrnr::Image img = edrnr::render_reference(model, camera, settings, &stats);
    benchmark::DoNotOptimize(img.data.data());
    rays += stats.rays;
    samples += stats.samples;
    checks += stats.occupancy_checks;
  }
  state.counters["rays/s"] = benchmark::Counter(double(rays), benchmark::Counter::kIsRate);
  state.counters["samples/s"] = benchmark::Counter(double(samples), benchmark::Counter::kIsRate);
  state.counters["samples/ray"] = double(samples) / double(rays);
  state.counters["checks/ray"] = double(checks) / double(rays);
}
BENCHMARK(BM_RenderReference)
    ->ArgNames({"quantized", "tiers", "threads"})
    ->Args({0, 1, 0})
    ->Args({1, 1, 0})
    ->Args({1, 0, 0})
    ->Args({1, 1, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
