// The cycle simulator end to end: the image against the functional model,
// statistics invariants, determinism, frame rate against the core clock,
// configuration round trips.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>

#include "chip/chip.h"
#include "core/error.h"
#include "model/footprint.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "sim/memory_system.h"
#include "sim/sim_config.h"
#include "sim/simulator.h"

namespace edrnr::sim {
namespace {

const std::filesystem::path kPreset = std::filesystem::path(EDRNR_SOURCE_DIR) / "configs/chip/edr_nr_40nm.yaml";

const SceneModel& several(int micro_res) {
  static const SceneModel m32 = [] {
    ProceduralOptions o;
    o.micro_res = 32;
    o.seed = 3;
    return make_procedural_model("several", procedural_shapes("several"), o);
  }();
  static const SceneModel m64 = [] {
    ProceduralOptions o;
    o.micro_res = 64;
    o.seed = 7;
    return make_procedural_model("several", procedural_shapes("several"), o);
  }();
  return micro_res == 32 ? m32 : m64;
}

const SimConfig& preset() {
  static const SimConfig c = load_sim_config(kPreset);
  return c;
}

Camera camera(int w, int h, double azimuth = 30.0) { return orbit_camera(w, h, azimuth, 25.0, 4.0, 50.0); }

bool same_bits(const Image& a, const Image& b) {
  return a.width == b.width && a.height == b.height && a.channels == b.channels && a.data == b.data;
}

TEST(Simulator, ImageIsBitIdenticalToTheFunctionalModel) {
  for (int res : {32, 64}) {
    const SceneModel& m = several(res);
    for (double azimuth : {30.0, 200.0}) {
      const Camera cam = camera(27, 21, azimuth);  // odd sizes: partial quads
      const Image functional = render_chip(m, cam, preset().chip);
      for (int threads : {1, 2}) {
        SimOptions opt;
        opt.threads = threads;
        const SimResult r = simulate_chip(m, cam, preset(), opt);
        EXPECT_TRUE(same_bits(r.image, functional))
            << "micro_res " << res << " azimuth " << azimuth << " threads " << threads;
      }
    }
  }
}

TEST(Simulator, SwitchesAndTinyBuffersKeepTheImage) {
  const SceneModel& m = several(64);
  const Camera cam = camera(23, 17);
  const Image functional = render_chip(m, cam, preset().chip);
  std::vector<std::pair<const char*, SimConfig>> variants;
  auto add = [&](const char* name, auto edit) {
    SimConfig c = preset();
    edit(c);
    variants.push_back({name, c});
  };
  add("everything off", [](SimConfig& c) {
    c.chip.switches = {false, false, false, false, false};
    c.chip.bank_mapping = chip::BankMapping::Linear;
  });
  add("tiny buffers", [](SimConfig& c) {
    c.chip.rp_buffer_capacity = 3;
    c.chip.rp_rob = {.entries = 2, .entry_depth = 1, .recent_tags = 1};
    c.chip.ooo_queue_depth = 2;
    c.chip.feature_cache_bytes = 8000;  // 8 blocks
    c.chip.mshr_entries = 1;
    c.memory.micro_grid_cache = {8, 1, Replacement::Fifo, 1, 1, 1};  // one word per line, direct mapped
    c.chip.micro_grid_cache_bytes = 64;
    c.memory.mlp_cache.mshr_entries = 1;
    c.timing.cfiu_fifo_slots = 1;
    c.timing.tme_fifo_slots = 1;
  });
  add("slow everything", [](SimConfig& c) {
    c.timing.tme_macs_per_cycle = 100;
    c.timing.cfiu_cycles_per_sample = 3;
    c.timing.vru_cycles_per_sample = 2;
    c.timing.ctu_cycles_per_iteration = 5;
    c.timing.ftu_lanes = 1;
    c.clock_MHz = 2000;
  });
  for (const auto& [name, cfg] : variants) {
    const SimResult r = simulate_chip(m, cam, cfg);
    EXPECT_TRUE(same_bits(r.image, functional)) << name;
  }
}

TEST(Simulator, SameInputSameBits) {
  const SceneModel& m = several(64);
  const Camera cam = camera(32, 32);
  SimOptions a, b;
  b.threads = 2;
  const SimResult r1 = simulate_chip(m, cam, preset(), a);
  const SimResult r2 = simulate_chip(m, cam, preset(), a);
  const SimResult r3 = simulate_chip(m, cam, preset(), b);
  EXPECT_EQ(r1.stats->to_json(), r2.stats->to_json());
  EXPECT_EQ(r1.stats->to_json(), r3.stats->to_json());  // the worker thread changes nothing
  EXPECT_TRUE(same_bits(r1.image, r3.image));
  EXPECT_EQ(r1.hit_rate_series, r3.hit_rate_series);
}

TEST(Simulator, StatisticsObeyTheirInvariants) {
  const SceneModel& m = several(64);
  const Camera cam = camera(40, 36);
  const SimResult r = simulate_chip(m, cam, preset());
  const StatsRegistry& s = *r.stats;
  const ChipCounters& c = r.chip;
  ASSERT_GT(c.ftu.samples, 0u);

  // Every sample generated is interpolated, evaluated and composited (or
  // skipped for a stopped ray) exactly once.
  EXPECT_EQ(c.cfiu.samples, c.ftu.samples);
  EXPECT_EQ(c.tme.samples, c.ftu.samples);
  EXPECT_EQ(c.vru.samples + c.vru.samples_skipped, c.ftu.samples);
  EXPECT_EQ(r.summary.samples, c.ftu.samples);
  EXPECT_EQ(c.cfiu.corner_reads, 8 * c.ftu.samples);
  EXPECT_EQ(c.ooo.issued, c.ftu.batches);

  // Every pixel's RP went through: ceil(W/2) * ceil(H/2) Z-order packets.
  EXPECT_EQ(c.packets, uint64_t(20 * 18));
  EXPECT_EQ(c.rps_finished + c.packets_dropped, c.packets);

  // Bytes read cover at least the distinct bytes touched, which lie inside
  // the model's footprint.
  const DramFootprint fp = dram_footprint(m);
  for (const char* type : {"micro_grid", "features", "mlp_weights", "bitmaps"}) {
    const std::string p = std::string("mem.") + type;
    EXPECT_GE(s.get(p + ".read_bytes"), s.get(p + ".unique_read_bytes")) << type;
  }
  EXPECT_LE(s.get("mem.features.unique_read_bytes"), double(fp.feature_bytes));
  EXPECT_LE(s.get("mem.micro_grid.unique_read_bytes"), double(fp.micro_grid_bytes + 64));
  EXPECT_EQ(s.get("mem.bitmaps.read_bytes"), double(fp.coarse_bitmap_bytes + fp.fine_bitmap_bytes));
  // One feature block (125 vertices x 16 INT4 channels = 1000 bytes) per fetch.
  EXPECT_EQ(s.get("mem.features.read_bytes"), 1000.0 * s.get("cache.features.misses_issued"));
  // The DRAM moves whole bursts: at least what was asked for.
  double asked = 0;
  for (const char* type : {"bitmaps", "micro_grid", "features", "mlp_weights"})
    asked += s.get(std::string("mem.") + type + ".read_bytes");
  EXPECT_GE(s.get("dram.read_bytes"), asked);
  // The output records go to the host, not to DRAM (the preset); with
  // write_output, one 16-byte record per RP is written.
  EXPECT_EQ(s.get("mem.rp_output.write_bytes"), 0.0);
  SimConfig frame_buffer = preset();
  frame_buffer.memory.write_output = true;
  const SimResult fb = simulate_chip(m, cam, frame_buffer);
  EXPECT_EQ(fb.stats->get("mem.rp_output.write_bytes"), 16.0 * double(c.packets));
  EXPECT_EQ(fb.image.data, r.image.data);

  // Hits and misses add up, per cache.
  EXPECT_EQ(s.get("cache.mlp.batches"), double(c.ftu.batches));
  // A batch misses its MLP only at a switch, and then at least one line comes from DRAM.
  const double mlp_misses = s.get("cache.mlp.batches") - s.get("cache.mlp.batch_hits");
  EXPECT_LE(mlp_misses, s.get("sim.mlp_switches"));
  EXPECT_GE(s.get("cache.mlp_weights.misses"), mlp_misses);
  for (const char* cache : {"cache.micro_grid", "cache.mlp_weights", "cache.features"}) {
    const std::string p = cache;
    EXPECT_EQ(s.get(p + ".hits") + s.get(p + ".misses"), s.get(p + ".accesses")) << cache;
  }
  // Per access (per sample): every sample is one access, and a batch adds at
  // most one miss, so the per-access rate is at least the per-batch one.
  for (const char* cache : {"features", "mlp"}) {
    const std::string p = std::string("cache.") + cache + ".per_access.";
    EXPECT_EQ(s.get(p + "hits") + s.get(p + "misses"), s.get(p + "accesses")) << cache;
    EXPECT_EQ(s.get(p + "accesses"), double(c.ftu.samples)) << cache;
  }
  EXPECT_EQ(s.get("cache.features.per_access.misses"), s.get("cache.features.misses"));
  EXPECT_EQ(s.get("cache.mlp.per_access.misses"), s.get("cache.mlp.batches") - s.get("cache.mlp.batch_hits"));
  EXPECT_GE(r.summary.feature_hit_rate_per_access, r.summary.feature_hit_rate);
  EXPECT_GE(r.summary.mlp_hit_rate_per_access, r.summary.mlp_hit_rate);
  EXPECT_EQ(s.get("cache.micro_grid.accesses"), double(c.ftu.micro_word_reads));
  EXPECT_EQ(s.get("cache.features.accesses"), double(c.ftu.batches));

  // No faster than the slowest sample stage allows.
  EXPECT_GE(double(r.summary.cycles), double(r.summary.samples) / r.summary.peak_samples_per_cycle);
  EXPECT_LE(r.summary.samples_per_cycle, r.summary.peak_samples_per_cycle);

  // Each unit is in exactly one state per cycle.
  for (const char* unit : {"front_end", "ctu", "ftu", "ooo_si", "cfiu", "tme", "vru"}) {
    double sum = 0;
    for (const char* st : {"busy", "stall_output", "stall_memory", "idle"})
      sum += s.get(std::string("sim.unit.") + unit + "." + st + "_cycles");
    EXPECT_EQ(sum, double(r.summary.cycles)) << unit;
  }
  // The VRU is busy exactly one cycle per sample (vru.cycles_per_sample = 1).
  EXPECT_EQ(s.get("sim.unit.vru.busy_cycles"), double(c.ftu.samples));
  EXPECT_DOUBLE_EQ(r.summary.fps, 380e6 / double(r.summary.cycles));

  // Energy events: 800 MACs per sample for the default MLP (density net
  // 16x16 + 16x8, colour net 23x16 + 16x3), 8 bank reads per sample.
  EXPECT_EQ(r.energy_run.event_counts.at("int8_mult"), 800 * c.ftu.samples);
  EXPECT_EQ(r.energy_run.event_counts.at("feature_sram_read"), 8 * c.ftu.samples);
  const char* dram_event = preset().energy.dram == DramEnergySource::Events ? "dram_bit" : "dram_io_bit";
  EXPECT_EQ(r.energy_run.event_counts.at(dram_event),
            8 * uint64_t(s.get("dram.read_bytes") + s.get("dram.write_bytes")));
  ASSERT_TRUE(r.energy.has_value());
  EXPECT_DOUBLE_EQ(r.energy->point.voltage_V, 1.21);
  EXPECT_GT(r.energy->nJ_per_pixel, 0.0);
}

TEST(SramBudget, EveryBufferIsCountedAndOneByteOverIsRefused) {
  const SimConfig& cfg = preset();
  const SramBudget b = compute_sram_budget(cfg, {256, 16, 1216});
  // The three caches are their configured sizes; the bitmaps are Rc^3 and Rf^3 bits.
  auto bytes = [&](const std::string& name) {
    for (const SramBuffer& x : b.buffers)
      if (x.name == name) return x.bytes;
    ADD_FAILURE() << "no buffer " << name;
    return uint64_t(0);
  };
  EXPECT_EQ(bytes("micro_grid_cache"), uint64_t(cfg.chip.micro_grid_cache_bytes));
  EXPECT_EQ(bytes("mlp_cache"), uint64_t(cfg.chip.mlp_cache_bytes));
  EXPECT_EQ(bytes("feature_cache"), uint64_t(feature_cache_lines(cfg.chip, 16)) * 1000);
  EXPECT_EQ(bytes("coarse_bitmap"), 64u);   // 8^3 bits
  EXPECT_EQ(bytes("fine_bitmap"), 32768u);  // 64^3 bits
  EXPECT_EQ(bytes("tme_weights"), 1216u);   // the MLP in the MAC array
  uint64_t others = 0, total = 0;
  for (const SramBuffer& x : b.buffers) {
    total += x.bytes;
    if (x.sram_class == SramClass::Others) others += x.bytes;
  }
  EXPECT_EQ(b.class_bytes[int(SramClass::Others)], others);
  EXPECT_EQ(b.total_bytes(), total);
  // The RP buffer grows by whole RPs.
  SimConfig bigger = cfg;
  bigger.chip.rp_buffer_capacity = cfg.chip.rp_buffer_capacity * 2;
  const SramBudget b2 = compute_sram_budget(bigger, {256, 16, 1216});
  uint64_t rp2 = 0;
  for (const SramBuffer& x : b2.buffers)
    if (x.name == "rp_buffer") rp2 = x.bytes;
  EXPECT_GE(rp2, 2 * bytes("rp_buffer"));

  // The preset fits; a budget one byte short of the need is refused, naming
  // the class, the overrun and the largest buffer.
  EXPECT_FALSE(b.over_budget()) << b.format();
  SimConfig tight = cfg;
  tight.sram_budget.others_bytes = others - 1;
  const SramBudget over = compute_sram_budget(tight, {256, 16, 1216});
  ASSERT_TRUE(over.over_budget());
  ASSERT_EQ(over.violations().size(), 1u);
  const std::string v = over.violations()[0];
  EXPECT_NE(v.find("'others'"), std::string::npos) << v;
  EXPECT_NE(v.find("1 over"), std::string::npos) << v;
  EXPECT_NE(v.find("fine_bitmap"), std::string::npos) << v;
  EXPECT_EQ(over.to_json()["over_budget"], true);
}

TEST(Simulator, FrameRateRisesWithTheClockButSubLinearlyWhenMemoryWaits) {
  const SceneModel& m = several(64);
  const Camera cam = camera(32, 32);
  double last_fps = 0;
  uint64_t last_cycles = 0;
  for (double mhz : {50.0, 150.0, 380.0, 1500.0}) {
    SimConfig c = preset();
    c.clock_MHz = mhz;
    const SimResult r = simulate_chip(m, cam, c);
    // Tag switches depend on timing (switch_when: idle), so on the memory-bound
    // plateau the frame rate may dip by a fraction of a percent; it never falls.
    EXPECT_GE(r.summary.fps, 0.99 * last_fps) << mhz << " MHz";
    // The DRAM keeps its own clock: the faster core waits more of its cycles.
    EXPECT_GE(r.summary.cycles, last_cycles) << mhz << " MHz";
    last_fps = r.summary.fps;
    last_cycles = r.summary.cycles;
  }
  SimConfig slow = preset(), fast = preset();
  slow.clock_MHz = 50;
  fast.clock_MHz = 1500;
  const double f50 = simulate_chip(m, cam, slow).summary.fps, f1500 = simulate_chip(m, cam, fast).summary.fps;
  EXPECT_LT(f1500 / f50, 1500.0 / 50.0);
  EXPECT_GT(f1500, 1.2 * f50);
}

TEST(Simulator, ProgressReachesEveryPacket) {
  const SceneModel& m = several(32);
  SimOptions opt;
  opt.progress_interval_cycles = 100;
  std::vector<SimProgress> seen;
  opt.progress = [&](const SimProgress& p) { seen.push_back(p); };
  const SimResult r = simulate_chip(m, camera(16, 10), preset(), opt);
  ASSERT_GE(seen.size(), 2u);
  for (size_t i = 1; i < seen.size(); ++i) EXPECT_GE(seen[i].rps_done, seen[i - 1].rps_done);
  EXPECT_EQ(seen.back().rps_total, 8u * 5u);
  EXPECT_EQ(seen.back().rps_done, 8u * 5u);
  EXPECT_EQ(seen.back().cycle, r.summary.cycles);
}

TEST(Simulator, TraceCoversTheWindow) {
  SimOptions opt;
  opt.trace_start_cycle = 100;
  opt.trace_cycles = 400;
  const SimResult r = simulate_chip(several(32), camera(16, 16), preset(), opt);
  ASSERT_TRUE(r.trace.contains("traceEvents"));
  int complete = 0;
  for (const auto& e : r.trace["traceEvents"]) {
    if (e["ph"] != "X") continue;
    ++complete;
    const uint64_t start = e["args"]["start_cycle"], n = e["args"]["cycles"];
    EXPECT_GE(start, 100u);
    EXPECT_LE(start + n, 500u);
    EXPECT_DOUBLE_EQ(double(e["ts"]), double(start) / 380.0);
  }
  EXPECT_GT(complete, 0);
}

TEST(Simulator, RejectsBadInput) {
  SimOptions opt;
  opt.threads = 3;
  EXPECT_THROW(simulate_chip(several(32), camera(8, 8), preset(), opt), Error);
  SimConfig c = preset();
  c.timing.tme_macs_per_cycle = 0;
  try {
    simulate_chip(several(32), camera(8, 8), c);
    FAIL() << "expected an Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("tme.macs_per_cycle"), std::string::npos) << e.what();
  }
}

TEST(SimConfig, PresetRoundTripsThroughItsResolvedForm) {
  const SimConfig& a = preset();
  EXPECT_EQ(a.clock_MHz, 380.0);
  EXPECT_EQ(a.chip.feature_cache_bytes, 262144);
  EXPECT_EQ(a.memory.dram.bus_width_bits, 16u);
  EXPECT_EQ(a.operating_points.size(), 5u);
  YAML::Emitter e;
  e << sim_config_to_yaml(a);
  const SimConfig b = sim_config_from_yaml(YAML::Load(e.c_str()), "resolved", "", {});
  EXPECT_EQ(b.chip.rp_buffer_capacity, a.chip.rp_buffer_capacity);
  EXPECT_EQ(b.clock_MHz, a.clock_MHz);
  EXPECT_EQ(b.timing, a.timing);
  EXPECT_EQ(b.memory.micro_grid_cache, a.memory.micro_grid_cache);
  EXPECT_EQ(b.memory.mlp_cache, a.memory.mlp_cache);
  EXPECT_EQ(b.memory.dram.tRCD, a.memory.dram.tRCD);
  EXPECT_EQ(b.memory.dram.name, a.memory.dram.name);
  EXPECT_EQ(b.energy.events_csv, std::filesystem::absolute(a.energy.events_csv).lexically_normal());
  EXPECT_EQ(b.operating_points.back().voltage_V, 1.21);
  // The functional model reads the same preset (it skips the simulator section).
  EXPECT_EQ(load_chip_config(kPreset).ooo_queue_depth, a.chip.ooo_queue_depth);
}

TEST(SimConfig, ErrorsNameTheKey) {
  auto expect_error = [](const std::string& yaml, const std::string& needle) {
    try {
      sim_config_from_yaml(YAML::Load(yaml), "test.yaml", std::filesystem::path(EDRNR_SOURCE_DIR) / "configs/chip", {});
      FAIL() << "expected an Error for " << yaml;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  const std::string dram = "simulator: {memory: {dram: ddr3-1600-4gb-x16-16bit}, ";
  expect_error(dram + "timing: {tme: {macs: 3}}}", "test.yaml.simulator.timing.tme: unknown key 'macs'");
  expect_error(dram + "clock_MHz: fast}", "test.yaml.simulator.clock_MHz");
  expect_error(dram + "timing: {vru: {cycles_per_sample: 0}}}", "vru.cycles_per_sample");
  expect_error(dram + "energy: {dram: both}}", "'both' is not events, model or access");
  expect_error("simulator: {memory: {dram: no-such-part}}", "no-such-part");
  expect_error("simulator: {memory: {dram: {name: x}}}", "test.yaml.simulator.memory.dram");
}

TEST(SimConfig, AFunctionalPresetSimulatesWithThePapersDefaults) {
  const SimConfig d = load_sim_config(std::filesystem::path(EDRNR_SOURCE_DIR) / "configs/chip/default.yaml");
  const SimConfig& p = preset();
  EXPECT_EQ(d.timing, p.timing);
  EXPECT_EQ(d.clock_MHz, p.clock_MHz);
  EXPECT_EQ(d.memory.dram.name, p.memory.dram.name);
  EXPECT_EQ(d.memory.micro_grid_cache, p.memory.micro_grid_cache);
  EXPECT_EQ(d.memory.mlp_cache, p.memory.mlp_cache);
  EXPECT_EQ(d.energy.events_csv, p.energy.events_csv);
  EXPECT_EQ(d.energy.leakage_csv, p.energy.leakage_csv);
  EXPECT_EQ(d.operating_points.size(), p.operating_points.size());
  EXPECT_EQ(d.chip.rp_buffer_capacity, p.chip.rp_buffer_capacity);
}

TEST(SimConfig, VoltageComesFromTheNextOperatingPointUp) {
  const SimConfig& c = preset();
  bool extrapolated = true;
  EXPECT_DOUBLE_EQ(operating_point_at(c, 50, &extrapolated).voltage_V, 0.79);
  EXPECT_FALSE(extrapolated);
  EXPECT_DOUBLE_EQ(operating_point_at(c, 100, &extrapolated).voltage_V, 0.98);
  EXPECT_DOUBLE_EQ(operating_point_at(c, 100).frequency_MHz, 100.0);
  EXPECT_DOUBLE_EQ(operating_point_at(c, 380).voltage_V, 1.21);
  EXPECT_DOUBLE_EQ(operating_point_at(c, 500, &extrapolated).voltage_V, 1.21);
  EXPECT_TRUE(extrapolated);
}

}  // namespace
}  // namespace edrnr::sim
