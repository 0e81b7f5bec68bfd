// Frames per second of the fast CPU renderer against the reference renderer,
// in one process: an 800x800 orbit view of the procedural "several" scene at
// micro resolution 256 (quantized form, as the bundled models), and of the
// bundled lego model when assets/lego.edrnr is found from the working
// folder. Argument: path (0 fast INT8, 1 fast float, 2 reference).
#include <benchmark/benchmark.h>

#include <filesystem>
#include <memory>

#include "model/model_io.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "render/fast.h"
#include "render/reference.h"

namespace {

const edrnr::SceneModel& several_256() {
  static const edrnr::SceneModel model = [] {
    edrnr::ProceduralOptions o;
    o.micro_res = 256;
    o.store_float = false;
    return edrnr::make_procedural_model("several", edrnr::procedural_shapes("several"), o);
  }();
  return model;
}

const edrnr::SceneModel* lego() {
  static const std::unique_ptr<edrnr::SceneModel> model = []() -> std::unique_ptr<edrnr::SceneModel> {
    for (const char* p : {"assets/lego.edrnr", "../assets/lego.edrnr", "../../assets/lego.edrnr"})
      if (std::filesystem::exists(p)) return std::make_unique<edrnr::SceneModel>(edrnr::load_model(p));
    return nullptr;
  }();
  return model.get();
}

void run(benchmark::State& state, const edrnr::SceneModel& model) {
  const edrnr::Camera camera = edrnr::orbit_camera(800, 800, 30, 30, 4, 40);
  edrnr::RenderSettings settings;
  const int path = int(state.range(0));
  std::unique_ptr<edrnr::FastRenderer> fast;
  if (path < 2)
    fast = std::make_unique<edrnr::FastRenderer>(model, settings.form,
                                                 path == 0 ? edrnr::FastPath::Int8 : edrnr::FastPath::Float);
  edrnr::RenderStats stats;
  uint64_t samples = 0;
  for (auto _ : state) {
    edrnr::Image img =
        fast ? fast->render(camera, settings, &stats) : edrnr::render_reference(model, camera, settings, &stats);
    benchmark::DoNotOptimize(img.data.data());
    samples += stats.samples;
  }
  state.counters["FPS"] = benchmark::Counter(double(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["samples/s"] = benchmark::Counter(double(samples), benchmark::Counter::kIsRate);
}

void BM_RenderSeveral(benchmark::State& state) { run(state, several_256()); }

void BM_RenderLego(benchmark::State& state) {
  if (!lego()) {
    state.SkipWithError("assets/lego.edrnr not found from the working folder");
    return;
  }
  run(state, *lego());
}

}  // namespace

BENCHMARK(BM_RenderSeveral)->ArgName("path")->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_RenderLego)->ArgName("path")->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();
