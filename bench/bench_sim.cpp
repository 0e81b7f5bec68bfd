// Host speed of the cycle simulator: one frame of the procedural "several"
// scene (micro resolution 256, as `edrnr make-scene several`) through
// simulate_chip, at 200x200 and 800x800, on one and two threads; and the
// memory system's cost per core cycle; and the bundled lego model
// (assets/lego.edrnr) from its first test view, the host-speed target's
// workload. docs/simulator.md lists the figures.
//
//   bench_sim --benchmark_filter=Frame/800    # the procedural scene, 800x800
//   bench_sim --benchmark_filter=Lego         # the 60 s target (needs ../shared/data)
#include <benchmark/benchmark.h>

#include <filesystem>

#include "data/dataset.h"
#include "model/model_io.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "sim/memory_system.h"
#include "sim/simulator.h"

namespace {

using namespace edrnr;

// The source tree this benchmark was built from (for the presets).
const std::filesystem::path kSource = std::filesystem::path(__FILE__).parent_path().parent_path();

const SceneModel& several() {
  static const SceneModel m = [] {
    ProceduralOptions o;
    o.store_float = false;
    return make_procedural_model("several", procedural_shapes("several"), o);
  }();
  return m;
}

const sim::SimConfig& preset() {
  static const sim::SimConfig c = sim::load_sim_config(kSource / "configs/chip/edr_nr_40nm.yaml");
  return c;
}

// args: image side, threads.
void BM_SimulateFrame(benchmark::State& state) {
  const SceneModel& m = several();
  const Camera cam = orbit_camera(int(state.range(0)), int(state.range(0)), 30.0, 30.0, 4.0, 40.0);
  sim::SimOptions opt;
  opt.threads = int(state.range(1));
  uint64_t cycles = 0, samples = 0;
  for (auto _ : state) {
    const sim::SimResult r = sim::simulate_chip(m, cam, preset(), opt);
    cycles += r.summary.cycles;
    samples += r.summary.samples;
  }
  state.counters["sim_cycles_per_s"] = benchmark::Counter(double(cycles), benchmark::Counter::kIsRate);
  state.counters["samples_per_s"] = benchmark::Counter(double(samples), benchmark::Counter::kIsRate);
  state.counters["cycles_per_frame"] = double(cycles) / double(state.iterations());
}
BENCHMARK(BM_SimulateFrame)
    ->Args({200, 1})
    ->Args({200, 2})
    ->Args({800, 1})
    ->Args({800, 2})
    ->Iterations(1)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

// The bundled lego model, test view 0 of the dataset beside the source tree,
// 800x800; skipped when the model or the dataset is missing.
void BM_SimulateLego(benchmark::State& state) {
  const std::filesystem::path model = kSource / "assets/lego.edrnr";
  const std::filesystem::path data = kSource.parent_path() / "shared/data/nerf_synthetic/lego";
  if (!std::filesystem::exists(model) || !std::filesystem::exists(data / "transforms_test.json")) {
    state.SkipWithError("needs assets/lego.edrnr and ../shared/data/nerf_synthetic/lego");
    return;
  }
  const SceneModel m = load_model(model);
  DatasetOptions d;
  d.split = "test";
  d.load_images = false;
  const Camera cam = load_dataset(data, d).frames.at(0).camera;
  sim::SimOptions opt;
  opt.threads = int(state.range(0));
  uint64_t cycles = 0;
  for (auto _ : state) cycles += sim::simulate_chip(m, cam, preset(), opt).summary.cycles;
  state.counters["sim_cycles_per_s"] = benchmark::Counter(double(cycles), benchmark::Counter::kIsRate);
  state.counters["cycles_per_frame"] = double(cycles) / double(state.iterations());
}
BENCHMARK(BM_SimulateLego)->Arg(1)->Arg(2)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

// The DRAM model behind the clock crossing, per core cycle: idle, and with a
// 1000-byte feature block read started every 200 core cycles.
void BM_MemorySystemCycle(benchmark::State& state) {
  const sim::DramConfig dram = sim::load_dram_config(kSource / "configs/dram/ddr3-1600-4gb-x16-16bit.yaml");
  sim::AddressMap map;
  map.bytes = {0, 0, uint64_t(1) << 26, 0, 0};
  StatsRegistry stats;
  sim::MemorySystem mem(dram, 380.0, 64, map, stats);
  std::vector<sim::MemoryCompletion> done;
  uint64_t cycle = 0, block = 0;
  const bool loaded = state.range(0) != 0;
  for (auto _ : state) {
    if (loaded && cycle % 200 == 0) mem.read(sim::DataType::Features, (block++ * 7919 % 65536) * 1024, 1000, 0, cycle);
    mem.advance(cycle++, done);
    done.clear();
  }
  state.counters["core_cycles_per_s"] = benchmark::Counter(double(cycle), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_MemorySystemCycle)->Arg(0)->Arg(1);

}  // namespace

BENCHMARK_MAIN();
