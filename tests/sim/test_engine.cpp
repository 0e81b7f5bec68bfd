// The cycle engine's parts: back-pressure between units, the memory system's
// clock crossing and address map, the activity recorder.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <stdexcept>

#include "chip/chip.h"
#include "core/error.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "sim/chrome_trace.h"
#include "sim/memory_system.h"
#include "sim/sim_config.h"
#include "sim/simulator.h"

namespace edrnr::sim {
namespace {

const std::filesystem::path kPreset = std::filesystem::path(EDRNR_SOURCE_DIR) / "configs/chip/edr_nr_40nm.yaml";
const std::filesystem::path kDram =
    std::filesystem::path(EDRNR_SOURCE_DIR) / "configs/dram/ddr3-1600-4gb-x16-16bit.yaml";

const SceneModel& model64() {
  static const SceneModel m = [] {
    ProceduralOptions o;
    o.micro_res = 64;
    return make_procedural_model("several", procedural_shapes("several"), o);
  }();
  return m;
}

TEST(Engine, ASlowTmeBackPressuresTheCfiu) {
  SimConfig c = load_sim_config(kPreset);
  // 800 MACs per sample at 64 per cycle: 13 cycles per sample.
  c.timing.tme_macs_per_cycle = 64;
  c.timing.cfiu_fifo_slots = 2;
  const Camera cam = orbit_camera(24, 24, 30.0, 25.0, 4.0, 50.0);
  const SimResult r = simulate_chip(model64(), cam, c);
  const StatsRegistry& s = *r.stats;
  ASSERT_GT(r.summary.samples, 100u);
  EXPECT_DOUBLE_EQ(r.summary.peak_samples_per_cycle, 1.0 / 13.0);
  EXPECT_GE(double(r.summary.cycles), 13.0 * double(r.summary.samples));
  // The queue between CFIU and TME fills up (latency 4 + 2 slots) and the
  // CFIU waits on it; the queue never holds more than its capacity.
  EXPECT_EQ(s.get("sim.fifo.cfiu_to_tme.capacity"), 6.0);
  EXPECT_EQ(s.get("sim.fifo.cfiu_to_tme.max_occupancy"), 6.0);
  EXPECT_GT(s.get("sim.fifo.cfiu_to_tme.full_cycles"), 0.0);
  EXPECT_GT(s.get("sim.unit.cfiu.stall_output_cycles"), 0.0);
  // The TME works 13 cycles per sample, so it is busy for at least that.
  EXPECT_GE(s.get("sim.unit.tme.busy_cycles"), 13.0 * double(r.summary.samples));
  // Still the functional model's image.
  EXPECT_EQ(r.image.data, render_chip(model64(), cam, c.chip).data);
}

TEST(Engine, AFullRpBufferStallsTheFrontEnd) {
  SimConfig c = load_sim_config(kPreset);
  c.chip.rp_buffer_capacity = 2;
  const SimResult r = simulate_chip(model64(), orbit_camera(24, 24, 30.0, 25.0, 4.0, 50.0), c);
  EXPECT_EQ(r.chip.peak_rp_buffer, 2u);
  EXPECT_GT(r.stats->get("sim.unit.front_end.stall_output_cycles"), 0.0);
}

// A read of 64 bytes (4 bursts of 16 bytes on the 16-bit bus) to a closed
// bank of an idle DDR3-1600: ACT, then RD after tRCD, data CL + tBURST later,
// the 3 further RDs tCCD apart: tRCD + CL + tBURST + 3 tCCD = 38 DRAM cycles
// of 1.25 ns. The core sees it at the first of its cycles that ends after the
// DRAM's 38th: a faster core waits more of its own cycles.
TEST(MemorySystem, ReadLatencyFollowsTheClockRatio) {
  const DramConfig dram = load_dram_config(kDram);
  ASSERT_EQ(dram.tRCD + dram.CL + dram.burst_cycles() + 3 * dram.tCCD, 38u);
  AddressMap map;
  map.bytes = {4096, 0, 0, 0, 0};
  for (auto [mhz, expected] : {std::pair{200.0, 10u}, {400.0, 19u}, {800.0, 38u}, {1000.0, 48u}}) {
    StatsRegistry stats;
    MemorySystem mem(dram, mhz, 64, map, stats);
    mem.read(DataType::Bitmaps, 0, 64, 7, 0);
    std::vector<MemoryCompletion> done;
    uint64_t cycle = 0;
    for (; done.empty(); ++cycle) mem.advance(cycle, done);
    ASSERT_EQ(done.size(), 1u);
    EXPECT_EQ(done[0].tag, 7u);
    EXPECT_EQ(cycle, expected) << mhz << " MHz";  // usable from this cycle on
    EXPECT_TRUE(mem.idle());
    EXPECT_EQ(stats.get("mem.bitmaps.read_bytes"), 64.0);
    EXPECT_EQ(stats.get("dram.read_bytes"), 64.0);
  }
}

// With nothing in flight advance() leaves the DRAM's clocks for later; they
// run before the next transfer starts, so the DRAM it meets has ticked
// floor(c f_dram / f_core) times (800 MHz against 380 MHz) and refreshed on
// schedule, as if every cycle had been run.
TEST(MemorySystem, IdleClocksRunBeforeTheNextTransfer) {
  const DramConfig dram = load_dram_config(kDram);
  ASSERT_TRUE(dram.refresh);
  AddressMap map;
  map.bytes = {4096, 0, 0, 0, 0};
  StatsRegistry stats;
  MemorySystem mem(dram, 380.0, 64, map, stats);
  std::vector<uint64_t> offered;
  mem.set_request_observer([&](uint64_t dram_cycle, DramOp, uint64_t, uint32_t) { offered.push_back(dram_cycle); });
  std::vector<MemoryCompletion> done;
  const uint64_t idle_cycles = 100000;
  for (uint64_t c = 0; c < idle_cycles; ++c) mem.advance(c, done);
  EXPECT_THROW(static_cast<const MemorySystem&>(mem).dram(), std::logic_error);  // its clocks are still to run
  mem.read(DataType::Bitmaps, 0, 64, 1, idle_cycles);
  ASSERT_EQ(offered.size(), 1u);
  const uint64_t dram_hz = uint64_t(std::llround(1e9 / dram.tCK_ns));
  EXPECT_EQ(offered[0], idle_cycles * dram_hz / 380000000u);  // the DRAM as the core cycle before ended
  for (uint64_t c = idle_cycles; done.empty(); ++c) mem.advance(c, done);
  for (uint64_t c = 0; c < idle_cycles; ++c) mem.advance(2 * idle_cycles + c, done);
  mem.sync();
  const uint64_t ticks = 3 * idle_cycles * dram_hz / 380000000u;
  EXPECT_EQ(static_cast<const MemorySystem&>(mem).dram().cycle(), ticks);
  EXPECT_EQ(stats.get("dram.cmd_refresh"), double(ticks / dram.tREFI));  // one per tREFI
}

// advance_through() over many cycles gives the completions of advance() cycle
// by cycle, each in its cycle, and stops at the first.
TEST(MemorySystem, AdvanceThroughStopsAtEachCompletion) {
  const DramConfig dram = load_dram_config(kDram);
  AddressMap map;
  map.bytes = {1 << 20, 0, 0, 0, 0};
  std::vector<std::pair<uint64_t, uint64_t>> by_cycle, through;  // (cycle, tag)
  StatsRegistry stats_a, stats_b;
  MemorySystem a(dram, 380.0, 64, map, stats_a), b(dram, 380.0, 64, map, stats_b);
  for (MemorySystem* m : {&a, &b}) {
    m->read(DataType::Bitmaps, 0, 640, 1, 0);
    m->read(DataType::Bitmaps, 300000, 64, 2, 0);  // another row
    m->write(DataType::Bitmaps, 700000, 64, 0);
    m->read(DataType::Bitmaps, 4096, 128, 3, 0);
  }
  std::vector<MemoryCompletion> done;
  a.advance(0, done);
  b.advance(0, done);
  ASSERT_TRUE(done.empty());
  for (uint64_t c = 1; !a.idle(); ++c) {
    a.advance(c, done);
    for (const MemoryCompletion& m : done) by_cycle.push_back({c, m.tag});
    done.clear();
  }
  uint64_t stops = 0;
  for (uint64_t c = 1; !b.idle(); ++c, ++stops) {
    c = b.advance_through(c, c + 1000000, done);
    for (const MemoryCompletion& m : done) through.push_back({c, m.tag});
    done.clear();
  }
  ASSERT_EQ(by_cycle.size(), 3u);
  EXPECT_EQ(through, by_cycle);
  EXPECT_EQ(stops, 4u);  // three reads and the write, each ending a call
  a.sync();
  b.sync();
  EXPECT_EQ(static_cast<const MemorySystem&>(a).dram().cycle(), static_cast<const MemorySystem&>(b).dram().cycle());
  EXPECT_EQ(stats_a.get("dram.active_rank_cycles"), stats_b.get("dram.active_rank_cycles"));
}

TEST(MemorySystem, SplitsTransfersAndCountsUniqueBytes) {
  const DramConfig dram = load_dram_config(kDram);
  AddressMap map;
  map.base = {0, 4096, 8192, 12288, 16384};
  map.bytes = {4096, 4096, 4096, 4096, 4096};
  StatsRegistry stats;
  MemorySystem mem(dram, 400, 64, map, stats);
  mem.read(DataType::Features, 8192, 1000, 1, 0);  // 16 requests
  mem.read(DataType::Features, 8192 + 512, 64, 2, 0);
  mem.write(DataType::RpOutput, 16384, 16, 0);
  std::vector<MemoryCompletion> done;
  for (uint64_t c = 0; !mem.idle() && c < 100000; ++c) mem.advance(c, done);
  ASSERT_TRUE(mem.idle());
  ASSERT_EQ(done.size(), 2u);
  EXPECT_EQ(stats.get("mem.features.reads"), 2.0);
  EXPECT_EQ(mem.read_bytes(DataType::Features), 1064u);
  EXPECT_EQ(mem.unique_read_bytes(DataType::Features), 1000u);  // the second read lies inside the first
  EXPECT_EQ(mem.write_bytes(DataType::RpOutput), 16u);
  EXPECT_EQ(stats.get("dram.writes"), 1.0);
  EXPECT_EQ(stats.get("dram.reads"), 17.0);
}

TEST(MemorySystem, RejectsRequestsTheQueueCannotHold) {
  const DramConfig dram = load_dram_config(kDram);  // 64-burst queue, 16-byte bursts
  StatsRegistry stats;
  EXPECT_THROW(MemorySystem(dram, 380, 4096, AddressMap{}, stats), Error);
  StatsRegistry stats2;
  EXPECT_THROW(MemorySystem(dram, 0, 64, AddressMap{}, stats2), Error);
}

TEST(AddressMap, RegionsFollowTheModelsFootprint) {
  const SceneModel& m = model64();
  const AddressMap a = make_address_map(m, 4128, 64, 100, 16, uint64_t(1) << 29);
  EXPECT_EQ(a.bitmap_bytes, 1u + 16u * 16u * 16u / 8u);  // coarse 2^3 bits in one byte, fine 16^3 bits
  EXPECT_EQ(a.feature_block_bytes, 1000u);
  EXPECT_EQ(a.feature_stride_bytes, 1024u);
  EXPECT_EQ(a.mlp_stride_bytes, 4160u);  // 4128 rounded up to 64
  EXPECT_EQ(a.bytes[1], 8 * m.block_count());
  EXPECT_EQ(a.bytes[3], 4160 * m.mlp_count());
  EXPECT_EQ(a.bytes[4], 1600u);
  for (int t = 0; t < kDataTypes; ++t) {
    EXPECT_EQ(a.base[size_t(t)] % 4096, 0u);
    if (t > 0) {
      EXPECT_GE(a.base[size_t(t)], a.base[size_t(t - 1)] + a.bytes[size_t(t - 1)]);
    }
  }
  EXPECT_EQ(a.feature_block(3), a.base[2] + 3 * 1024);
  EXPECT_THROW(make_address_map(m, 4128, 64, 100, 16, 4096), Error);
}

TEST(ActivityRecorder, CountsStatesAndKeepsIntervalsInTheWindow) {
  ActivityRecorder rec({"a", "b"}, 2, 6);  // window: cycles 2..7
  const UnitState a[10] = {UnitState::Busy,        UnitState::Busy,        UnitState::Busy, UnitState::Idle,
                           UnitState::StallOutput, UnitState::StallOutput, UnitState::Busy, UnitState::Busy,
                           UnitState::Busy,        UnitState::StallMemory};
  for (uint64_t c = 0; c < 10; ++c) {
    rec.set(0, a[c], c);
    rec.set(1, UnitState::Idle, c);
  }
  rec.finish();
  EXPECT_EQ(rec.cycles(0, UnitState::Busy), 6u);
  EXPECT_EQ(rec.cycles(0, UnitState::StallOutput), 2u);
  EXPECT_EQ(rec.cycles(0, UnitState::StallMemory), 1u);
  EXPECT_EQ(rec.cycles(0, UnitState::Idle), 1u);
  EXPECT_EQ(rec.cycles(1, UnitState::Idle), 10u);
  // Busy 0-2 clipped to 2-2, stall 4-5, busy 6-8 clipped to 6-7; idle is not kept.
  ASSERT_EQ(rec.intervals().size(), 3u);
  EXPECT_EQ(rec.intervals()[0].start_cycle, 2u);
  EXPECT_EQ(rec.intervals()[0].cycles, 1u);
  EXPECT_EQ(rec.intervals()[1].state, UnitState::StallOutput);
  EXPECT_EQ(rec.intervals()[1].start_cycle, 4u);
  EXPECT_EQ(rec.intervals()[1].cycles, 2u);
  EXPECT_EQ(rec.intervals()[2].start_cycle, 6u);
  EXPECT_EQ(rec.intervals()[2].cycles, 2u);
  const nlohmann::json t = rec.chrome_trace(500.0);  // 2 ns per cycle
  int x = 0;
  for (const auto& e : t["traceEvents"])
    if (e["ph"] == "X" && e["args"]["start_cycle"] == 4) {
      EXPECT_DOUBLE_EQ(double(e["ts"]), 0.008);
      EXPECT_DOUBLE_EQ(double(e["dur"]), 0.004);
      EXPECT_EQ(e["name"], "stall_output");
      ++x;
    }
  EXPECT_EQ(x, 1);
}

TEST(ActivityRecorder, DropsEventsPastTheLimit) {
  ActivityRecorder rec({"a"}, 0, 100, 2);
  for (uint64_t c = 0; c < 10; ++c) rec.set(0, c % 2 ? UnitState::Busy : UnitState::StallMemory, c);
  rec.finish();
  EXPECT_EQ(rec.intervals().size(), 2u);
  EXPECT_EQ(rec.dropped_events(), 8u);
}

}  // namespace
}  // namespace edrnr::sim
