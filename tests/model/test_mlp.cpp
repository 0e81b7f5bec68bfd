#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"
#include "model/mlp.h"

namespace edrnr {
namespace {

DenseF layer(int in, int out, std::vector<float> w, std::vector<float> b) {
  DenseF d;
  d.in = in;
  d.out = out;
  d.w = std::move(w);
  d.b = std::move(b);
  return d;
}

float sigmoid(double x) { return float(1.0 / (1.0 + std::exp(-x))); }

TEST(Mlp, DefaultArchFitsTheMlpCache) {
  const MlpArch a = default_mlp_arch(16);
  EXPECT_EQ(a.density_widths, (std::vector<int>{16, 16, 8}));
  EXPECT_EQ(a.color_widths, (std::vector<int>{23, 16, 3}));  // 8 + 3 + 6*2
  EXPECT_EQ(a.dir_frequencies, 2);
  // Weights 16*16 + 16*8 + 23*16 + 16*3 = 800; biases 16+8+16+3 = 43.
  EXPECT_EQ(a.q8_bytes(), 800u + 8u * 43u + 4u * 18u);
  EXPECT_EQ(a.q8_bytes(), 1216u);
  EXPECT_EQ(kMlpCacheBytes / a.q8_bytes(), 6u);  // six MLPs fit the MLP cache
}

TEST(Mlp, EncodeDirectionValues) {
  float e[15];
  encode_direction({1.f, 0.f, 0.f}, 2, e);
  const float expected[15] = {1, 0, 0, std::sin(1.f), 0, 0, std::cos(1.f), 1, 1, std::sin(2.f), 0, 0, std::cos(2.f),
                              1, 1};
  for (int i = 0; i < 15; ++i) EXPECT_FLOAT_EQ(e[i], expected[i]) << i;

  // 0.6, 0, 0.8: sin(0.6) = 0.5646425, cos(1.6) = -0.0291995, sin(1.6) = 0.9995736.
  encode_direction({0.6f, 0.f, 0.8f}, 2, e);
  EXPECT_NEAR(e[3], 0.5646425f, 1e-6f);
  EXPECT_NEAR(e[9 + 5], -0.0291995f, 1e-6f);  // k = 1, cos(2 * 0.8)
  EXPECT_NEAR(e[9 + 2], 0.9995736f, 1e-6f);   // k = 1, sin(2 * 0.8)
  EXPECT_FLOAT_EQ(e[0], 0.6f);
  EXPECT_FLOAT_EQ(e[2], 0.8f);

  float three[3];
  encode_direction({0.f, -1.f, 0.f}, 0, three);
  EXPECT_EQ(three[1], -1.f);
}

// density [2, 2, 2], colour [2 + 3, 2, 3] with L = 0, computed by hand.
TEST(Mlp, ForwardMatchesHandComputedNetwork) {
  MlpArch arch;
  arch.density_widths = {2, 2, 2};
  arch.color_widths = {5, 2, 3};
  arch.dir_frequencies = 0;
  MlpF m;
  m.density.push_back(layer(2, 2, {1, -1, 0.5f, 2}, {0, -1}));
  m.density.push_back(layer(2, 2, {1, 1, -1, 0.5f}, {0.5f, 0}));
  m.color.push_back(layer(5, 2, {0.2f, 0, 0, 0, 1, -1, 0, 0, 0, 0}, {0, 1}));
  m.color.push_back(layer(2, 3, {1, 0, 0, 1, -1, 0}, {0, 0.3f, 0.2f}));
  const float feature[2] = {2, 1};
  const float dir[3] = {0, 0, 1};
  // hidden = relu(2 - 1, 1 + 2 - 1) = (1, 2); geo = (1 + 2 + 0.5, -1 + 1) = (3.5, 0)
  // colour hidden = relu(0.2 * 3.5 + 1, -3.5 + 1) = (1.7, 0); out = (1.7, 0.3, -1.5)
  const MlpOutput o = eval_mlp(arch, m, feature, dir);
  EXPECT_FLOAT_EQ(o.raw_sigma, 3.5f);
  EXPECT_NEAR(o.sigma, std::exp(3.5), 1e-4);
  EXPECT_NEAR(o.rgb[0], sigmoid(1.7), 1e-6);
  EXPECT_NEAR(o.rgb[1], sigmoid(0.3), 1e-6);
  EXPECT_NEAR(o.rgb[2], sigmoid(-1.5), 1e-6);
}

TEST(Mlp, RawDensityIsClampedBeforeExp) {
  MlpArch arch;
  arch.density_widths = {1, 1};
  arch.color_widths = {4, 3};
  arch.dir_frequencies = 0;
  MlpF m;
  m.density.push_back(layer(1, 1, {1}, {0}));
  m.color.push_back(layer(4, 3, std::vector<float>(12, 0.f), {0, 0, 0}));
  const float dir[3] = {1, 0, 0};
  float f = 100.f;
  MlpOutput o = eval_mlp(arch, m, &f, dir);
  EXPECT_EQ(o.raw_sigma, 100.f);
  EXPECT_FLOAT_EQ(o.sigma, std::exp(kRawSigmaMax));
  f = -100.f;
  o = eval_mlp(arch, m, &f, dir);
  EXPECT_FLOAT_EQ(o.sigma, std::exp(kRawSigmaMin));
  EXPECT_FLOAT_EQ(o.rgb[0], 0.5f);  // sigmoid(0)
}

TEST(Mlp, RejectsLayersWiderThanTheEvaluator) {
  MlpArch arch;
  arch.density_widths = {1, kMlpEvalMaxWidth + 1};
  MlpF m;
  m.density.push_back(layer(1, kMlpEvalMaxWidth + 1, std::vector<float>(kMlpEvalMaxWidth + 1, 0.f),
                            std::vector<float>(kMlpEvalMaxWidth + 1, 0.f)));
  m.color.push_back(layer(1, 3, {0, 0, 0}, {0, 0, 0}));
  const float f = 0, dir[3] = {0, 0, 1};
  EXPECT_THROW(eval_mlp(arch, m, &f, dir), Error);
}

TEST(Mlp, DequantizeScalesEachRow) {
  MlpQ q;
  DenseQ d;
  d.in = 2;
  d.out = 2;
  d.w = {2, -3, 4, 5};
  d.w_scale = {0.5f, 0.25f};
  d.b = {0.1f, -0.2f};
  d.in_scale = 0.01f;
  q.density.push_back(d);
  q.color.push_back(d);
  const MlpF f = dequantize_mlp(q);
  ASSERT_EQ(f.density.size(), 1u);
  ASSERT_EQ(f.color.size(), 1u);
  EXPECT_EQ(f.density[0].w, (std::vector<float>{1.f, -1.5f, 1.f, 1.25f}));
  EXPECT_EQ(f.density[0].b, (std::vector<float>{0.1f, -0.2f}));
  EXPECT_EQ(f.color[0].in, 2);
  EXPECT_EQ(f.color[0].out, 2);
}

// A 32^3 model with one block at fine voxel `fine` whose two channels hold
// g0(x, y, z) = 1 + 2x - 3y + 0.5z and g1 = x*y*z at the lattice vertices (micro
// units). Trilinear interpolation reproduces both exactly inside the block.
SceneModel one_block_model(Vec3i fine) {
  SceneModel m;
  m.micro_res = 32;
  m.feature_channels = 2;
  m.init_grids();
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 4; ++j)
      for (int i = 0; i < 4; ++i) m.occupancy[int(Tier::Micro)].set(4 * fine.x + i, 4 * fine.y + j, 4 * fine.z + k);
  m.rebuild_upper_tiers();
  m.block_fine_index = {linear_index(fine.x, fine.y, fine.z, m.fine_res())};
  for (int v = 0; v < kBlockVerts; ++v) {
    const float x = float(4 * fine.x + v % 5), y = float(4 * fine.y + (v / 5) % 5), z = float(4 * fine.z + v / 25);
    m.features_f32.push_back(1 + 2 * x - 3 * y + 0.5f * z);
    m.features_f32.push_back(x * y * z);
  }
  m.finalize();
  return m;
}

TEST(Mlp, InterpolateFeatureIsExactAtVerticesAndTrilinearBetween) {
  const SceneModel m = one_block_model({1, 2, 3});  // micro x 4..8, y 8..12, z 12..16
  float f[2];
  // Vertex (1, 2, 3) of the block: micro (5, 10, 15).
  ASSERT_TRUE(interpolate_feature(m, {5.f, 10.f, 15.f}, f));
  EXPECT_EQ(f[0], 1 + 10 - 30 + 7.5f);
  EXPECT_EQ(f[1], 750.f);
  // Between vertices: 5.5 * 9.25 * 13.75 = 699.53125; 1 + 11 - 27.75 + 6.875 = -8.875.
  ASSERT_TRUE(interpolate_feature(m, {5.5f, 9.25f, 13.75f}, f));
  EXPECT_NEAR(f[0], -8.875f, 1e-4f);
  EXPECT_NEAR(f[1], 699.53125f, 1e-3f);
  // Outside the block (its upper faces belong to the next fine voxel), or
  // outside the grid: no feature, nothing written.
  f[0] = f[1] = -7.f;
  EXPECT_FALSE(interpolate_feature(m, {8.f, 12.f, 16.f}, f));
  EXPECT_FALSE(interpolate_feature(m, {3.99f, 10.f, 15.f}, f));
  EXPECT_FALSE(interpolate_feature(m, {-0.5f, 10.f, 15.f}, f));
  EXPECT_FALSE(interpolate_feature(m, {5.f, 10.f, 32.5f}, f));
  EXPECT_EQ(f[0], -7.f);
}

TEST(Mlp, PointsOnTheUpperSceneFaceClampIntoTheLastVoxel) {
  const SceneModel m = one_block_model({7, 7, 7});  // micro 28..32 on every axis
  float f[2];
  ASSERT_TRUE(interpolate_feature(m, {32.f, 32.f, 32.f}, f));
  EXPECT_EQ(f[1], 32.f * 32.f * 32.f);
  ASSERT_TRUE(interpolate_feature(m, {32.f, 30.5f, 28.f}, f));
  EXPECT_NEAR(f[1], 32.f * 30.5f * 28.f, 1e-2f);
  Vec3i v;
  ASSERT_TRUE(micro_voxel_of({32.f, 0.f, 31.999f}, 32, v));
  EXPECT_EQ(v, (Vec3i{31, 0, 31}));
  EXPECT_FALSE(micro_voxel_of({32.001f, 0.f, 0.f}, 32, v));
  EXPECT_FALSE(micro_voxel_of({NAN, 0.f, 0.f}, 32, v));
}

TEST(Mlp, QuantizedSourceReadsTheInt4Codes) {
  SceneModel m = one_block_model({1, 2, 3});
  m.quantize_features();
  SceneModel q4_only = m;
  q4_only.features_f32.clear();
  float f[2], g[2];
  // At a vertex the quantized lookup equals SceneModel::feature's dequantized code.
  ASSERT_TRUE(interpolate_feature(m, {6.f, 9.f, 13.f}, FeatureSource::Quantized, f));
  const int vertex = 2 + 5 * (1 + 5 * 1);
  EXPECT_EQ(f[0], q4_only.feature(0, vertex, 0));
  EXPECT_EQ(f[1], q4_only.feature(0, vertex, 1));
  // Auto reads INT4 when there are no float features, float otherwise.
  ASSERT_TRUE(interpolate_feature(q4_only, {6.5f, 9.5f, 13.5f}, g));
  ASSERT_TRUE(interpolate_feature(m, {6.5f, 9.5f, 13.5f}, FeatureSource::Quantized, f));
  EXPECT_EQ(f[0], g[0]);
  ASSERT_TRUE(interpolate_feature(m, {6.5f, 9.5f, 13.5f}, f));
  EXPECT_NEAR(f[1], 6.5f * 9.5f * 13.5f, 1e-3f);
  EXPECT_THROW(interpolate_feature(q4_only, {6.f, 9.f, 13.f}, FeatureSource::Float, f), Error);
}

}  // namespace
}  // namespace edrnr
