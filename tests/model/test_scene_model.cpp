// SceneModel: tiers, INT4 feature quantization, MLP sizes and the invariant checks.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "core/error.h"
#include "model/scene_model.h"

namespace edrnr {
namespace {

bool has_line(const std::vector<std::string>& lines, const std::string& text) {
  for (const std::string& l : lines)
    if (l.find(text) != std::string::npos) return true;
  return false;
}

TEST(SceneModel, TierResolutions) {
  SceneModel m;
  m.micro_res = 64;
  EXPECT_EQ(m.tier_res(Tier::Coarse), 2);
  EXPECT_EQ(m.tier_res(Tier::Fine), 16);
  EXPECT_EQ(m.tier_res(Tier::Leaf), 32);
  EXPECT_EQ(m.tier_res(Tier::Micro), 64);
  m.init_grids();
  EXPECT_EQ(m.occupancy[int(Tier::Coarse)].size(), 8u);
  EXPECT_EQ(m.occupancy[int(Tier::Leaf)].size(), 32768u);
  m.micro_res = 48;
  EXPECT_THROW(m.init_grids(), Error);
  m.micro_res = 0;
  EXPECT_THROW(m.init_grids(), Error);
}

TEST(SceneModel, BitmapIndexAndCount) {
  Bitmap3 bm(3);
  EXPECT_EQ(bm.size(), 27u);
  EXPECT_EQ(bm.words().size(), 1u);
  EXPECT_EQ(bm.index(2, 1, 0), 5u);
  EXPECT_EQ(bm.index(2, 2, 2), 26u);
  bm.set(2, 1, 0);
  bm.set(26);
  EXPECT_TRUE(bm.get(5));
  EXPECT_TRUE(bm.get(2, 2, 2));
  EXPECT_FALSE(bm.get(1, 1, 0));
  EXPECT_EQ(bm.count(), 2u);
  EXPECT_EQ(bm.words()[0], (uint64_t(1) << 5) | (uint64_t(1) << 26));
  bm.set(5, false);
  EXPECT_EQ(bm.count(), 1u);
}

TEST(SceneModel, RebuildUpperTiersIsTheOr) {
  SceneModel m;
  m.micro_res = 64;
  m.init_grids();
  Bitmap3& micro = m.occupancy[int(Tier::Micro)];
  micro.set(40, 3, 63);                       // leaf (20,1,31), fine (10,0,15), coarse (1,0,1)
  micro.set(41, 2, 62);                       // the same leaf voxel
  micro.set(0, 0, 0);                         // leaf, fine, coarse (0,0,0)
  micro.set(7, 7, 7);                         // leaf (3,3,3), fine (1,1,1), coarse (0,0,0)
  m.occupancy[int(Tier::Fine)].set(5, 5, 5);  // stale: must be cleared
  m.rebuild_upper_tiers();
  const Bitmap3& leaf = m.occupancy[int(Tier::Leaf)];
  const Bitmap3& fine = m.occupancy[int(Tier::Fine)];
  const Bitmap3& coarse = m.occupancy[int(Tier::Coarse)];
  EXPECT_EQ(leaf.count(), 3u);
  EXPECT_TRUE(leaf.get(20, 1, 31));
  EXPECT_TRUE(leaf.get(0, 0, 0));
  EXPECT_TRUE(leaf.get(3, 3, 3));
  EXPECT_EQ(fine.count(), 3u);
  EXPECT_TRUE(fine.get(10, 0, 15));
  EXPECT_TRUE(fine.get(0, 0, 0));
  EXPECT_TRUE(fine.get(1, 1, 1));
  EXPECT_FALSE(fine.get(5, 5, 5));
  EXPECT_EQ(coarse.count(), 2u);
  EXPECT_TRUE(coarse.get(1, 0, 1));
  EXPECT_TRUE(coarse.get(0, 0, 0));
}

TEST(SceneModel, MlpArchSizes) {
  MlpArch a;
  a.dir_frequencies = 2;
  a.density_widths = {16, 64, 16};
  a.color_widths = {31, 64, 3};
  EXPECT_EQ(a.dir_dims(), 15);
  EXPECT_EQ(a.feature_channels(), 16);
  EXPECT_EQ(a.geo_width(), 16);
  // 16*64 + 64*16 + 31*64 + 64*3 weights; 64 + 16 + 64 + 3 outputs.
  EXPECT_EQ(a.weight_count(), 4224u);
  EXPECT_EQ(a.bias_count(), 147u);
  EXPECT_EQ(a.q8_bytes(), 4224u + 8 * 147 + 4 * (16 + 2));
  EXPECT_LE(a.q8_bytes(), kMlpCacheBytes);
}

// One block of 3 channels: channel 0 runs from -1 to 2, channel 1 is 0, channel 2 runs from 0.5 to 3.
SceneModel one_block_model() {
  SceneModel m;
  m.micro_res = 32;
  m.feature_channels = 3;
  m.init_grids();
  m.block_fine_index = {0};
  m.features_f32.resize(kBlockVerts * 3);
  for (int v = 0; v < kBlockVerts; ++v) {
    m.features_f32[size_t(v) * 3 + 0] = -1.f + 3.f * float(v) / 124.f;
    m.features_f32[size_t(v) * 3 + 1] = 0.f;
    m.features_f32[size_t(v) * 3 + 2] = 0.5f + 2.5f * float(v) / 124.f;
  }
  return m;
}

TEST(SceneModel, QuantizeFeaturesScaleAndZeroPoint) {
  SceneModel m = one_block_model();
  m.quantize_features();
  // Range [-1, 2]: 15 steps of 0.2, zero at code 5. Constant 0: scale 1, zero point 0.
  // Range [0.5, 3] widened to include 0: [0, 3], 15 steps of 0.2, zero at code 0.
  ASSERT_EQ(m.feature_quant.scale.size(), 3u);
  EXPECT_FLOAT_EQ(m.feature_quant.scale[0], 0.2f);
  EXPECT_EQ(m.feature_quant.zero_point[0], 5);
  EXPECT_EQ(m.feature_quant.scale[1], 1.f);
  EXPECT_EQ(m.feature_quant.zero_point[1], 0);
  EXPECT_FLOAT_EQ(m.feature_quant.scale[2], 0.2f);
  EXPECT_EQ(m.feature_quant.zero_point[2], 0);
  // 375 nibbles in 188 bytes; the ends of each range map to codes 0 and 15.
  ASSERT_EQ(m.features_q4.size(), 188u);
  EXPECT_EQ(m.feature_q(0, 0, 0), 0);
  EXPECT_EQ(m.feature_q(0, 124, 0), 15);
  EXPECT_EQ(m.feature_q(0, 124, 1), 0);
  EXPECT_EQ(m.feature_q(0, 124, 2), 15);
  // Value i = 3v + c sits in byte i / 2, low nibble when i is even: vertex 124 is values 372..374.
  EXPECT_EQ(m.features_q4[186], 0x0F);  // 372: 15 (low), 373: 0 (high)
  EXPECT_EQ(m.features_q4[187], 0x0F);  // 374: 15 (low), high nibble unused
}

TEST(SceneModel, DequantizeErrorIsAtMostHalfAStep) {
  SceneModel m = one_block_model();
  std::vector<float> original = m.features_f32;
  m.quantize_features();
  m.dequantize_features();
  ASSERT_EQ(m.features_f32.size(), original.size());
  for (size_t i = 0; i < original.size(); ++i) {
    float step = m.feature_quant.scale[i % 3];
    EXPECT_LE(std::abs(m.features_f32[i] - original[i]), 0.5f * step * 1.0001f) << "value " << i;
  }
  EXPECT_FLOAT_EQ(m.features_f32[0], -1.f);       // code 0: (0 - 5) * 0.2
  EXPECT_FLOAT_EQ(m.features_f32[124 * 3], 2.f);  // code 15: (15 - 5) * 0.2
  EXPECT_EQ(m.features_f32[124 * 3 + 1], 0.f);    // a constant 0 stays exactly 0
  // feature() reads the INT4 codes when there are no float features.
  m.features_f32.clear();
  EXPECT_FLOAT_EQ(m.feature(0, 124, 0), 2.f);
  EXPECT_FLOAT_EQ(m.feature(0, 0, 2), 0.6f);  // 0.5 rounds to code 3 (0.5 / 0.2 = 2.5, rounded away from 0)
}

// A valid model over the scene box [0, 32]^3 at micro_res 32 (micro voxel = 1 unit):
// micro voxels (5, 5, 5) and (20, 9, 9), one block per fine voxel, one MLP for the one CV.
SceneModel valid_model() {
  SceneModel m;
  m.micro_res = 32;
  m.feature_channels = 2;
  m.scene_box = {{0.f, 0.f, 0.f}, {32.f, 32.f, 32.f}};
  m.object_aabb = {{5.f, 5.f, 5.f}, {21.f, 10.f, 10.f}};
  m.init_grids();
  m.occupancy[int(Tier::Micro)].set(5, 5, 5);
  m.occupancy[int(Tier::Micro)].set(20, 9, 9);
  m.rebuild_upper_tiers();
  m.block_fine_index = {linear_index(1, 1, 1, 8), linear_index(5, 2, 2, 8)};
  m.features_f32.assign(2 * kBlockVerts * 2, 0.25f);
  m.mlp_coarse_index = {0};
  m.mlps_f32.resize(1);
  m.finalize();
  return m;
}

TEST(SceneModel, CheckInvariantsAcceptsAValidModel) { EXPECT_TRUE(valid_model().check_invariants().empty()); }

TEST(SceneModel, CheckInvariantsCatchesTierNotOr) {
  SceneModel m = valid_model();
  m.occupancy[int(Tier::Leaf)].set(0, 0, 0);  // no micro voxel below it
  EXPECT_TRUE(has_line(m.check_invariants(), "leaf tier is not the OR of the micro tier"));
  m = valid_model();
  m.occupancy[int(Tier::Fine)].set(1, 1, 1, false);
  EXPECT_TRUE(has_line(m.check_invariants(), "fine tier is not the OR of the leaf tier"));
  m = valid_model();
  m.occupancy[int(Tier::Coarse)].set(0, 0, 0, false);
  EXPECT_TRUE(has_line(m.check_invariants(), "coarse tier is not the OR of the fine tier"));
}

TEST(SceneModel, CheckInvariantsCatchesMissingBlocksAndMlps) {
  SceneModel m = valid_model();
  m.block_fine_index.pop_back();
  m.features_f32.resize(kBlockVerts * 2);
  m.finalize();
  EXPECT_EQ(m.check_invariants(), std::vector<std::string>{"1 occupied fine voxels have no feature block"});
  m = valid_model();
  m.mlp_coarse_index.clear();
  m.mlps_f32.clear();
  m.finalize();
  EXPECT_EQ(m.check_invariants(), std::vector<std::string>{"1 occupied coarse voxels have no MLP"});
  // Without finalize() there are no lookups: every occupied voxel counts as missing.
  m = valid_model();
  m.fine_to_block.clear();
  EXPECT_TRUE(has_line(m.check_invariants(), "2 occupied fine voxels have no feature block"));
}

TEST(SceneModel, CheckInvariantsCatchesMicroVoxelsOutsideTheAabb) {
  SceneModel m = valid_model();
  m.object_aabb.lo.x = 6.f;  // voxel (5,5,5) spans [5, 6]: touching the face only is outside
  EXPECT_EQ(m.check_invariants(), std::vector<std::string>{"1 occupied micro voxels lie outside the object AABB"});
  m.object_aabb.lo.x = 5.5f;  // overlaps half of it: inside
  EXPECT_TRUE(m.check_invariants().empty());
  m.object_aabb.hi.y = 5.f;  // both voxels now lie above the box in y
  EXPECT_EQ(m.check_invariants(), std::vector<std::string>{"2 occupied micro voxels lie outside the object AABB"});
}

}  // namespace
}  // namespace edrnr
