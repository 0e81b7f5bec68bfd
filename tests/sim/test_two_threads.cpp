// The simulator's shortcuts give the results of the plain cycle-by-cycle run,
// with buffers and queues of every size: the second thread (batch arithmetic
// and front-end packets built ahead on the worker) and the skipping of cycles
// in which no unit can act give the same packets, statistics, hit-rate
// series, unit trace and image as one thread stepping every cycle.
#include <gtest/gtest.h>

#include <filesystem>
#include <thread>
#include <vector>

#include "chip/chip_ray.h"
#include "chip/front_end.h"
#include "chip/vru.h"
#include "chip/zorg.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "sim/batch_worker.h"
#include "sim/sim_config.h"
#include "sim/simulator.h"

namespace edrnr::sim {
namespace {

const std::filesystem::path kPreset = std::filesystem::path(EDRNR_SOURCE_DIR) / "configs/chip/edr_nr_40nm.yaml";

const SceneModel& scene() {
  static const SceneModel m = [] {
    ProceduralOptions o;
    o.micro_res = 64;
    o.seed = 11;
    return make_procedural_model("several", procedural_shapes("several"), o);
  }();
  return m;
}

const SimConfig& preset() {
  static const SimConfig c = load_sim_config(kPreset);
  return c;
}

// Every statistic but the host's timings.
nlohmann::json chip_stats(const SimResult& r) {
  nlohmann::json stats = r.stats->to_json();
  for (auto it = stats.begin(); it != stats.end();)
    it = it.key().rfind("host.", 0) == 0 ? stats.erase(it) : std::next(it);
  return stats;
}

void expect_same_rays(const chip::RayPacket& a, const chip::RayPacket& b) {
  EXPECT_EQ(a.pixels.sequence, b.pixels.sequence);
  EXPECT_EQ(a.pixels.valid_mask, b.pixels.valid_mask);
  EXPECT_EQ(a.travel_sign, b.travel_sign);
  for (size_t r = 0; r < a.rays.size(); ++r) {
    const chip::RayState &x = a.rays[r], &y = b.rays[r];
    EXPECT_EQ(x.valid, y.valid);
    EXPECT_EQ(x.k, y.k);
    EXPECT_EQ(x.k_end, y.k_end);
    EXPECT_EQ(x.ray.origin, y.ray.origin);
    EXPECT_EQ(x.ray.dir, y.ray.dir);
    EXPECT_EQ(x.transmittance, y.transmittance);
  }
}

// The packets FrontEndAhead builds ahead, through a ring smaller than the
// frame so that it wraps many times, are those the front end builds when
// asked quad by quad in ZORG order, with the same TSPS evaluations each.
TEST(Shortcuts, FrontEndPacketsBuiltAheadMatchThoseBuiltInOrder) {
  const SceneModel& m = scene();
  const SimConfig& cfg = preset();
  const ChipNumerics& n = cfg.chip.numerics;
  const chip::RayMath math(n.traversal_float, cfg.chip.step_micro, m.micro_res);
  const Camera cam = orbit_camera(40, 36, 120.0, 20.0, 4.0, 50.0);
  const chip::Vru vru(n, cfg.chip.transmittance_min, cfg.chip.background);
  const chip::Zorg zorg(cam.width, cam.height, chip::ScanOrder::ZOrder);
  chip::FrontEnd ahead_front(m, cam, n, math, true), front(m, cam, n, math, true);
  FrontEndAhead ahead(zorg, ahead_front, vru, 4);
  chip::Zorg order = zorg;
  size_t packets = 0, traversed = 0;
  FrontEndPacket e;
  while (!order.done()) {
    while (!ahead.ready()) ASSERT_TRUE(ahead.produce_one());
    ahead.take(e);
    const chip::PixelQuad quad = order.next();
    const uint64_t evals = front.tsps_position_evals();
    const chip::RayPacket p = front.build(quad, vru);
    ASSERT_EQ(e.quad.sequence, quad.sequence);
    EXPECT_EQ(e.tsps_position_evals, front.tsps_position_evals() - evals);
    expect_same_rays(*e.packet, p);
    ++packets;
    traversed += p.live_mask() != 0;
  }
  EXPECT_FALSE(ahead.produce_one());  // the frame is done
  EXPECT_EQ(packets, size_t(zorg.packet_count()));
  EXPECT_GT(traversed, 0u);
}

TEST(Shortcuts, EveryStatisticTraceAndImageMatchSteppingEveryCycle) {
  const SceneModel& m = scene();
  std::vector<std::pair<const char*, SimConfig>> variants;
  auto add = [&](const char* name, auto edit) {
    SimConfig c = preset();
    edit(c);
    variants.push_back({name, c});
  };
  add("preset", [](SimConfig&) {});
  // Queues of one or two: traversals refused by a full queue are done by the FTU.
  add("tiny buffers", [](SimConfig& c) {
    c.chip.rp_buffer_capacity = 2;
    c.chip.rp_rob = {.entries = 2, .entry_depth = 1, .recent_tags = 1};
    c.chip.ooo_queue_depth = 1;
    c.memory.micro_grid_cache = {8, 1, Replacement::Fifo, 1, 1, 1};  // one word per line, direct mapped
    c.chip.micro_grid_cache_bytes = 64;
  });
  add("no reordering, no lag-first", [](SimConfig& c) {
    c.chip.switches.rp_reorder = false;
    c.chip.switches.lag_first = false;
    c.chip.switches.ooo_issue = false;
  });
  add("large RP buffer", [](SimConfig& c) { c.chip.rp_buffer_capacity = 256; });
  // Samples that take several cycles in each back-end unit, bank conflicts
  // and a shadow weight buffer: the CFIU, TME and VRU count down between
  // their actions.
  add("slow back end", [](SimConfig& c) {
    c.timing.cfiu_cycles_per_sample = 2;
    c.timing.tme_macs_per_cycle = 128;
    c.timing.vru_cycles_per_sample = 3;
    c.timing.tme_weight_buffers = 2;
    c.chip.bank_mapping = chip::BankMapping::Linear;
  });
  double skipped = 0;
  for (const auto& [name, cfg] : variants) {
    SCOPED_TRACE(name);
    for (double azimuth : {30.0, 250.0}) {
      const Camera cam = orbit_camera(48, 40, azimuth, 25.0, 4.0, 50.0);
      SimOptions stepped, one, two;
      stepped.skip_quiet_cycles = false;
      two.threads = 2;
      for (SimOptions* o : {&stepped, &one, &two}) {
        o->trace_start_cycle = 300;  // a window that starts and ends mid-frame
        o->trace_cycles = 2000;
      }
      const SimResult r = simulate_chip(m, cam, cfg, stepped);
      ASSERT_GT(r.summary.samples, 0u);
      EXPECT_EQ(r.stats->get("host.skipped_cycles"), 0.0);
      for (const SimOptions* o : {&one, &two}) {
        SCOPED_TRACE(o->threads);
        const SimResult a = simulate_chip(m, cam, cfg, *o);
        EXPECT_EQ(chip_stats(r), chip_stats(a)) << "azimuth " << azimuth;
        EXPECT_EQ(r.hit_rate_series, a.hit_rate_series);
        EXPECT_EQ(r.trace, a.trace);
        EXPECT_EQ(r.image.data, a.image.data);
        skipped += a.stats->get("host.skipped_cycles");
      }
    }
  }
  EXPECT_GT(skipped, 0.0);  // the shortcut was taken
}

}  // namespace
}  // namespace edrnr::sim
