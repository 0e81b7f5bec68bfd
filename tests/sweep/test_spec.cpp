// SPEC parsing and plan expansion: errors name the line and key; points come
// out in the documented order with the documented values.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/error.h"
#include "sim/reproduce_runs.h"
#include "sim/sim_config.h"
#include "sweep/plan.h"
#include "sweep/spec.h"
#include "sweep_fixture.h"

namespace edrnr::sweep {
namespace {

using ::testing::HasSubstr;
using testing::source_dirs;
using testing::TempDir;

std::string spec_error(const std::string& text) {
  try {
    make_plan(parse_sweep_spec(text, "s.yaml"), source_dirs());
  } catch (const Error& e) {
    return e.what();
  }
  return "(no error)";
}

const char* kModel = "models: [{procedural: sphere, res: 64, channels: 8}]\nviews: {width: 16}\n";

TEST(SweepSpec, UnknownTopLevelKeyNamesItsLine) {
  const std::string e = spec_error(std::string("base: edr_nr_40nm\nvari:\n  rp_rob.entries: [8]\n") + kModel);
  EXPECT_THAT(e, HasSubstr("s.yaml:2"));
  EXPECT_THAT(e, HasSubstr("unknown key 'vari'"));
}

TEST(SweepSpec, UnknownPresetKeyNamesItsLineAndTheKnownKeys) {
  const std::string e = spec_error(std::string("vary:\n  rp_rob.entriez: [8, 16]\n") + kModel);
  EXPECT_THAT(e, HasSubstr("s.yaml:2"));
  EXPECT_THAT(e, HasSubstr("rp_rob.entriez"));
  EXPECT_THAT(e, HasSubstr("entry_depth"));  // a key that does exist under rp_rob
}

TEST(SweepSpec, WrongTypeNamesItsLine) {
  const std::string e =
      spec_error(std::string("vary:\n  feature_cache.bytes: [262144]\n  rp_rob.entries: [8, lots]\n") + kModel);
  EXPECT_THAT(e, HasSubstr("s.yaml:3"));
  EXPECT_THAT(e, HasSubstr("'lots' is not a number"));
  const std::string b = spec_error(std::string("vary:\n  switches.z_order: [true, 3]\n") + kModel);
  EXPECT_THAT(b, HasSubstr("s.yaml:2"));
  EXPECT_THAT(b, HasSubstr("'3' is not true or false"));
}

TEST(SweepSpec, EmptyListsAndRangesAreRefused) {
  EXPECT_THAT(spec_error(std::string("vary:\n  rp_rob.entries: []\n") + kModel), HasSubstr("s.yaml:2"));
  EXPECT_THAT(spec_error(std::string("vary:\n  rp_rob.entries: []\n") + kModel), HasSubstr("empty"));
  const std::string r = spec_error(std::string("\nvary:\n  rp_rob.entries: {from: 16, to: 8, step: 1}\n") + kModel);
  EXPECT_THAT(r, HasSubstr("s.yaml:3"));
  EXPECT_THAT(r, HasSubstr("the range is empty"));
  EXPECT_THAT(spec_error(std::string("vary:\n  rp_rob.entries: {from: 8, to: 16, step: 0}\n") + kModel),
              HasSubstr("must be positive"));
}

TEST(SweepSpec, ZipNeedsListsOfOneLength) {
  const std::string e =
      spec_error(std::string("combine: zip\nvary:\n  rp_rob.entries: [8, 16]\n  ooo_queue_depth: [4]\n") + kModel);
  EXPECT_THAT(e, HasSubstr("s.yaml:4"));
  EXPECT_THAT(e, HasSubstr("one length"));
}

TEST(SweepSpec, IntervalsOnlyForRandom) {
  EXPECT_THAT(spec_error(std::string("vary:\n  render.step_micro: {from: 0.5, to: 2}\n") + kModel),
              HasSubstr("combine: random"));
  EXPECT_THAT(spec_error(std::string("combine: random\nvary:\n  rp_rob.entries: [8]\n") + kModel),
              HasSubstr("needs 'samples'"));
}

TEST(SweepSpec, MalformedYamlAndMissingModels) {
  EXPECT_THAT(spec_error("vary: [\n"), HasSubstr("not valid YAML"));
  EXPECT_THAT(spec_error("vary: {rp_rob.entries: [8]}\n"), HasSubstr("no 'models'"));
  EXPECT_THAT(spec_error(std::string("base: no_such_preset\n") + kModel), HasSubstr("no chip preset no_such_preset"));
  EXPECT_THAT(spec_error("models: [{procedural: teapot}]\n"), HasSubstr("unknown scene 'teapot'"));
}

TEST(SweepPlan, ProductOrderLastKeyFastestAndBaseDeduplicated) {
  const SweepPlan p = make_plan(
      parse_sweep_spec(
          std::string("vary:\n  rp_rob.entries: [8, 16]\n  simulator.clock_MHz: {from: 100, to: 380, step: 140}\n") +
              kModel,
          "s.yaml"),
      source_dirs());
  // 2 x 3 points; the base (16 entries, 380 MHz) is one of them, so no extra point.
  ASSERT_EQ(p.points.size(), 6u);
  const int entries[] = {8, 8, 8, 16, 16, 16};
  const double clocks[] = {100, 240, 380, 100, 240, 380};
  for (size_t i = 0; i < 6; ++i) {
    ASSERT_TRUE(p.points[i].config) << p.points[i].config_error;
    EXPECT_EQ(p.points[i].config->chip.rp_rob.entries, entries[i]);
    EXPECT_DOUBLE_EQ(p.points[i].config->clock_MHz, clocks[i]);
  }
  ASSERT_TRUE(p.base_point);
  EXPECT_EQ(*p.base_point, 5u);
  EXPECT_EQ(p.jobs.size(), 6u);
}

TEST(SweepPlan, ConfigHashIsTheResolvedConfigsHash) {
  const SweepPlan p =
      make_plan(parse_sweep_spec(std::string("vary:\n  rp_rob.entries: [8]\n") + kModel, "s.yaml"), source_dirs());
  ASSERT_EQ(p.points.size(), 2u);  // the point and the base design
  sim::SimConfig c = sim::load_sim_config(std::filesystem::path(EDRNR_SOURCE_DIR) / "configs/chip/edr_nr_40nm.yaml",
                                          source_dirs().dram);
  EXPECT_EQ(p.points[1].config_hash, sim::config_hash(c));
  c.chip.rp_rob.entries = 8;
  EXPECT_EQ(p.points[0].config_hash, sim::config_hash(c));
}

TEST(SweepPlan, FactorRangesZipAndSet) {
  const SweepPlan p = make_plan(
      parse_sweep_spec(std::string("combine: zip\ninclude_base: false\nset: {simulator.clock_MHz: 200}\nvary:\n"
                                   "  feature_cache.bytes: {from: 65536, to: 262144, factor: 2}\n"
                                   "  rp_rob.entries: [4, 8, 16]\n") +
                           kModel,
                       "s.yaml"),
      source_dirs());
  ASSERT_EQ(p.points.size(), 3u);
  const int64_t bytes[] = {65536, 131072, 262144};
  const int entries[] = {4, 8, 16};
  for (size_t i = 0; i < 3; ++i) {
    ASSERT_TRUE(p.points[i].config) << p.points[i].config_error;
    EXPECT_EQ(p.points[i].config->chip.feature_cache_bytes, bytes[i]);
    EXPECT_EQ(p.points[i].config->chip.rp_rob.entries, entries[i]);
    EXPECT_DOUBLE_EQ(p.points[i].config->clock_MHz, 200);
  }
  // The base with `set` (256 KB, 16 entries, 200 MHz) is the last point, found without include_base.
  ASSERT_TRUE(p.base_point);
  EXPECT_EQ(*p.base_point, 2u);
}

TEST(SweepPlan, RandomSamplesAreDistinctInTheirDomainsAndSeeded) {
  auto make = [](int seed) {
    return make_plan(parse_sweep_spec(fmt::format("combine: random\nsamples: 6\nseed: {}\ninclude_base: false\nvary:\n"
                                                  "  rp_rob.entries: [4, 8, 16, 32]\n"
                                                  "  render.step_micro: {{from: 0.5, to: 2.0}}\n{}",
                                                  seed, kModel),
                                      "s.yaml"),
                     source_dirs());
  };
  const SweepPlan a = make(7), b = make(7), c = make(8);
  ASSERT_EQ(a.points.size(), 6u);
  std::set<std::string> hashes;
  for (size_t i = 0; i < a.points.size(); ++i) {
    ASSERT_TRUE(a.points[i].config);
    const int e = a.points[i].config->chip.rp_rob.entries;
    EXPECT_TRUE(e == 4 || e == 8 || e == 16 || e == 32) << e;
    const double s = a.points[i].config->chip.step_micro;
    EXPECT_GE(s, 0.5);
    EXPECT_LE(s, 2.0);
    hashes.insert(a.points[i].config_hash);
    EXPECT_EQ(a.points[i].config_hash, b.points[i].config_hash);
  }
  EXPECT_EQ(hashes.size(), 6u);
  EXPECT_NE(plan_hash(a), plan_hash(c));
}

TEST(SweepPlan, OutOfRangeValueIsAnInvalidPointNotASpecError) {
  const SweepPlan p = make_plan(
      parse_sweep_spec(std::string("include_base: false\nvary:\n  rp_rob.entries: [0, 8]\n") + kModel, "s.yaml"),
      source_dirs());
  ASSERT_EQ(p.points.size(), 2u);
  EXPECT_FALSE(p.points[0].config);
  EXPECT_THAT(p.points[0].config_error, HasSubstr("entries"));
  EXPECT_TRUE(p.points[1].config);
}

TEST(SweepPlan, ModelFilesResolveBesideTheSpec) {
  TempDir t("files");
  const SweepSpec s = parse_sweep_spec(std::string("models: [missing.edrnr]\n"), t.path / "s.yaml");
  try {
    make_plan(s, source_dirs());
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("s.yaml:1"));
    EXPECT_THAT(e.what(), HasSubstr("missing.edrnr"));
  }
}

}  // namespace
}  // namespace edrnr::sweep
