// Trace parsing, synthetic traffic and the workload driver.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <filesystem>

#include "core/error.h"
#include "core/stats.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "sim/dram_trace.h"
#include "sim/sim_config.h"
#include "sim/simulator.h"

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

TEST(DramTrace, LatencyFromArrivalIncludesTheWaitForRoomInTheQueue) {
  DramConfig c = load_dram_config(kPreset);
  {
    // Nothing waits: from arrival is the model's latency (26 closed bank, 15 row hit).
    StatsRegistry stats;
    DramSystem dram(c, stats);
    Distribution from_arrival;
    run_dram_workload(dram, trace_source(parse_dram_trace("0x0 READ 0\n0x48 READ 100\n", "t")), &from_arrival);
    EXPECT_EQ(from_arrival.count(), 2u);
    EXPECT_EQ(from_arrival.max(), 26u);
    EXPECT_EQ(from_arrival.min(), 15u);
  }
  {
    // A one-burst queue: the second read of the row arrives at 0 with the
    // first but enters only when the queue has room, so from its arrival it
    // waits longer than the model counts from its entry; its data follows the
    // first's by at least tBURST (26 + 4). Writes are not counted.
    c.queue_depth_bursts = 1;
    StatsRegistry stats;
    DramSystem dram(c, stats);
    Distribution from_arrival;
    run_dram_workload(dram, trace_source(parse_dram_trace("0x0 READ 0\n0x40 READ 0\n0x80 WRITE 0\n", "t")),
                      &from_arrival);
    dram.update_stats();
    EXPECT_EQ(from_arrival.count(), 2u);
    EXPECT_EQ(from_arrival.min(), 26u);
    EXPECT_GE(from_arrival.max(), 30u);
    EXPECT_GT(from_arrival.max(), stats.to_json()["dram.read_latency"]["max"].get<uint64_t>());
  }
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

TEST(DramTrace, AppendWritesOneLinePerBurstThatParsesBack) {
  std::string text;
  append_dram_trace(text, 0x1234, 40, DramOp::kWrite, 7, 16);  // bytes 0x1234..0x125b: bursts 0x1230, 0x1240, 0x1250
  append_dram_trace(text, 0x100, 32, DramOp::kRead, 9, 16);    // aligned: 0x100, 0x110
  append_dram_trace(text, 0x500, 0, DramOp::kRead, 9, 16);     // nothing
  append_dram_trace(text, 0x7f, 1, DramOp::kRead, 12, 64);     // one byte: its 64-byte burst 0x40
  EXPECT_EQ(text, "0x1230 WRITE 7\n0x1240 WRITE 7\n0x1250 WRITE 7\n0x100 READ 9\n0x110 READ 9\n0x40 READ 12\n");
  const std::vector<DramTraceRecord> r = parse_dram_trace(text, "appended");
  ASSERT_EQ(r.size(), 6u);
  EXPECT_EQ(r[2].address, 0x1250u);
  EXPECT_EQ(r[2].op, DramOp::kWrite);
  EXPECT_EQ(r[4].cycle, 9u);
}

TEST(DramTrace, SimulatorFrameTraceReplaysToTheSameTraffic) {
  ProceduralOptions po;
  po.micro_res = 32;
  po.seed = 3;
  const SceneModel model = make_procedural_model("several", procedural_shapes("several"), po);
  SimConfig cfg = load_sim_config(std::filesystem::path(EDRNR_SOURCE_DIR) / "configs/chip/edr_nr_40nm.yaml");
  cfg.memory.write_output = true;  // the finished ray packets go to DRAM too: writes in the trace
  std::string text;
  SimOptions opt;
  const uint64_t burst_bytes = cfg.memory.dram.burst_bytes();
  opt.dram_request_observer = [&](uint64_t cycle, DramOp op, uint64_t address, uint32_t bytes) {
    append_dram_trace(text, address, bytes, op, cycle, burst_bytes);
  };
  const SimResult sim = simulate_chip(model, orbit_camera(16, 10, 30.0, 25.0, 4.0, 50.0), cfg, opt);
  const std::vector<DramTraceRecord> records = parse_dram_trace(text, "frame");  // in time order, or it throws
  const StatsRegistry& s = *sim.stats;
  const uint64_t burst = cfg.memory.dram.burst_bytes();
  uint64_t read_bursts = 0, write_bursts = 0;
  for (const DramTraceRecord& r : records) {
    EXPECT_EQ(r.address % burst, 0u);
    (r.op == DramOp::kRead ? read_bursts : write_bursts) += 1;
  }
  // Every burst the DRAM model moved is in the trace, and nothing else.
  EXPECT_GT(read_bursts, 0u);
  EXPECT_GT(write_bursts, 0u);
  EXPECT_EQ(read_bursts, uint64_t(s.get("dram.read_bursts")));
  EXPECT_EQ(write_bursts, uint64_t(s.get("dram.write_bursts")));
  EXPECT_LE(records.back().cycle, uint64_t(s.get("dram.cycles")));
  // Replayed on its own, the trace moves the same bytes.
  StatsRegistry rs;
  DramSystem replay(cfg.memory.dram, rs);
  EXPECT_EQ(run_dram_workload(replay, trace_source(records)), records.size());
  replay.update_stats();
  EXPECT_EQ(rs.get("dram.read_bytes"), s.get("dram.read_bytes"));
  EXPECT_EQ(rs.get("dram.write_bytes"), s.get("dram.write_bytes"));
}

}  // namespace
}  // namespace edrnr::sim
