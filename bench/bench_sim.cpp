// Host speed of the cycle simulator, on the frames docs/simulator.md reports:
//   lego  assets/lego.edrnr, test view 3 of ../shared/data/nerf_synthetic/lego, 800x800
//   mic   assets/mic.edrnr, test view 3 of ../shared/data/nerf_synthetic/mic, 800x800
//   proc  the procedural "several" scene (micro resolution 256, as
//         `edrnr make-scene several`), orbit camera, 800x800 (and 200x200)
// Each frame is simulated with simulate_chip on one and two threads, and
// rendered by the reference renderer on one thread (`edrnr render --engine
// reference --threads 1`: the default step, white background), so the ratio of the two
// comes from one run. Models are loaded before the clock starts. Also the
// memory system's cost per core cycle.
//
//   bench_sim --benchmark_filter='BM_Simulate/frame:0/|BM_Reference/frame:0'   # lego
//   bench_sim --benchmark_filter='BM_Simulate/frame:[0-3]/threads:1|BM_Simulate/frame:0/threads:2|BM_Reference'
//   bench_sim --benchmark_filter=MemorySystem
//   bench_sim --benchmark_filter='BM_SimulateVsReference/frame:0'   # nine lego pairs, median ratio
//   bench_sim --benchmark_filter='BM_TwoThreadsVsOne|BM_CoreRoundTrip'  # two threads' speed-up, core round trips
// Last figures (wall s, noisy host; docs/simulator.md "Host speed"): at the
// default step of half a micro voxel, AVX2-only AMD EPYC, lego one thread
// median 1.57 against the reference renderer's 1.74 (median ratio 0.90), mic
// 0.84, two threads 1.34-1.37x one thread; after the engine made the batch
// jobs the worker had not started (session 30): medians 1.32-1.38x, best
// 1.39-1.59x; session 31, the models in fitted boxes, a quieter window:
// lego one thread ratio median 0.93 (1.79 s against 1.99 s), mic 0.78, two
// threads medians 1.41-1.59x in seven runs. At one micro voxel before: on an
// AVX2-only AMD EPYC, lego one thread median 1.46 against the reference
// renderer's 1.45 (BM_SimulateVsReference median ratio 0.98 to 1.01), two
// threads 1.02 (BM_TwoThreadsVsOne median 1.45x) while the host kept the
// two vCPUs near each other (core round trip below 150 ns), about 1.0x one
// thread when not (round trip near 350 ns); the round before, one thread
// median 1.56 against 1.55 (ratio 1.02); on an
// AVX-512 machine before that, lego one thread least 1.20, median 1.32,
// against 1.13 and 1.20 (median ratio 1.09), two threads about 0.89-0.93
// when the host leaves both cores; mic one thread about 1.0x the reference.
// A frame whose model or dataset is missing is skipped with a message.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "data/dataset.h"
#include "model/model_io.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "render/reference.h"
#include "sim/memory_system.h"
#include "sim/simulator.h"

namespace {

using namespace edrnr;

// The source tree this benchmark was built from (for the presets and assets).
const std::filesystem::path kSource = std::filesystem::path(__FILE__).parent_path().parent_path();

const sim::SimConfig& preset() {
  static const sim::SimConfig c = sim::load_sim_config(kSource / "configs/chip/edr_nr_40nm.yaml");
  return c;
}

struct Workload {
  std::unique_ptr<SceneModel> model;
  Camera camera;
  std::string missing;  // non-empty: why the workload cannot run
};

// Frame index: 0 lego, 1 mic, 2 procedural 800x800, 3 procedural 200x200.
const Workload& workload(int64_t frame) {
  static std::map<int64_t, Workload> cache;
  auto it = cache.find(frame);
  if (it != cache.end()) return it->second;
  Workload w;
  if (frame <= 1) {
    const char* name = frame == 0 ? "lego" : "mic";
    const std::filesystem::path model = kSource / "assets" / (std::string(name) + ".edrnr");
    const std::filesystem::path data = kSource.parent_path() / "shared/data/nerf_synthetic" / name;
    if (!std::filesystem::exists(model) || !std::filesystem::exists(data / "transforms_test.json")) {
      w.missing = "needs " + model.string() + " and " + data.string();
    } else {
      w.model = std::make_unique<SceneModel>(load_model(model));
      DatasetOptions d;
      d.split = "test";
      d.load_images = false;
      w.camera = load_dataset(data, d).frames.at(3).camera;
    }
  } else {
    ProceduralOptions o;
    o.store_float = false;
    w.model = std::make_unique<SceneModel>(make_procedural_model("several", procedural_shapes("several"), o));
    const int side = frame == 2 ? 800 : 200;
    w.camera = orbit_camera(side, side, 30.0, 30.0, 4.0, 40.0);
  }
  return cache.emplace(frame, std::move(w)).first->second;
}

const char* kFrameNames[] = {"lego", "mic", "proc800", "proc200"};

// The workload of the benchmark's frame argument, labelled; null (the run
// skipped with the reason) when its model or dataset is missing.
const Workload* frame_of(benchmark::State& state) {
  const Workload& w = workload(state.range(0));
  if (!w.missing.empty()) {
    state.SkipWithError(w.missing.c_str());
    return nullptr;
  }
  state.SetLabel(kFrameNames[state.range(0)]);
  return &w;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Counters name_median, name_min and name_max of the values v (not empty).
void spread_counters(benchmark::State& state, const std::string& name, const std::vector<double>& v) {
  state.counters[name + "_median"] = median(v);
  state.counters[name + "_min"] = *std::min_element(v.begin(), v.end());
  state.counters[name + "_max"] = *std::max_element(v.begin(), v.end());
}

// The time, in ns, for a cache line to go from this thread to another and
// back: `trips` handovers of one atomic counter between two threads. Two
// threads of the simulator exchange results through such lines, so their
// speed-up over one depends on it (on a shared host it changes from minute
// to minute as the host moves the two vCPUs between cores).
double core_round_trip_ns(int trips) {
  alignas(64) std::atomic<int64_t> line{0};
  std::thread other([&] {
    for (int64_t i = 0; i < trips; ++i) {
      while (line.load(std::memory_order_acquire) != 2 * i + 1) {
      }
      line.store(2 * i + 2, std::memory_order_release);
    }
  });
  const auto t0 = std::chrono::steady_clock::now();
  for (int64_t i = 0; i < trips; ++i) {
    line.store(2 * i + 1, std::memory_order_release);
    while (line.load(std::memory_order_acquire) != 2 * i + 2) {
    }
  }
  const auto t1 = std::chrono::steady_clock::now();
  other.join();
  return std::chrono::duration<double, std::nano>(t1 - t0).count() / trips;
}

// args: frame, threads. Counters: simulated cycles per host second, cycles and
// samples of the frame.
void BM_Simulate(benchmark::State& state) {
  const Workload* wp = frame_of(state);
  if (!wp) return;
  const Workload& w = *wp;
  sim::SimOptions opt;
  opt.threads = int(state.range(1));
  uint64_t cycles = 0, samples = 0;
  for (auto _ : state) {
    const sim::SimResult r = sim::simulate_chip(*w.model, w.camera, preset(), opt);
    cycles += r.summary.cycles;
    samples += r.summary.samples;
  }
  state.counters["sim_cycles_per_s"] = benchmark::Counter(double(cycles), benchmark::Counter::kIsRate);
  state.counters["samples_per_s"] = benchmark::Counter(double(samples), benchmark::Counter::kIsRate);
  state.counters["cycles_per_frame"] = double(cycles) / double(state.iterations());
}
BENCHMARK(BM_Simulate)
    ->ArgNames({"frame", "threads"})
    ->ArgsProduct({{0, 1, 2}, {1, 2}})
    ->Args({3, 1})
    ->Iterations(1)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

// The reference renderer on one thread, same frames (args: frame).
void BM_Reference(benchmark::State& state) {
  const Workload* wp = frame_of(state);
  if (!wp) return;
  const Workload& w = *wp;
  RenderSettings s;
  s.threads = 1;
  for (auto _ : state) benchmark::DoNotOptimize(render_reference(*w.model, w.camera, s));
}
BENCHMARK(BM_Reference)->ArgNames({"frame"})->DenseRange(0, 2)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

// The simulator against the reference renderer, both on one thread, as
// pairs run back to back in one process: each iteration times one
// simulate_chip and then one render_reference of the frame, and the
// counters give the median, least and greatest ratio of the pairs (a noisy
// host moves single runs by tens of percent; the pairs' median much less).
void BM_SimulateVsReference(benchmark::State& state) {
  const Workload* wp = frame_of(state);
  if (!wp) return;
  const Workload& w = *wp;
  sim::SimOptions opt;
  RenderSettings s;
  s.threads = 1;
  std::vector<double> ratios, sim_s, ref_s;
  using Clock = std::chrono::steady_clock;
  for (auto _ : state) {
    const Clock::time_point t0 = Clock::now();
    benchmark::DoNotOptimize(sim::simulate_chip(*w.model, w.camera, preset(), opt));
    const Clock::time_point t1 = Clock::now();
    benchmark::DoNotOptimize(render_reference(*w.model, w.camera, s));
    const Clock::time_point t2 = Clock::now();
    sim_s.push_back(std::chrono::duration<double>(t1 - t0).count());
    ref_s.push_back(std::chrono::duration<double>(t2 - t1).count());
    ratios.push_back(sim_s.back() / ref_s.back());
  }
  spread_counters(state, "ratio", ratios);
  state.counters["sim_s_median"] = median(sim_s);
  state.counters["reference_s_median"] = median(ref_s);
}
BENCHMARK(BM_SimulateVsReference)
    ->ArgNames({"frame"})
    ->DenseRange(0, 1)
    ->Iterations(9)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

// The simulator on two threads against one, as pairs back to back (one
// thread, then two), each pair followed by a core round trip
// (core_round_trip_ns). Counters: the median speed-up of the pairs, that of
// the pairs whose round trips before and after stayed below 150 ns (the
// two vCPUs near each other), the median round trip, and best_speedup: the
// least one-thread time over the least two-thread time.
void BM_TwoThreadsVsOne(benchmark::State& state) {
  const Workload* wp = frame_of(state);
  if (!wp) return;
  const Workload& w = *wp;
  sim::SimOptions one, two;
  two.threads = 2;
  std::vector<double> speedups, near_speedups, trips, one_s, two_s;
  using Clock = std::chrono::steady_clock;
  double before = core_round_trip_ns(20000);
  for (auto _ : state) {
    const Clock::time_point t0 = Clock::now();
    benchmark::DoNotOptimize(sim::simulate_chip(*w.model, w.camera, preset(), one));
    const Clock::time_point t1 = Clock::now();
    benchmark::DoNotOptimize(sim::simulate_chip(*w.model, w.camera, preset(), two));
    const Clock::time_point t2 = Clock::now();
    const double after = core_round_trip_ns(20000);
    one_s.push_back(std::chrono::duration<double>(t1 - t0).count());
    two_s.push_back(std::chrono::duration<double>(t2 - t1).count());
    const double speedup = one_s.back() / two_s.back();
    speedups.push_back(speedup);
    if (std::max(before, after) < 150.0) near_speedups.push_back(speedup);
    trips.push_back(after);
    before = after;
  }
  spread_counters(state, "speedup", speedups);
  state.counters["near_pairs"] = double(near_speedups.size());
  if (!near_speedups.empty()) state.counters["near_speedup_median"] = median(near_speedups);
  state.counters["round_trip_ns_median"] = median(trips);
  // The least time of each: what the host's noise (which only adds time)
  // leaves of each side.
  state.counters["best_speedup"] =
      *std::min_element(one_s.begin(), one_s.end()) / *std::min_element(two_s.begin(), two_s.end());
}
BENCHMARK(BM_TwoThreadsVsOne)->ArgNames({"frame"})->Arg(0)->Iterations(9)->Unit(benchmark::kSecond)->UseRealTime();

// The core round trip alone (see core_round_trip_ns), 20000 trips a time.
void BM_CoreRoundTrip(benchmark::State& state) {
  std::vector<double> trips;
  for (auto _ : state) trips.push_back(core_round_trip_ns(20000));
  spread_counters(state, "round_trip_ns", trips);
}
BENCHMARK(BM_CoreRoundTrip)->Iterations(50)->Unit(benchmark::kMillisecond)->UseRealTime();

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
  mem.sync();  // the idle clocks advance() left for later
  state.counters["core_cycles_per_s"] = benchmark::Counter(double(cycle), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_MemorySystemCycle)->Arg(0)->Arg(1);

}  // namespace

BENCHMARK_MAIN();
