#include <gtest/gtest.h>

#include <array>

#include "chip/cfiu.h"
#include "chip/oo_si.h"
#include "core/error.h"

namespace edrnr::chip {
namespace {

// One fine voxel (block 0) of a 32^3 model with 2 channels:
// channel 0 code = i, channel 1 code = j + 2k at vertex (i, j, k).
SceneModel linear_feature_model() {
  SceneModel m;
  m.micro_res = 32;
  m.feature_channels = 2;
  m.init_grids();
  m.occupancy[int(Tier::Micro)].set(0, 0, 0);
  m.rebuild_upper_tiers();
  m.block_fine_index = {0};
  m.features_q4.assign(kBlockVerts, 0);  // 125 vertices x 2 channels x 4 bits
  for (int k = 0; k < 5; ++k)
    for (int j = 0; j < 5; ++j)
      for (int i = 0; i < 5; ++i) {
        const size_t v = size_t(block_vertex(i, j, k));
        m.features_q4[v] = uint8_t(i | (j + 2 * k) << 4);  // even channel in the low nibble
      }
  m.feature_quant.scale = {1.f, 1.f};
  m.feature_quant.zero_point = {0, 3};
  m.finalize();
  return m;
}

TEST(Cfiu, InterpolatesLinearFeaturesExactlyWithEveryBankMapping) {
  const SceneModel m = linear_feature_model();
  // Local micro voxel (1, 2, 0), fractions (0.25, 0.5, 0.75) in 8 bits.
  SampleCoord s;
  s.local = {1, 2, 0};
  s.frac = {64, 128, 192};
  for (BankMapping mapping : {BankMapping::Balanced, BankMapping::Direct, BankMapping::Linear}) {
    Cfiu cfiu(m, ChipNumerics{}, {.lines = 8, .mshr_entries = 2, .mapping = mapping});
    ASSERT_EQ(cfiu.cache().request(0), CacheAccess::MissAllocated);
    cfiu.cache().fill(0);
    int32_t out[2];
    cfiu.interpolate(0, s, out);
    // Trilinear interpolation reproduces a linear function: channel 0 is
    // 1 + 0.25 = 1.25 codes; channel 1 is (2 + 0.5) + 2 (0 + 0.75) - 3 = 1.
    EXPECT_EQ(out[0], 320) << bank_mapping_name(mapping);  // 1.25 * 256
    EXPECT_EQ(out[1], 256) << bank_mapping_name(mapping);
    EXPECT_EQ(cfiu.counters().corner_reads, 8u);
    uint64_t reads = 0;
    for (uint64_t r : cfiu.counters().bank_reads) reads += r;
    EXPECT_EQ(reads, 8u);
    // Micro voxel (0, 0, 0) costs the linear layout one extra cycle (banks 1 and 6 twice).
    const uint64_t before = cfiu.counters().conflict_cycles;
    s.local = {0, 0, 0};
    cfiu.interpolate(0, s, out);
    EXPECT_EQ(cfiu.counters().conflict_cycles - before, mapping == BankMapping::Linear ? 1u : 0u);
    if (mapping != BankMapping::Linear) {
      EXPECT_EQ(cfiu.counters().conflict_cycles, 0u);
    }
    s.local = {1, 2, 0};
  }
}

TEST(Cfiu, RoundsOnceAndSaturates) {
  const SceneModel m = linear_feature_model();
  ChipNumerics n;
  n.interp_feature_frac_bits = 0;  // whole codes: 1.25 rounds to 1
  Cfiu cfiu(m, n, {.lines = 8, .mshr_entries = 2, .mapping = BankMapping::Balanced});
  cfiu.cache().request(0);
  cfiu.cache().fill(0);
  SampleCoord s;
  s.local = {1, 2, 0};
  s.frac = {64, 128, 192};
  int32_t out[2];
  cfiu.interpolate(0, s, out);
  EXPECT_EQ(out[0], 1);
  EXPECT_EQ(out[1], 1);
  s.local = {3, 0, 0};
  s.frac = {128, 0, 0};  // channel 0: 3.5 codes, a tie: half up gives 4
  cfiu.interpolate(0, s, out);
  EXPECT_EQ(out[0], 4);
  // 8-bit output with 8 fraction bits saturates 3.5 codes (896) at 127.
  n.interp_feature_frac_bits = 8;
  n.interp_feature_bits = 8;
  Cfiu narrow(m, n, {.lines = 8, .mshr_entries = 2, .mapping = BankMapping::Balanced});
  narrow.cache().request(0);
  narrow.cache().fill(0);
  narrow.interpolate(0, s, out);
  EXPECT_EQ(out[0], 127);
}

TEST(Cfiu, OddChannelCountsReadCodesAcrossBytes) {
  // 3 channels: a vertex's codes start on either nibble of a byte. Channel 0
  // code = i, channel 1 = j, channel 2 = k + 1 (zero point 1) at vertex
  // (i, j, k); trilinear interpolation reproduces each linear function.
  SceneModel m;
  m.micro_res = 32;
  m.feature_channels = 3;
  m.init_grids();
  m.occupancy[int(Tier::Micro)].set(0, 0, 0);
  m.rebuild_upper_tiers();
  m.block_fine_index = {0};
  m.features_q4.assign((kBlockVerts * 3 + 1) / 2, 0);
  auto put = [&](size_t at, int code) { m.features_q4[at >> 1] |= uint8_t(code << ((at & 1) * 4)); };
  for (int k = 0; k < 5; ++k)
    for (int j = 0; j < 5; ++j)
      for (int i = 0; i < 5; ++i) {
        const size_t v = size_t(block_vertex(i, j, k));
        put(3 * v, i);
        put(3 * v + 1, j);
        put(3 * v + 2, k + 1);
      }
  m.feature_quant.scale = {1.f, 1.f, 1.f};
  m.feature_quant.zero_point = {0, 0, 1};
  m.finalize();
  Cfiu cfiu(m, ChipNumerics{}, {.lines = 8, .mshr_entries = 2, .mapping = BankMapping::Balanced});
  cfiu.cache().request(0);
  cfiu.cache().fill(0);
  const struct {
    Vec3i local;
    std::array<int, 3> frac;  // 8 bits
  } cases[] = {
      {{1, 2, 0}, {64, 128, 192}}, {{0, 3, 1}, {255, 1, 7}}, {{3, 3, 3}, {0, 0, 0}}, {{2, 1, 3}, {17, 200, 99}}};
  for (const auto& c : cases) {
    SampleCoord s;
    s.local = c.local;
    s.frac = {uint32_t(c.frac[0]), uint32_t(c.frac[1]), uint32_t(c.frac[2])};
    int32_t out[3];
    cfiu.interpolate(0, s, out);
    // In steps of 1/256 code: the position along each axis, exactly.
    for (int a = 0; a < 3; ++a) EXPECT_EQ(out[a], 256 * c.local[a] + c.frac[size_t(a)]) << "axis " << a;
  }
}

TEST(Cfiu, NeedsQuantizedFeatures) {
  SceneModel m = linear_feature_model();
  m.features_q4.clear();
  EXPECT_THROW(Cfiu(m, ChipNumerics{}, {}), Error);
}

TEST(OooSi, IssuesTheOldestEntryWhoseBlockIsOnChip) {
  FeatureCache cache({.lines = 4, .mshr_entries = 4, .mapping = BankMapping::Balanced});
  cache.request(10);  // pending
  cache.request(11);
  cache.fill(11);
  cache.request(12);
  cache.fill(12);
  OooSi ooo(4, true);
  ooo.push({1, 10, 0});
  ooo.push({2, 11, 1});
  ooo.push({3, 12, 2});
  ASSERT_EQ(ooo.select(cache), 1);
  EXPECT_EQ(ooo.take(1).rp, 2u);
  EXPECT_EQ(ooo.at(1).rp, 3u);  // the location shifter moved it down
  EXPECT_EQ(ooo.select(cache), 1);
  EXPECT_EQ(ooo.counters().issued_out_of_order, 1u);

  OooSi in_order(4, false);
  in_order.push({1, 10, 0});
  in_order.push({2, 11, 1});
  EXPECT_FALSE(in_order.select(cache));  // the head waits for its block
  EXPECT_EQ(in_order.counters().waits, 1u);
  cache.fill(10);
  EXPECT_EQ(in_order.select(cache), 0);
  in_order.push({3, 12, 2});
  in_order.push({4, 12, 3});
  EXPECT_THROW(in_order.push({5, 12, 4}), std::logic_error);
}

TEST(OooSi, SampleCoordinateByHand) {
  const RayMath math(ChipNumerics{}.traversal_float, 1.0, 32);
  // A ray with d = 0 stays at its origin: every candidate is that point.
  const ChipRay r{{10.25, 3.5, 7.0}, {0, 0, 0}};
  SampleCoord s = sample_coordinate(math, r, 4, 8, fx::Rounding::HalfUp);
  EXPECT_EQ(s.micro, (Vec3i{10, 3, 7}));
  EXPECT_EQ(s.local, (Vec3i{2, 3, 3}));
  EXPECT_EQ(s.frac, (std::array<int64_t, 3>{64, 128, 0}));
  // 10.999 is 0.999 into its voxel: 255.7 steps round up to a whole voxel
  // (weights 0 and 1), in the format 10.999 is 10.9990234375.
  const ChipRay near_face{{math.format().round(10.999), 0.5, 0.5}, {0, 0, 0}};
  s = sample_coordinate(math, near_face, 0, 8, fx::Rounding::HalfUp);
  EXPECT_EQ(s.micro.x, 10);
  EXPECT_EQ(s.frac[0], 256);
}

TEST(OooSi, SampleCoordinateRoundsTiesAsEachModeSays) {
  const RayMath math(ChipNumerics{}.traversal_float, 1.0, 32);
  // Fractions 0.25, 0.75 and 0.5 at one fraction bit: 0.5, 1.5 (ties) and 1.
  const ChipRay r{{10.25, 3.75, 7.5}, {0, 0, 0}};
  using A = std::array<int64_t, 3>;
  EXPECT_EQ(sample_coordinate(math, r, 0, 1, fx::Rounding::Floor).frac, (A{0, 1, 1}));
  EXPECT_EQ(sample_coordinate(math, r, 0, 1, fx::Rounding::HalfUp).frac, (A{1, 2, 1}));
  EXPECT_EQ(sample_coordinate(math, r, 0, 1, fx::Rounding::HalfEven).frac, (A{0, 2, 1}));
  // Wider than a double's significand: the general conversion, exact here.
  const int64_t q = int64_t(1) << 58;  // 0.25 at 60 fraction bits
  EXPECT_EQ(sample_coordinate(math, r, 0, 60, fx::Rounding::HalfEven).frac, (A{q, 3 * q, 2 * q}));
}

}  // namespace
}  // namespace edrnr::chip
