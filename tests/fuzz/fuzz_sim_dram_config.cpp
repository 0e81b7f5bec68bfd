// libFuzzer harness for the DRAM preset loader (scripts/fuzz.sh).
//
// Each input is parsed as a configs/dram YAML text. A parse may only end in
// edrnr::Error; anything else is a finding. A preset that parses must build a
// DramSystem, serve a few requests, and write back to YAML that parses to the
// same values.
//
// With EDRNR_FUZZ_WRITE_SEEDS=DIR set, the harness copies the shipped presets
// into DIR as the seed corpus and exits.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "core/error.h"
#include "core/file_io.h"
#include "core/stats.h"
#include "sim/dram.h"
#include "sim/dram_config.h"

namespace {

using namespace edrnr;
using namespace edrnr::sim;

void write_seeds(const std::filesystem::path& dir) {
  std::filesystem::create_directories(dir);
  int n = 0;
  for (const auto& e :
       std::filesystem::directory_iterator(std::filesystem::path(EDRNR_SOURCE_DIR) / "configs" / "dram"))
    if (e.path().extension() == ".yaml") {
      write_file_atomic(dir / e.path().filename(), read_file_text(e.path()));
      ++n;
    }
  std::printf("wrote %d seed presets to %s\n", n, dir.c_str());
}

[[noreturn]] void finding(const char* what, const std::string& detail) {
  std::fprintf(stderr, "%s: %s\n", what, detail.c_str());
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = std::getenv("EDRNR_FUZZ_WRITE_SEEDS")) {
    write_seeds(dir);
    std::exit(0);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  DramConfig c;
  try {
    c = parse_dram_config(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.yaml");
  } catch (const Error&) {
    return 0;
  }
  try {
    const DramConfig back = parse_dram_config(dram_config_to_yaml(c), "fuzz round trip");
    if (dram_config_to_yaml(back) != dram_config_to_yaml(c)) finding("YAML round trip changed the preset", "");
    StatsRegistry stats;
    DramSystem dram(c, stats);
    const uint64_t burst = c.burst_bytes();
    const uint64_t bursts = c.capacity_bytes() / burst;
    uint64_t id = 0, done = 0;
    // Eight requests, or as many as the queue takes (back-pressure is not a fault).
    for (uint64_t k = 0; k < 8; ++k)
      if (dram.enqueue(k % 3 ? DramOp::kRead : DramOp::kWrite, (k * 7919 % bursts) * burst, uint32_t(burst), id)) ++id;
    for (uint64_t cycle = 0; cycle < 200000 && done < id; ++cycle) {
      dram.tick();
      while (dram.pop_completion()) ++done;
    }
    if (done != id) finding("requests did not complete within 200000 cycles", std::to_string(done));
    dram.update_stats();
  } catch (const Error& e) {
    finding("a preset that parsed fails to round-trip or to run", e.what());
  }
  return 0;
}
