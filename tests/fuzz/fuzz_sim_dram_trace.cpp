// libFuzzer harness for the DRAM trace reader and the workload driver
// (scripts/fuzz.sh).
//
// Each input is parsed as a trace. A parse may only end in edrnr::Error;
// anything else is a finding. A short trace that parses is run on the
// DDR3-1600 x16 preset to completion (run_dram_workload may refuse an address
// beyond the capacity with Error); the driver's idle jumps must give exactly
// the statistics of ticking through the trace one clock at a time.
//
// With EDRNR_FUZZ_WRITE_SEEDS=DIR set, the harness writes a few traces into
// DIR as the seed corpus and exits.
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
#include "sim/dram_trace.h"

namespace {

using namespace edrnr;
using namespace edrnr::sim;

const DramConfig& preset() {
  static const DramConfig c =
      load_dram_config(std::filesystem::path(EDRNR_SOURCE_DIR) / "configs" / "dram" / "ddr3-1600-4gb-x16-16bit.yaml");
  return c;
}

void write_seeds(const std::filesystem::path& dir) {
  std::filesystem::create_directories(dir);
  write_file_atomic(dir / "stream.trace", std::string("# address type cycle\n0x0 READ 0\n0x10 READ 0\n0x20 WRITE 3\n"
                                                      "0x30 READ 3\n0x1000 READ 10\n"));
  write_file_atomic(dir / "gaps.trace", std::string("0x0 READ 0\n0x4000000 WRITE 5\n0x40 READ 7000\n"
                                                    "0x8000 read 7001\n4096 write 20000\n"));
  write_file_atomic(dir / "conflicts.trace", std::string("0x0 READ 1\n0x100000 READ 1\n0x200000 READ 1\n"
                                                         "0x0 WRITE 2\r\n\n0X300000 READ 2\n"));
  std::printf("wrote 3 seed traces to %s\n", dir.c_str());
}

[[noreturn]] void finding(const char* what, const std::string& detail) {
  std::fprintf(stderr, "%s: %s\n", what, detail.c_str());
  std::abort();
}

// The driver as it was before idle jumps: one tick per DRAM clock.
uint64_t run_ticking(DramSystem& dram, const std::vector<DramTraceRecord>& records) {
  const uint64_t burst = dram.config().burst_bytes();
  size_t next = 0;
  uint64_t accepted = 0;
  while (next < records.size() || !dram.idle()) {
    while (next < records.size() && records[next].cycle <= dram.cycle()) {
      const uint64_t a = records[next].address - records[next].address % burst;
      if (!dram.enqueue(records[next].op, a, uint32_t(burst), accepted)) break;
      ++accepted;
      ++next;
    }
    dram.tick();
    while (dram.pop_completion()) {
    }
  }
  return accepted;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = std::getenv("EDRNR_FUZZ_WRITE_SEEDS")) {
    write_seeds(dir);
    std::exit(0);
  }
  preset();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::vector<DramTraceRecord> records;
  try {
    records = parse_dram_trace(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.trace");
  } catch (const Error&) {
    return 0;
  }
  // Run short traces only (a long gap is fine for the driver, but the
  // tick-by-tick reference would take too long).
  if (records.size() > 64 || (!records.empty() && records.back().cycle > 100000)) return 0;
  for (const DramTraceRecord& r : records)
    if (r.address >= preset().capacity_bytes()) {
      StatsRegistry s;
      DramSystem d(preset(), s);
      try {
        run_dram_workload(d, trace_source(records));
      } catch (const Error&) {
        return 0;  // refused, as it must be
      }
      finding("an address beyond the capacity was accepted", std::to_string(r.address));
    }
  StatsRegistry sa, sb;
  DramSystem a(preset(), sa), b(preset(), sb);
  uint64_t na = 0, nb = 0;
  try {
    na = run_dram_workload(a, trace_source(records));
    nb = run_ticking(b, records);
  } catch (const Error& e) {
    finding("a valid trace failed to run", e.what());
  }
  a.update_stats();
  b.update_stats();
  if (na != nb || na != records.size() || a.cycle() != b.cycle() || sa.to_json() != sb.to_json())
    finding("idle jumps changed the result", std::to_string(a.cycle()) + " vs " + std::to_string(b.cycle()));
  return 0;
}
