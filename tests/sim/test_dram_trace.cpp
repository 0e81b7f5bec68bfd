// Trace parsing, synthetic traffic and the workload driver.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <filesystem>

#include "core/error.h"
#include "core/stats.h"
#include "sim/dram_trace.h"

namespace edrnr::sim {
namespace {

const std::filesystem::path kPreset =
    std::filesystem::path(EDRNR_SOURCE_DIR) / "configs" / "dram" / "ddr3-1600-4gb-x16-64bit.yaml";

std::string error_of(const std::string& text) {
  try {
    parse_dram_trace(text, "t.trace");
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(DramTrace, ParsesTheCommonFormat) {
  auto r = parse_dram_trace(
      "# address type cycle\n"
      "0x1000 READ 0\n"
      "\n"
      "  0X2a40\tWRITE   5\r\n"
      "4096 read 5\n"
      "0xffffffff write 1000",
      "t.trace");
  ASSERT_EQ(r.size(), 4u);
  EXPECT_EQ(r[0].address, 0x1000u);
  EXPECT_EQ(r[0].op, DramOp::kRead);
  EXPECT_EQ(r[0].cycle, 0u);
  EXPECT_EQ(r[0].line, 2u);
  EXPECT_EQ(r[1].address, 0x2a40u);
  EXPECT_EQ(r[1].op, DramOp::kWrite);
  EXPECT_EQ(r[1].cycle, 5u);
  EXPECT_EQ(r[1].line, 4u);
  EXPECT_EQ(r[2].address, 4096u);  // decimal is accepted too
  EXPECT_EQ(r[3].address, 0xffffffffu);
  EXPECT_EQ(r[3].cycle, 1000u);
  EXPECT_EQ(r[3].line, 6u);
}

TEST(DramTrace, ErrorsNameTheLine) {
  EXPECT_NE(error_of("0x0 READ 0\n0x40 FETCH 1\n").find("t.trace:2:"), std::string::npos);
  EXPECT_NE(error_of("0x0 READ 0\n0x40 FETCH 1\n").find("FETCH"), std::string::npos);
  EXPECT_NE(error_of("\n\n0xZZ READ 1\n").find("t.trace:3:"), std::string::npos);
  EXPECT_NE(error_of("0x0 READ\n").find("t.trace:1:"), std::string::npos);
  EXPECT_NE(error_of("0x0 READ 1 extra\n").find("t.trace:1:"), std::string::npos);
  EXPECT_NE(error_of("0x0 READ 1.5\n").find("t.trace:1:"), std::string::npos);
  EXPECT_NE(error_of("0x0 READ 10\n0x40 READ 9\n").find("t.trace:2:"), std::string::npos);
  EXPECT_EQ(error_of("0x0 READ 10\n0x40 READ 10\n"), "");
}

TEST(DramTrace, TraceRunGivesTheClosedBankAndRowHitLatencies) {
  DramConfig c = load_dram_config(kPreset);
  StatsRegistry stats;
  DramSystem dram(c, stats);
  // A read to a closed bank at 0 (tRCD + CL + tBURST = 26), a hit on the same
  // row at 100 (CL + tBURST = 15); the address 0x48 lies in burst 1.
  auto records = parse_dram_trace("0x0 READ 0\n0x48 READ 100\n", "t");
  EXPECT_EQ(run_dram_workload(dram, trace_source(records)), 2u);
  EXPECT_EQ(dram.cycle(), 115u);
  dram.update_stats();
  nlohmann::json j = stats.to_json();
  EXPECT_EQ(j["dram.read_latency"]["max"], 26);
  EXPECT_EQ(j["dram.read_latency"]["min"], 15);
  EXPECT_EQ(stats.get("dram.row_hits"), 1.0);
  EXPECT_DOUBLE_EQ(stats.get("dram.row_hit_rate"), 0.5);
  EXPECT_DOUBLE_EQ(stats.get("dram.read_latency_max_ns"), 26 * 1.25);
  EXPECT_DOUBLE_EQ(stats.get("dram.bandwidth_GBps"), 128.0 / (115 * 1.25));
}

TEST(DramTrace, AddressBeyondCapacityNamesTheLine) {
  DramConfig c = load_dram_config(kPreset);
  StatsRegistry stats;
  DramSystem dram(c, stats);
  auto records = parse_dram_trace("0x0 READ 0\n0x80000000 READ 1\n", "t");  // capacity is 2 GiB = 0x80000000
  try {
    run_dram_workload(dram, trace_source(records));
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("line 2"), std::string::npos) << e.what();
  }
}

TEST(DramTrace, SyntheticSourcesAreDeterministicAndShaped) {
  DramConfig c = load_dram_config(kPreset);
  auto collect = [](const DramRequestSource& s) {
    std::vector<DramTraceRecord> out;
    DramTraceRecord r;
    while (s(r)) out.push_back(r);
    return out;
  };
  auto stream = collect(stream_source(c, 1000, 0.0, 1));
  ASSERT_EQ(stream.size(), 1000u);
  for (size_t i = 0; i < stream.size(); ++i) {
    EXPECT_EQ(stream[i].address, i * 64);
    EXPECT_EQ(stream[i].op, DramOp::kRead);
    EXPECT_EQ(stream[i].cycle, 0u);
  }
  auto a = collect(random_source(c, 20000, 0.25, 9));
  auto b = collect(random_source(c, 20000, 0.25, 9));
  ASSERT_EQ(a.size(), 20000u);
  size_t writes = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].address, b[i].address);
    EXPECT_EQ(a[i].address % 64, 0u);
    EXPECT_LT(a[i].address, c.capacity_bytes());
    writes += a[i].op == DramOp::kWrite;
  }
  // Binomial(20000, 0.25): mean 5000, standard deviation ~61; allow 6 sigma.
  EXPECT_NEAR(static_cast<double>(writes), 5000.0, 370.0);
  auto all_writes = collect(stream_source(c, 100, 1.0, 3));
  for (const auto& r : all_writes) EXPECT_EQ(r.op, DramOp::kWrite);
}

// A request far in the future is refused past the stated limit, and the idle
// stretch before a late request is jumped over with exactly the result of
// ticking through it (issue #16: a request at cycle 9e18 hung `edrnr dram`).
TEST(DramTrace, ArrivalCycleLimit) {
  const std::string m = error_of("0x0 READ 5\n0x40 READ 9000000000000000000\n");
  EXPECT_NE(m.find("t.trace:2: cycle 9000000000000000000 is over the limit of 10000000000 DRAM clocks"),
            std::string::npos)
      << m;
  EXPECT_EQ(error_of("0x0 READ 10000000000\n"), "");
}

// The reference: the workload driver as it was, one tick per DRAM clock.
uint64_t run_ticking(DramSystem& dram, const DramRequestSource& source) {
  DramTraceRecord next;
  bool have = source(next);
  uint64_t accepted = 0;
  while (have || !dram.idle()) {
    while (have && next.cycle <= dram.cycle()) {
      if (!dram.enqueue(next.op, next.address, 64, accepted)) break;
      ++accepted;
      have = source(next);
    }
    dram.tick();
    while (dram.pop_completion()) {
    }
  }
  return accepted;
}

TEST(DramTrace, IdleGapsAreJumpedWithTheSameResultAsTicking) {
  DramConfig c = load_dram_config(kPreset);
  // Bursts, then gaps across several refresh intervals (tREFI), one ending
  // right at a refresh, some rows left open across a gap.
  std::string text;
  const uint64_t refi = c.tREFI;
  for (uint64_t t : {uint64_t{0}, uint64_t{3}, uint64_t{40}, refi - 1, refi, 5 * refi + 17, 5 * refi + 18, 9 * refi + 2,
                     40 * refi + 123}) {
    for (int k = 0; k < 6; ++k)
      text += fmt::format("0x{:x} {} {}\n", (t * 4096 + uint64_t(k) * 8192) % (1u << 30), k % 3 ? "READ" : "WRITE", t);
  }
  for (bool refresh : {true, false}) {
    c.refresh = refresh;
    StatsRegistry sa, sb;
    DramSystem a(c, sa), b(c, sb);
    const uint64_t na = run_dram_workload(a, trace_source(parse_dram_trace(text, "gaps")));
    const uint64_t nb = run_ticking(b, trace_source(parse_dram_trace(text, "gaps")));
    a.update_stats();
    b.update_stats();
    EXPECT_EQ(na, nb);
    EXPECT_EQ(a.cycle(), b.cycle());
    EXPECT_EQ(sa.to_json().dump(), sb.to_json().dump()) << "refresh " << refresh;
  }
}

}  // namespace
}  // namespace edrnr::sim
