// Timing, scheduling and energy of the DDR3 model, against values worked out
// by hand from the timing parameters. The base configuration is DRAMsim3's
// DDR3-1600 4Gb x16 part on a 64-bit bus, written out here so that the tests
// do not depend on the preset files: CL 11, CWL 8, tRCD 11, tRP 11, tRAS 28,
// tRC 39, tRRD 5, tFAW 32, tWR 12, tWTR 6, tRTP 6, tCCD 4, BL 8 (tBURST 4),
// tRFC 208, tREFI 6240.
//
// Address layout with the default mapping row:bank:rank:column:channel, one
// channel and one rank: 64-byte bursts, 128 bursts per row (bits 6..12), bank
// in bits 13..15, row from bit 16.
#include <gtest/gtest.h>

#include <array>
#include <tuple>

#include "core/error.h"
#include "sim/dram.h"
#include "sim/dram_trace.h"

namespace edrnr::sim {
namespace {

DramConfig ddr3_1600() {
  DramConfig c;
  c.name = "test DDR3-1600";
  c.source = "test";
  c.channels = 1;
  c.ranks = 1;
  c.banks = 8;
  c.rows = 32768;
  c.columns = 1024;
  c.device_width_bits = 16;
  c.bus_width_bits = 64;
  c.burst_length = 8;
  c.tCK_ns = 1.25;
  c.CL = 11;
  c.CWL = 8;
  c.tRCD = 11;
  c.tRP = 11;
  c.tRAS = 28;
  c.tRC = 39;
  c.tRRD = 5;
  c.tFAW = 32;
  c.tWR = 12;
  c.tWTR = 6;
  c.tRTP = 6;
  c.tCCD = 4;
  c.tRTRS = 1;
  c.tRFC = 208;
  c.tREFI = 6240;
  c.VDD_V = 1.35;
  c.IDD0_mA = 66;
  c.IDD2N_mA = 32;
  c.IDD3N_mA = 47;
  c.IDD4R_mA = 235;
  c.IDD4W_mA = 171;
  c.IDD5_mA = 235;
  c.io_pJ_per_bit = 0.0;
  c.queue_depth_bursts = 32;
  return c;
}

constexpr uint64_t kBank = 1u << 13;  // address step to the next bank
constexpr uint64_t kRow = 1u << 16;   // address step to the next row of the same bank

// Ticks until `count` requests have completed (or a generous limit passes) and
// returns the completions in order.
std::vector<DramCompletion> run_until(DramSystem& dram, size_t count, uint64_t limit = 100000) {
  std::vector<DramCompletion> done;
  for (uint64_t i = 0; i < limit && done.size() < count; ++i) {
    dram.tick();
    while (auto c = dram.pop_completion()) done.push_back(*c);
  }
  return done;
}

void tick_to(DramSystem& dram, uint64_t cycle) {
  while (dram.cycle() < cycle) dram.tick();
}

// Cycle of the n-th (0-based) logged command of the given kind, or UINT64_MAX.
uint64_t command_cycle(const DramSystem& dram, DramCommand kind, int n = 0) {
  for (const DramCommandRecord& r : dram.command_log()) {
    if (r.command == kind && n-- == 0) return r.cycle;
  }
  return UINT64_MAX;
}

TEST(Dram, AddressMappingSplitsFieldsAsConfigured) {
  StatsRegistry stats;
  DramSystem dram(ddr3_1600(), stats);
  DramLocation l = dram.locate(0x12345678);
  EXPECT_EQ(l.channel, 0u);
  EXPECT_EQ(l.rank, 0u);
  EXPECT_EQ(l.row, 0x1234u);   // bits 16..30
  EXPECT_EQ(l.bank, 2u);       // bits 13..15 of 0x5678 = 0b010
  EXPECT_EQ(l.column, 0x59u);  // bits 6..12 of 0x5678 = 0x159 & 0x7f
  EXPECT_EQ(dram.locate(kBank).bank, 1u);
  EXPECT_EQ(dram.locate(kRow).row, 1u);

  // channel:rank:row:bank:column with 2 channels and 2 ranks: column bits
  // 6..12, bank 13..15, row 16..30, rank 31, channel 32.
  DramConfig c = ddr3_1600();
  c.channels = 2;
  c.ranks = 2;
  c.address_mapping = parse_address_mapping("channel:rank:row:bank:column");
  StatsRegistry stats2;
  DramSystem dram2(c, stats2);
  DramLocation m =
      dram2.locate((uint64_t{1} << 32) | (uint64_t{1} << 31) | (uint64_t{5} << 16) | (3u << 13) | (7u << 6));
  EXPECT_EQ(m.channel, 1u);
  EXPECT_EQ(m.rank, 1u);
  EXPECT_EQ(m.row, 5u);
  EXPECT_EQ(m.bank, 3u);
  EXPECT_EQ(m.column, 7u);
  EXPECT_EQ(c.capacity_bytes(), uint64_t{8} << 30);
}

TEST(Dram, ReadToClosedBankTakesTrcdPlusClPlusBurst) {
  StatsRegistry stats;
  DramSystem dram(ddr3_1600(), stats);
  dram.enable_command_log(true);
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 0, 64, 7));
  auto done = run_until(dram, 1);
  ASSERT_EQ(done.size(), 1u);
  EXPECT_EQ(done[0].id, 7u);
  EXPECT_EQ(done[0].latency_cycles(), 11u + 11u + 4u);
  EXPECT_EQ(command_cycle(dram, DramCommand::kActivate), 0u);
  EXPECT_EQ(command_cycle(dram, DramCommand::kRead), 11u);
  EXPECT_EQ(stats.get("dram.row_misses"), 1.0);
  EXPECT_EQ(stats.get("dram.read_bytes"), 64.0);
}

TEST(Dram, WriteToClosedBankTakesTrcdPlusCwlPlusBurst) {
  StatsRegistry stats;
  DramSystem dram(ddr3_1600(), stats);
  ASSERT_TRUE(dram.enqueue(DramOp::kWrite, 5 * kRow, 64, 1));
  auto done = run_until(dram, 1);
  ASSERT_EQ(done.size(), 1u);
  EXPECT_EQ(done[0].op, DramOp::kWrite);
  EXPECT_EQ(done[0].latency_cycles(), 11u + 8u + 4u);
}

TEST(Dram, SecondReadToTheSameRowIsARowHitPipelinedByTccd) {
  StatsRegistry stats;
  DramSystem dram(ddr3_1600(), stats);
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 0, 64, 1));
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 64, 64, 2));
  auto done = run_until(dram, 2);
  ASSERT_EQ(done.size(), 2u);
  EXPECT_EQ(done[0].done_cycle, 26u);      // RD at 11
  EXPECT_EQ(done[1].done_cycle, 26u + 4);  // RD at 11 + tCCD
  EXPECT_EQ(stats.get("dram.row_hits"), 1.0);
  EXPECT_EQ(stats.get("dram.row_misses"), 1.0);

  // A later hit on the open row pays only CL + tBURST.
  tick_to(dram, 100);
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 128, 64, 3));
  done = run_until(dram, 1);
  ASSERT_EQ(done.size(), 1u);
  EXPECT_EQ(done[0].latency_cycles(), 11u + 4u);
  EXPECT_EQ(stats.get("dram.row_hits"), 2.0);
}

TEST(Dram, RowConflictPaysPrechargeAndActivate) {
  StatsRegistry stats;
  DramSystem dram(ddr3_1600(), stats);
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 0, 64, 1));
  run_until(dram, 1);
  tick_to(dram, 100);
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 3 * kRow, 64, 2));
  auto done = run_until(dram, 1);
  ASSERT_EQ(done.size(), 1u);
  EXPECT_EQ(done[0].latency_cycles(), 11u + 11u + 11u + 4u);  // tRP + tRCD + CL + tBURST
  EXPECT_EQ(stats.get("dram.row_conflicts"), 1.0);
  EXPECT_EQ(stats.get("dram.cmd_precharge"), 1.0);
}

TEST(Dram, ConflictWaitsForTrasFromTheActivate) {
  // Both at cycle 0: the first opens row 0 at 0 (RD at 11); the precharge for
  // the second waits for max(tRAS, 11 + tRTP) = 28, then ACT at 39, RD at 50.
  StatsRegistry stats;
  DramSystem dram(ddr3_1600(), stats);
  dram.enable_command_log(true);
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 0, 64, 1));
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, kRow, 64, 2));
  auto done = run_until(dram, 2);
  ASSERT_EQ(done.size(), 2u);
  EXPECT_EQ(command_cycle(dram, DramCommand::kPrecharge), 28u);
  EXPECT_EQ(command_cycle(dram, DramCommand::kActivate, 1), 39u);
  EXPECT_EQ(done[1].done_cycle, 39u + 26u);

  // With tRAS = 40 (tRC = 51) the precharge moves to 40 and the read to 51 + 26.
  DramConfig c = ddr3_1600();
  c.tRAS = 40;
  c.tRC = 51;
  StatsRegistry stats2;
  DramSystem slow(c, stats2);
  slow.enable_command_log(true);
  ASSERT_TRUE(slow.enqueue(DramOp::kRead, 0, 64, 1));
  ASSERT_TRUE(slow.enqueue(DramOp::kRead, kRow, 64, 2));
  done = run_until(slow, 2);
  ASSERT_EQ(done.size(), 2u);
  EXPECT_EQ(command_cycle(slow, DramCommand::kPrecharge), 40u);
  EXPECT_EQ(done[1].done_cycle, 51u + 26u);
}

TEST(Dram, FourActivateWindowDelaysTheFifthActivate) {
  // Five reads to five banks at cycle 0: ACTs at 0, 5, 10, 15 (tRRD), then
  // the fifth waits for tFAW after the first: 32. Its read ends at 32 + 26.
  StatsRegistry stats;
  DramSystem dram(ddr3_1600(), stats);
  dram.enable_command_log(true);
  for (uint64_t b = 0; b < 5; ++b) ASSERT_TRUE(dram.enqueue(DramOp::kRead, b * kBank, 64, b));
  auto done = run_until(dram, 5);
  ASSERT_EQ(done.size(), 5u);
  EXPECT_EQ(command_cycle(dram, DramCommand::kActivate, 0), 0u);
  EXPECT_EQ(command_cycle(dram, DramCommand::kActivate, 1), 5u);
  EXPECT_EQ(command_cycle(dram, DramCommand::kActivate, 2), 10u);
  EXPECT_EQ(command_cycle(dram, DramCommand::kActivate, 3), 15u);
  EXPECT_EQ(command_cycle(dram, DramCommand::kActivate, 4), 32u);
  EXPECT_EQ(done[3].done_cycle, 15u + 26u);
  EXPECT_EQ(done[4].done_cycle, 32u + 26u);

  // Without the window (tFAW <= 4 tRRD) the fifth ACT goes at 20.
  DramConfig c = ddr3_1600();
  c.tFAW = 20;
  StatsRegistry stats2;
  DramSystem free_dram(c, stats2);
  for (uint64_t b = 0; b < 5; ++b) ASSERT_TRUE(free_dram.enqueue(DramOp::kRead, b * kBank, 64, b));
  done = run_until(free_dram, 5);
  ASSERT_EQ(done.size(), 5u);
  EXPECT_EQ(done[4].done_cycle, 20u + 26u);
}

TEST(Dram, RefreshBlocksTheRankForTrfcEveryTrefi) {
  StatsRegistry stats;
  DramSystem dram(ddr3_1600(), stats);
  dram.enable_command_log(true);
  tick_to(dram, 6240);
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 0, 64, 1));
  auto done = run_until(dram, 1);
  ASSERT_EQ(done.size(), 1u);
  EXPECT_EQ(command_cycle(dram, DramCommand::kRefresh, 0), 6240u);
  EXPECT_EQ(done[0].latency_cycles(), 208u + 26u);  // waits out tRFC, then a closed-bank read

  // Refreshes keep coming every tREFI. The read left its row open (open-page
  // policy), so the second one first precharges at 2 tREFI and waits tRP.
  tick_to(dram, 3 * 6240 + 1);
  EXPECT_EQ(stats.get("dram.cmd_refresh"), 3.0);
  EXPECT_EQ(command_cycle(dram, DramCommand::kPrecharge, 0), 2u * 6240);
  EXPECT_EQ(command_cycle(dram, DramCommand::kRefresh, 1), 2u * 6240 + 11);
  EXPECT_EQ(command_cycle(dram, DramCommand::kRefresh, 2), 3u * 6240);
}

TEST(Dram, RefreshClosesAnOpenRowFirst) {
  // ACT at tREFI - 5; at tREFI the rank stops taking column commands, so the
  // row is precharged at ACT + tRAS = tREFI + 23, REF at + tRP = tREFI + 34,
  // and the read re-activates at tREFI + 34 + tRFC and ends 26 cycles later.
  StatsRegistry stats;
  DramSystem dram(ddr3_1600(), stats);
  dram.enable_command_log(true);
  tick_to(dram, 6240 - 5);
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 0, 64, 1));
  auto done = run_until(dram, 1);
  ASSERT_EQ(done.size(), 1u);
  EXPECT_EQ(command_cycle(dram, DramCommand::kPrecharge), 6240u + 23);
  EXPECT_EQ(command_cycle(dram, DramCommand::kRefresh), 6240u + 34);
  EXPECT_EQ(done[0].done_cycle, 6240u + 34 + 208 + 26);
}

TEST(Dram, FrFcfsServesAYoungerRowHitBeforeAnOlderMiss) {
  StatsRegistry stats;
  DramSystem dram(ddr3_1600(), stats);
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 0, 64, 1));  // opens row 0 of bank 0
  run_until(dram, 1);
  tick_to(dram, 100);
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 2 * kRow, 64, 10));  // older: conflict in bank 0
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 64, 64, 11));        // younger: hit on row 0
  auto done = run_until(dram, 2);
  ASSERT_EQ(done.size(), 2u);
  EXPECT_EQ(done[0].id, 11u);
  EXPECT_EQ(done[0].latency_cycles(), 15u);  // RD at 100
  EXPECT_EQ(done[1].id, 10u);
  // PRE at 100 + tRTP = 106, ACT at 117, RD at 128, data done at 143.
  EXPECT_EQ(done[1].done_cycle, 143u);
}

TEST(Dram, WriteReadTurnaroundsFollowTwtrAndReadToWriteDelay) {
  StatsRegistry stats;
  DramSystem dram(ddr3_1600(), stats);
  ASSERT_TRUE(dram.enqueue(DramOp::kWrite, 0, 64, 1));
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 64, 64, 2));
  auto done = run_until(dram, 2);
  ASSERT_EQ(done.size(), 2u);
  EXPECT_EQ(done[0].done_cycle, 11u + 8 + 4);           // WR at 11
  EXPECT_EQ(done[1].done_cycle, 11u + 8 + 4 + 6 + 15);  // RD at WR + CWL + tBURST + tWTR = 29

  StatsRegistry stats2;
  DramSystem dram2(ddr3_1600(), stats2);
  ASSERT_TRUE(dram2.enqueue(DramOp::kRead, 0, 64, 1));
  ASSERT_TRUE(dram2.enqueue(DramOp::kWrite, 64, 64, 2));
  done = run_until(dram2, 2);
  ASSERT_EQ(done.size(), 2u);
  EXPECT_EQ(done[0].done_cycle, 26u);
  EXPECT_EQ(done[1].done_cycle, 20u + 8 + 4);  // WR at RD + CL + tCCD + 2 - CWL = 11 + 9
}

TEST(Dram, ReadsToAnotherRankWaitForTheBusTurnaround) {
  DramConfig c = ddr3_1600();
  c.ranks = 2;  // rank bit sits between bank and column: bit 13; bank moves to 14..16
  StatsRegistry stats;
  DramSystem dram(c, stats);
  dram.enable_command_log(true);
  ASSERT_EQ(dram.locate(1u << 13).rank, 1u);
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 0, 64, 1));
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 1u << 13, 64, 2));
  auto done = run_until(dram, 2);
  ASSERT_EQ(done.size(), 2u);
  // ACTs at 0 and 1 (one command per cycle); RD rank 0 at 11; RD rank 1 at
  // max(1 + tRCD, 11 + tBURST + tRTRS) = 16.
  EXPECT_EQ(command_cycle(dram, DramCommand::kActivate, 1), 1u);
  EXPECT_EQ(command_cycle(dram, DramCommand::kRead, 1), 16u);
  EXPECT_EQ(done[1].done_cycle, 16u + 15);
}

TEST(Dram, MultiBurstRequestCompletesOnceAfterItsLastBurst) {
  StatsRegistry stats;
  DramSystem dram(ddr3_1600(), stats);
  // Bytes 32..287 touch bursts 0..4: RDs at 11, 15, 19, 23, 27.
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 32, 256, 5));
  auto done = run_until(dram, 2, 200);
  ASSERT_EQ(done.size(), 1u);
  EXPECT_EQ(done[0].bytes, 256u);
  EXPECT_EQ(done[0].done_cycle, 27u + 15);
  EXPECT_EQ(stats.get("dram.read_bursts"), 5.0);
  EXPECT_EQ(stats.get("dram.read_bytes"), 320.0);
  EXPECT_EQ(stats.get("dram.reads"), 1.0);
}

TEST(Dram, BoundedQueueGivesBackPressureAndRejectsImpossibleRequests) {
  StatsRegistry stats;
  DramSystem dram(ddr3_1600(), stats);
  int accepted = 0;
  for (uint64_t i = 0; i < 40; ++i) accepted += dram.enqueue(DramOp::kRead, i * 64, 64, i);
  EXPECT_EQ(accepted, 32);
  EXPECT_EQ(stats.get("dram.rejected_enqueues"), 8.0);
  EXPECT_FALSE(dram.can_accept(0, 64));
  dram.tick();  // nothing completes yet, the queue is still full
  EXPECT_FALSE(dram.can_accept(0, 64));
  auto done = run_until(dram, 32);
  EXPECT_EQ(done.size(), 32u);
  EXPECT_TRUE(dram.idle());
  EXPECT_TRUE(dram.can_accept(0, 32 * 64));
  EXPECT_FALSE(dram.can_accept(0, 32 * 64 + 1));  // 33 bursts never fit
  EXPECT_THROW(dram.enqueue(DramOp::kRead, 0, 33 * 64, 1), Error);
  EXPECT_THROW(dram.enqueue(DramOp::kRead, 0, 0, 1), Error);  // empty
  uint64_t cap = dram.config().capacity_bytes();
  EXPECT_THROW(dram.enqueue(DramOp::kRead, cap - 32, 64, 1), Error);  // runs past the end
  EXPECT_TRUE(dram.enqueue(DramOp::kRead, cap - 64, 64, 1));
}

TEST(Dram, SequentialStreamReachesNinetyPercentOfPeak) {
  for (uint32_t bus_bits : {64u, 16u}) {
    DramConfig c = ddr3_1600();
    c.bus_width_bits = bus_bits;
    StatsRegistry stats;
    DramSystem dram(c, stats);
    const uint64_t n = 40000;  // spans several refresh intervals
    EXPECT_EQ(run_dram_workload(dram, stream_source(c, n, 0.0, 1)), n);
    dram.update_stats();
    const double peak_GBps = 2.0 * (bus_bits / 8) / 1.25;  // two transfers per 1.25 ns clock
    EXPECT_DOUBLE_EQ(stats.get("dram.peak_bandwidth_GBps"), peak_GBps);
    double bw = stats.get("dram.bandwidth_GBps");
    EXPECT_GE(bw, 0.9 * peak_GBps) << bus_bits << "-bit bus";
    EXPECT_LE(bw, peak_GBps);
    EXPECT_EQ(stats.get("dram.reads"), static_cast<double>(n));
    EXPECT_GT(stats.get("dram.row_hit_rate"), 0.95);  // 128 bursts per row: 127 of 128 hit
  }
}

TEST(Dram, EnergyOfAKnownSequenceMatchesTheCurrentFormula) {
  // One read to a closed bank, then idle until cycle 100: one ACT, one RD,
  // and 100 cycles of active standby (the row stays open). Per rank of four
  // devices, in pJ: V * I(mA) * cycles * tCK(ns) * 4.
  StatsRegistry stats;
  DramSystem dram(ddr3_1600(), stats);
  ASSERT_TRUE(dram.enqueue(DramOp::kRead, 0, 64, 1));
  tick_to(dram, 100);
  const double k = 1.35 * 1.25 * 4;                            // pJ per mA-cycle, whole rank
  const double act = k * (66.0 * 39 - 47.0 * 28 - 32.0 * 11);  // 6115.5
  const double rd = k * (235.0 - 47) * 4;                      // 5076
  const double bg = k * 47.0 * 100;                            // 31725
  DramEnergy e = dram.energy();
  EXPECT_NEAR(e.activate_pJ, 6115.5, 1e-9);
  EXPECT_NEAR(e.read_pJ, 5076.0, 1e-9);
  EXPECT_NEAR(e.background_pJ, 31725.0, 1e-9);
  EXPECT_NEAR(e.total_pJ(), act + rd + bg, 1e-6);
  dram.update_stats();
  EXPECT_NEAR(stats.get("dram.energy_pJ"), 42916.5, 1e-6);
  EXPECT_NEAR(stats.get("dram.energy_per_bit_pJ"), 42916.5 / 512, 1e-9);

  // Idle with refresh: tREFI + tRFC + 10 cycles, one REF; the rank counts as
  // active while refreshing (tRFC cycles) and precharged otherwise.
  StatsRegistry stats2;
  DramSystem idle(ddr3_1600(), stats2);
  tick_to(idle, 6240 + 208 + 10);
  DramEnergy r = idle.energy();
  EXPECT_NEAR(r.refresh_pJ, k * (235.0 - 47) * 208, 1e-6);             // 263952
  EXPECT_NEAR(r.background_pJ, k * (47.0 * 208 + 32.0 * 6250), 1e-6);  // 1415988
  EXPECT_NEAR(r.total_pJ(), 263952.0 + 1415988.0, 1e-6);

  // A write and the flat I/O term: 64 bytes = 512 bits at 2 pJ/bit.
  DramConfig c = ddr3_1600();
  c.io_pJ_per_bit = 2.0;
  StatsRegistry stats3;
  DramSystem w(c, stats3);
  ASSERT_TRUE(w.enqueue(DramOp::kWrite, 0, 64, 1));
  run_until(w, 1);
  EXPECT_NEAR(w.energy().write_pJ, k * (171.0 - 47) * 4, 1e-9);  // 3348
  EXPECT_NEAR(w.energy().io_pJ, 1024.0, 1e-9);
}

TEST(Dram, SameWorkloadAndSeedGiveTheSameStatistics) {
  auto run = [](uint64_t seed) {
    DramConfig c = ddr3_1600();
    StatsRegistry stats;
    DramSystem dram(c, stats);
    run_dram_workload(dram, random_source(c, 3000, 0.3, seed));
    dram.update_stats();
    return stats.to_json().dump();
  };
  EXPECT_EQ(run(42), run(42));
  EXPECT_NE(run(42), run(43));
}

// advance_quiet() jumps over the cycles in which nothing can happen; the
// result must be that of ticking every cycle: the same completions at the
// same cycles, the same commands and the same statistics (energy included).
TEST(Dram, AdvanceQuietMatchesTickingEveryCycle) {
  for (uint32_t channels : {1u, 2u}) {
    DramConfig c = ddr3_1600();
    c.channels = channels;
    c.ranks = 2;
    c.tREFI = 900;  // several refreshes in the run
    struct Arrival {
      uint64_t cycle, address;
      uint32_t bytes;
      bool write;
    };
    std::vector<Arrival> arrivals;
    uint64_t x = 12345, t = 0;
    auto next = [&] { return x = x * 6364136223846793005ull + 1442695040888963407ull, x >> 33; };
    for (int i = 0; i < 400; ++i) {
      t += next() % 3 == 0 ? next() % 400 : next() % 8;  // bursts of requests and long pauses
      arrivals.push_back(
          {t, (next() % (c.capacity_bytes() / 64 - 64)) * 64, uint32_t(64 * (1 + next() % 4)), next() % 4 == 0});
    }
    auto run = [&](bool quiet) {
      StatsRegistry stats;
      DramSystem dram(c, stats);
      dram.enable_command_log(true);
      std::vector<std::array<uint64_t, 3>> done;  // id, done cycle, cycle handed out
      auto drain = [&] {
        while (auto d = dram.pop_completion()) done.push_back({d->id, d->done_cycle, dram.cycle()});
      };
      size_t i = 0;
      uint64_t y = 99;  // the same steps for both runs
      while (i < arrivals.size() || !dram.idle()) {
        // Short steps, so that a completion handed out a cycle late shows.
        y = y * 6364136223846793005ull + 1442695040888963407ull;
        uint64_t target = dram.cycle() + 1 + (y >> 33) % 16;
        if (i < arrivals.size()) target = std::min(target, std::max(arrivals[i].cycle, dram.cycle() + 1));
        if (quiet) {
          dram.advance_quiet(target);
        } else {
          while (dram.cycle() < target) dram.tick();
        }
        drain();
        // Requests arrive at their cycle; one refused waits a cycle.
        while (i < arrivals.size() && arrivals[i].cycle <= dram.cycle()) {
          const Arrival& a = arrivals[i];
          if (!dram.enqueue(a.write ? DramOp::kWrite : DramOp::kRead, a.address, a.bytes, i)) {
            ++arrivals[i].cycle;
            break;
          }
          ++i;
        }
      }
      dram.update_stats();
      std::vector<uint64_t> log;
      for (const DramCommandRecord& r : dram.command_log()) log.push_back(r.cycle * 8 + uint64_t(r.command));
      return std::make_tuple(done, log, stats.to_json().dump());
    };
    const auto [done_a, log_a, stats_a] = run(false);
    const auto [done_b, log_b, stats_b] = run(true);
    ASSERT_EQ(done_a.size(), arrivals.size());
    ASSERT_EQ(done_a.size(), done_b.size());
    EXPECT_EQ(done_a, done_b);
    EXPECT_EQ(log_a, log_b);
    EXPECT_EQ(stats_a, stats_b);
  }
}

}  // namespace
}  // namespace edrnr::sim
