// edrnr dram: runs the DDR3 model on its own, on a trace or on synthetic
// traffic, and prints latency, bandwidth, row-buffer and energy statistics.
#include <fmt/format.h>

#include <filesystem>
#include <iostream>
#include <memory>
#include <utility>

#include "commands.h"
#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"
#include "core/stats.h"
#include "sim/dram.h"
#include "sim/dram_config.h"
#include "sim/dram_trace.h"

namespace edrnr::cli {
namespace {

struct DramOptions {
  std::string preset;
  std::string trace;
  int64_t random_count = 0;
  int64_t stream_count = 0;
  CLI::Option *random_opt = nullptr, *stream_opt = nullptr;
  double write_ratio = 0.0;
  uint64_t seed = 1;
  std::string json_path;
};

// Where presets are looked for: the working directory, beside the executable
// (build or install tree), and the source tree this binary was built from.
std::vector<std::filesystem::path> preset_search_dirs() {
  namespace fs = std::filesystem;
  std::vector<fs::path> dirs = {fs::path("configs") / "dram"};
  std::error_code ec;
  fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    fs::path dir = exe.parent_path();
    dirs.push_back(dir / "configs" / "dram");
    dirs.push_back(dir.parent_path() / "configs" / "dram");
    dirs.push_back(dir.parent_path() / "share" / "edrnr" / "configs" / "dram");
  }
  fs::path source_root = fs::path(__FILE__).parent_path().parent_path().parent_path();
  if (source_root.is_absolute()) dirs.push_back(source_root / "configs" / "dram");
  return dirs;
}

void run_dram(const DramOptions& o) {
  const int workloads = !o.trace.empty() + (o.random_opt->count() > 0) + (o.stream_opt->count() > 0);
  if (workloads != 1) fail("dram: give exactly one of --trace FILE, --random N or --stream N (N > 0)");
  for (auto [opt, n] : {std::pair{o.random_opt, o.random_count}, std::pair{o.stream_opt, o.stream_count}})
    if (opt->count() && (n < 1 || uint64_t(n) > limits::kMaxDramRequests))
      fail("{} {}: must be between 1 and {} requests (limit)", opt->get_name(), n, limits::kMaxDramRequests);
  if (!(o.write_ratio >= 0.0 && o.write_ratio <= 1.0)) {
    fail("--write-ratio {} must be between 0 and 1", o.write_ratio);
  }
  if (!o.json_path.empty()) check_output_path(o.json_path, "--json");
  std::filesystem::path preset_path;
  sim::DramConfig config;
  try {
    preset_path = sim::find_dram_preset(o.preset, preset_search_dirs());
    config = sim::load_dram_config(preset_path);
  } catch (const Error& e) {
    fail("--preset '{}': {}", o.preset, e.what());
  }

  sim::DramRequestSource source;
  std::string workload;
  if (!o.trace.empty()) {
    source = sim::trace_source(sim::load_dram_trace(o.trace));
    workload = fmt::format("trace {}", o.trace);
  } else if (o.random_opt->count()) {
    source = sim::random_source(config, uint64_t(o.random_count), o.write_ratio, o.seed);
    workload = fmt::format("random, {} requests, write ratio {}, seed {}", o.random_count, o.write_ratio, o.seed);
  } else {
    source = sim::stream_source(config, uint64_t(o.stream_count), o.write_ratio, o.seed);
    workload = fmt::format("stream, {} requests, write ratio {}, seed {}", o.stream_count, o.write_ratio, o.seed);
  }

  StatsRegistry stats;
  sim::DramSystem dram(config, stats);
  Distribution& from_arrival =
      stats.distribution("workload.read_latency_from_arrival", "cycles",
                         "read latency from the request's arrival cycle to its last data (queue wait included)");
  uint64_t requests = sim::run_dram_workload(dram, source, &from_arrival);
  dram.update_stats();

  std::cout << fmt::format("preset    {} ({})\n", config.name, preset_path.string());
  std::cout << fmt::format("organised {} channel(s) x {} rank(s) x {} banks, {}-bit bus, {} B bursts, {} MiB\n",
                           config.channels, config.ranks, config.banks, config.bus_width_bits, config.burst_bytes(),
                           config.capacity_bytes() >> 20);
  std::cout << fmt::format("timing    tCK {} ns, CL-tRCD-tRP {}-{}-{}, peak {:.3f} GB/s\n", config.tCK_ns, config.CL,
                           config.tRCD, config.tRP, config.peak_bandwidth_GBps());
  std::cout << fmt::format("workload  {}: {} requests in {} cycles ({:.3f} us)\n\n", workload, requests, dram.cycle(),
                           static_cast<double>(dram.cycle()) * config.tCK_ns / 1000.0);
  stats.print_table(std::cout);

  if (!o.json_path.empty()) {
    nlohmann::json j;
    j["preset"] = preset_path.string();
    j["config_yaml"] = sim::dram_config_to_yaml(config);
    j["workload"] = workload;
    j["requests"] = requests;
    j["stats"] = stats.to_json();
    write_file_atomic(o.json_path, j.dump(2) + "\n");
  }
}

void register_dram_cmd(CLI::App& app) {
  auto opts = std::make_shared<DramOptions>();
  CLI::App* cmd = app.add_subcommand("dram", "Run the DDR3 timing and energy model on a trace or synthetic traffic");
  cmd->add_option("--preset", opts->preset, "DRAM preset name (configs/dram/NAME.yaml) or a YAML file path")
      ->required();
  auto* trace = cmd->add_option("--trace", opts->trace, "trace file: one '0xADDRESS READ|WRITE CYCLE' per line");
  auto* random = opts->random_opt =
      cmd->add_option("--random", opts->random_count, "N one-burst requests at random addresses");
  auto* stream = opts->stream_opt =
      cmd->add_option("--stream", opts->stream_count, "N one-burst requests at sequential addresses");
  trace->excludes(random)->excludes(stream);
  random->excludes(stream);
  cmd->add_option("--write-ratio", opts->write_ratio, "fraction of synthetic requests that are writes (0..1)");
  cmd->add_option("--seed", opts->seed, "seed for synthetic traffic");
  cmd->add_option("--json", opts->json_path, "also write the configuration and statistics as JSON to this file");
  cmd->callback([opts] { run_dram(*opts); });
}

Registrar reg{70, register_dram_cmd};

}  // namespace
}  // namespace edrnr::cli
