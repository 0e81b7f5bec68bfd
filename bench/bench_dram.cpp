// Simulation speed of the DDR3 model: DRAM cycles simulated per second for a
// saturating sequential stream and for random traffic.
#include <benchmark/benchmark.h>

#include <filesystem>

#include "core/stats.h"
#include "sim/dram.h"
#include "sim/dram_config.h"
#include "sim/dram_trace.h"

namespace {

edrnr::sim::DramConfig preset() {
  std::filesystem::path source_root = std::filesystem::path(__FILE__).parent_path().parent_path();
  return edrnr::sim::load_dram_config(source_root / "configs" / "dram" / "ddr3-1600-4gb-x16-64bit.yaml");
}

void run(benchmark::State& state, bool random) {
  const edrnr::sim::DramConfig config = preset();
  const uint64_t requests = static_cast<uint64_t>(state.range(0));
  uint64_t cycles = 0;
  for (auto _ : state) {
    edrnr::StatsRegistry stats;
    edrnr::sim::DramSystem dram(config, stats);
    auto source = random ? edrnr::sim::random_source(config, requests, 0.3, 1)
                         : edrnr::sim::stream_source(config, requests, 0.0, 1);
    edrnr::sim::run_dram_workload(dram, source);
    cycles += dram.cycle();
  }
  state.counters["dram_cycles_per_s"] = benchmark::Counter(static_cast<double>(cycles), benchmark::Counter::kIsRate);
  state.SetItemsProcessed(static_cast<int64_t>(requests) * state.iterations());
}

void BM_DramStream(benchmark::State& state) { run(state, false); }
void BM_DramRandom(benchmark::State& state) { run(state, true); }

BENCHMARK(BM_DramStream)->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DramRandom)->Arg(100000)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
