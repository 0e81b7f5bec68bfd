#include <gtest/gtest.h>

#include <cmath>

#include "chip/chip.h"
#include "core/error.h"
#include "core/metrics.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "render/reference.h"

namespace edrnr {
namespace {

// Four objects of different colours and densities, one translucent, with
// seeded values in the channels the MLPs ignore.
const SceneModel& several_model() {
  static const SceneModel m = [] {
    ProceduralOptions o;
    o.micro_res = 64;
    o.seed = 7;
    return make_procedural_model("several", procedural_shapes("several"), o);
  }();
  return m;
}

Camera test_camera(int w, int h, double azimuth = 30.0) { return orbit_camera(w, h, azimuth, 25.0, 4.0, 50.0); }

bool same_bits(const Image& a, const Image& b) {
  return a.width == b.width && a.height == b.height && a.channels == b.channels && a.data == b.data;
}

TEST(Chip, MatchesTheReferenceRendererOnTheQuantizedModel) {
  const SceneModel& m = several_model();
  for (double azimuth : {30.0, 200.0}) {
    const Camera cam = test_camera(40, 36, azimuth);
    ChipCounters counters;
    const Image chip = render_chip(m, cam, ChipConfig{}, &counters);
    RenderSettings rs;
    rs.form = ModelForm::Quantized;
    RenderStats stats;
    const Image ref = render_reference(m, cam, rs, &stats);
    EXPECT_GE(psnr(chip, ref), 40.0) << "azimuth " << azimuth;
    // The chip finds (nearly) the reference's samples: positions differ only
    // by the custom-float rounding, near voxel faces.
    EXPECT_NEAR(double(counters.vru.samples), double(stats.samples), 0.02 * double(stats.samples));
  }
}

TEST(Chip, SchedulingSwitchesNeverChangeTheImage) {
  const SceneModel& m = several_model();
  const Camera cam = test_camera(23, 17);  // odd sizes: partial quads, out-of-bounds Z-curve stretches
  ChipCounters base_counters;
  const Image base = render_chip(m, cam, ChipConfig{}, &base_counters);
  std::vector<std::pair<const char*, ChipConfig>> variants;
  auto add = [&](const char* name, auto edit) {
    ChipConfig c;
    edit(c);
    variants.push_back({name, c});
  };
  add("row order", [](ChipConfig& c) { c.switches.z_order = false; });
  add("no AABB", [](ChipConfig& c) { c.switches.aabb = false; });
  add("no lag first", [](ChipConfig& c) { c.switches.lag_first = false; });
  add("no RP reordering", [](ChipConfig& c) { c.switches.rp_reorder = false; });
  add("in-order issue", [](ChipConfig& c) { c.switches.ooo_issue = false; });
  add("direct banks", [](ChipConfig& c) { c.bank_mapping = chip::BankMapping::Direct; });
  add("linear banks", [](ChipConfig& c) { c.bank_mapping = chip::BankMapping::Linear; });
  add("tiny buffers", [](ChipConfig& c) {
    c.rp_buffer_capacity = 3;
    c.rp_rob = {.entries = 2, .entry_depth = 1, .recent_tags = 1};
    c.ooo_queue_depth = 2;
    c.feature_cache_bytes = 8000;  // 8 blocks
    c.mshr_entries = 1;
    c.micro_grid_cache_bytes = 0;
    c.functional_fill_latency_issues = 0;
  });
  add("everything off", [](ChipConfig& c) {
    c.switches = {false, false, false, false, false};
    c.bank_mapping = chip::BankMapping::Direct;
    c.functional_fill_latency_issues = 30;
  });
  for (const auto& [name, cfg] : variants) {
    ChipCounters counters;
    const Image img = render_chip(m, cam, cfg, &counters);
    EXPECT_TRUE(same_bits(img, base)) << name;
    EXPECT_EQ(counters.vru.samples, base_counters.vru.samples) << name;
    EXPECT_EQ(counters.rays, uint64_t(23 * 17)) << name;
  }
}

TEST(Chip, DeterministicAcrossRuns) {
  const SceneModel& m = several_model();
  const Camera cam = test_camera(20, 20, 110.0);
  ChipCounters a, b;
  const Image first = render_chip(m, cam, ChipConfig{}, &a);
  const Image second = render_chip(m, cam, ChipConfig{}, &b);
  EXPECT_TRUE(same_bits(first, second));
  EXPECT_EQ(a.ctu.coarse_checks, b.ctu.coarse_checks);
  EXPECT_EQ(a.rp_rob.tag_runs, b.rp_rob.tag_runs);
  EXPECT_EQ(a.feature_cache.misses, b.feature_cache.misses);
}

TEST(Chip, TechniquesDoWhatThePaperSays) {
  const SceneModel& m = several_model();
  const Camera cam = test_camera(96, 96);
  ChipCounters on, no_aabb, no_reorder, in_order;
  render_chip(m, cam, ChipConfig{}, &on);
  ChipConfig c;
  c.switches.aabb = false;
  render_chip(m, cam, c, &no_aabb);
  c = ChipConfig{};
  c.switches.rp_reorder = false;
  render_chip(m, cam, c, &no_reorder);
  c = ChipConfig{};
  c.switches.ooo_issue = false;
  render_chip(m, cam, c, &in_order);
  // The AABB cuts coarse and fine bitmap checks (paper: -70.4 % and -26.0 %).
  EXPECT_LT(on.ctu.coarse_checks, no_aabb.ctu.coarse_checks);
  EXPECT_LE(on.ftu.fine_checks, no_aabb.ftu.fine_checks);
  EXPECT_GT(on.rays_dropped_abt, 0u);
  // Clustering by CV tag schedules more CCRPs per tag switch (paper: 24.24x).
  EXPECT_GT(on.rps_per_tag_switch(), 2.0 * no_reorder.rps_per_tag_switch());
  EXPECT_LE(on.tme.mlp_loads, no_reorder.tme.mlp_loads);
  // Out-of-order issue waits less for feature blocks.
  EXPECT_GT(on.ooo.issued_out_of_order, 0u);
  EXPECT_EQ(in_order.ooo.issued_out_of_order, 0u);
  EXPECT_LE(on.fill_waits, in_order.fill_waits);
  // Rays advance together: at most 4 per iteration, and at least 1.
  EXPECT_GE(on.coarse_rays_per_iteration(), 1.0);
  EXPECT_LE(on.coarse_rays_per_iteration(), 4.0);
  // Bookkeeping: every sample is composited or belongs to a stopped ray;
  // balanced banks: uniform depths and no conflicts.
  EXPECT_EQ(on.ftu.samples, on.vru.samples + on.vru.samples_skipped);
  EXPECT_EQ(on.cfiu.conflict_cycles, 0u);
  EXPECT_EQ(on.feature_cache_lines, 256);
  for (int b = 0; b < chip::kFeatureBanks; ++b) EXPECT_EQ(on.bank_depth_rows[size_t(b)], 256 / 8 * 125);
  // Every batch is issued, every CRP retires, every RP is finished or dropped.
  EXPECT_EQ(on.ooo.pushed, on.ftu.batches);
  EXPECT_EQ(on.ooo.issued, on.ftu.batches);
  EXPECT_EQ(on.rp_rob.retires, on.rp_rob.inserts);
  EXPECT_EQ(on.rps_finished + on.packets_dropped, on.packets);
}

TEST(Chip, EmptyViewIsBackground) {
  const SceneModel& m = several_model();
  Camera cam = test_camera(9, 7);
  // Look away from the scene: turn the camera around its up axis by 180 degrees.
  for (int i = 0; i < 3; ++i) {
    cam.c2w[size_t(4 * i + 0)] = -cam.c2w[size_t(4 * i + 0)];
    cam.c2w[size_t(4 * i + 2)] = -cam.c2w[size_t(4 * i + 2)];
  }
  ChipConfig cfg;
  cfg.background[0] = 0.25f;
  cfg.background[1] = 0.5f;
  cfg.background[2] = 1.f;
  ChipCounters counters;
  const Image img = render_chip(m, cam, cfg, &counters);
  for (int y = 0; y < 7; ++y)
    for (int x = 0; x < 9; ++x) {
      EXPECT_EQ(img.at(x, y)[0], 0.25f);
      EXPECT_EQ(img.at(x, y)[1], 0.5f);
      EXPECT_EQ(img.at(x, y)[2], 1.f);
    }
  EXPECT_EQ(counters.rays_dropped_abt + counters.rays_dropped_tsps, 63u);
  EXPECT_EQ(counters.ctu.iterations, 0u);
}

TEST(Chip, RejectsModelsAndConfigsItCannotRun) {
  SceneModel m = several_model();
  const Camera cam = test_camera(8, 8);
  ChipConfig bad;
  bad.ooo_queue_depth = 0;
  EXPECT_THROW(render_chip(m, cam, bad), Error);
  bad = ChipConfig{};
  bad.feature_cache_bytes = 4000;  // not even 8 blocks
  EXPECT_THROW(render_chip(m, cam, bad), Error);
  bad = ChipConfig{};
  bad.mlp_cache_bytes = 1000;  // the default MLP needs about 4 KB
  EXPECT_THROW(render_chip(m, cam, bad), Error);
  m.features_q4.clear();
  EXPECT_THROW(render_chip(m, cam, ChipConfig{}), Error);
}

TEST(ChipConfig, DefaultPresetIsTheBuiltInDefault) {
  const ChipConfig c = load_chip_config(std::string(EDRNR_SOURCE_DIR) + "/configs/chip/default.yaml");
  const ChipConfig d;
  EXPECT_EQ(c.rp_buffer_capacity, d.rp_buffer_capacity);
  EXPECT_EQ(c.rp_rob.entries, d.rp_rob.entries);
  EXPECT_EQ(c.rp_rob.entry_depth, d.rp_rob.entry_depth);
  EXPECT_EQ(c.rp_rob, d.rp_rob);
  EXPECT_EQ(c.ooo_queue_depth, d.ooo_queue_depth);
  EXPECT_EQ(c.feature_cache_bytes, 262144);
  EXPECT_EQ(c.mlp_cache_bytes, 8448);
  EXPECT_EQ(c.micro_grid_cache_bytes, 8192);
  EXPECT_EQ(c.bank_mapping, chip::BankMapping::Balanced);
  EXPECT_EQ(c.switches, d.switches);
  EXPECT_EQ(c.numerics, d.numerics);
  EXPECT_EQ(c.transmittance_min, 1e-4f);
}

TEST(ChipConfig, YamlRoundTripAndErrors) {
  ChipConfig c;
  c.rp_buffer_capacity = 12;
  c.rp_rob.recent_tags = 2;
  c.bank_mapping = chip::BankMapping::Linear;
  c.switches.lag_first = false;
  c.background[1] = 0.5f;
  c.numerics.alpha_bits = 12;
  const ChipConfig r = chip_config_from_yaml(chip_config_to_yaml(c));
  EXPECT_EQ(r.rp_buffer_capacity, 12);
  EXPECT_EQ(r.rp_rob.recent_tags, 2);
  EXPECT_EQ(r.bank_mapping, chip::BankMapping::Linear);
  EXPECT_FALSE(r.switches.lag_first);
  EXPECT_EQ(r.background[1], 0.5f);
  EXPECT_EQ(r.numerics, c.numerics);
  auto error_of = [](const char* yaml) {
    try {
      chip_config_from_yaml(YAML::Load(yaml), "test.yaml");
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(error_of("rp_bufer_capacity: 3").find("rp_bufer_capacity"), std::string::npos);
  EXPECT_NE(error_of("rp_rob: {entries: many}").find("test.yaml.rp_rob.entries"), std::string::npos);
  EXPECT_NE(error_of("ooo_queue_depth: 0").find("ooo_queue_depth"), std::string::npos);
  EXPECT_NE(error_of("feature_cache: {bank_mapping: rotated}").find("rotated"), std::string::npos);
  EXPECT_NE(error_of("render: {background: [1, 2]}").find("background"), std::string::npos);
  EXPECT_NE(error_of("switches: {aabb: maybe}").find("switches.aabb"), std::string::npos);
}

TEST(ChipCounters, ExportedWithUnits) {
  ChipCounters c;
  c.ctu.iterations = 10;
  c.ctu.rays_advanced = 35;
  c.rp_rob.schedules = 48;
  c.rp_rob.tag_runs = 4;
  StatsRegistry stats;
  export_chip_stats(c, stats);
  EXPECT_EQ(stats.get("chip.ctu.rays_per_iteration"), 3.5);
  EXPECT_EQ(stats.get("chip.rp_rob.rps_per_tag_switch"), 12.0);
  EXPECT_EQ(stats.get("chip.ctu.iterations"), 10.0);
}

}  // namespace
}  // namespace edrnr
