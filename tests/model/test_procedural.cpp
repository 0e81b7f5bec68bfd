#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <numbers>

#include "core/error.h"
#include "model/mlp.h"
#include "model/procedural.h"

namespace edrnr {
namespace {

Shape sphere(Vec3f c, float r) {
  Shape s;
  s.center = c;
  s.radius = r;
  return s;
}

Shape torus(Vec3f c, float ring, float tube) {
  Shape s;
  s.kind = ShapeKind::Torus;
  s.center = c;
  s.radius = ring;
  s.tube_radius = tube;
  return s;
}

Shape box(Vec3f c, Vec3f h) {
  Shape s;
  s.kind = ShapeKind::Box;
  s.center = c;
  s.half_size = h;
  return s;
}

ProceduralOptions small(int res = 32) {
  ProceduralOptions o;
  o.micro_res = res;
  return o;
}

TEST(Procedural, SignedDistances) {
  EXPECT_FLOAT_EQ(shape_distance(sphere({0, 0, 0}, 1), {2, 0, 0}), 1.f);
  EXPECT_FLOAT_EQ(shape_distance(sphere({1, 1, 1}, 0.5f), {1, 1, 1}), -0.5f);
  const Shape b = box({0, 0, 0}, {1, 1, 1});
  EXPECT_FLOAT_EQ(shape_distance(b, {2, 2, 0}), std::sqrt(2.f));
  EXPECT_FLOAT_EQ(shape_distance(b, {0, 0, 0}), -1.f);
  EXPECT_FLOAT_EQ(shape_distance(b, {0.5f, 0.25f, 0}), -0.5f);
  const Shape t = torus({0, 0, 0}, 1, 0.25f);
  EXPECT_FLOAT_EQ(shape_distance(t, {1, 0, 0}), -0.25f);
  EXPECT_FLOAT_EQ(shape_distance(t, {0, 0, 0}), 0.75f);
  EXPECT_FLOAT_EQ(shape_distance(t, {0, 1, 1}), 0.75f);
}

TEST(Procedural, ExactOverlapTests) {
  const Shape s = sphere({0, 0, 0}, 1);
  EXPECT_TRUE(shape_overlaps_box(s, {{0.6f, 0.6f, -0.1f}, {1, 1, 0.1f}}));     // nearest point at 0.85
  EXPECT_FALSE(shape_overlaps_box(s, {{0.75f, 0.75f, -0.1f}, {1, 1, 0.1f}}));  // 1.06: boxes' AABBs do overlap
  EXPECT_TRUE(shape_overlaps_box(s, {{-0.1f, -0.1f, -0.1f}, {0.1f, 0.1f, 0.1f}}));
  const Shape t = torus({0, 0, 0}, 1, 0.25f);
  EXPECT_FALSE(shape_overlaps_box(t, {{-0.2f, -0.2f, -0.2f}, {0.2f, 0.2f, 0.2f}}));  // in the hole
  EXPECT_TRUE(shape_overlaps_box(t, {{0.9f, -0.1f, 0.2f}, {1.1f, 0.1f, 0.3f}}));     // 0.2 above the ring
  EXPECT_FALSE(shape_overlaps_box(t, {{0.9f, -0.1f, 0.26f}, {1.1f, 0.1f, 0.3f}}));
  EXPECT_FALSE(shape_overlaps_box(t, {{0.7f, -0.01f, -0.01f}, {0.74f, 0.01f, 0.01f}}));  // rho <= 0.7401
  EXPECT_TRUE(shape_overlaps_box(t, {{0.7f, -0.01f, -0.01f}, {0.76f, 0.01f, 0.01f}}));
  const Shape b = box({0, 0, 0}, {0.5f, 0.5f, 0.5f});
  EXPECT_TRUE(shape_overlaps_box(b, {{0.5f, 0.5f, 0.5f}, {1, 1, 1}}));  // touching corners: closed sets
  EXPECT_FALSE(shape_overlaps_box(b, {{0.51f, 0, 0}, {1, 1, 1}}));
}

// The overlap test agrees with the signed distance sampled densely over boxes:
// a box that overlaps has a point within half a sample diagonal of the solid,
// and a box that does not has no sample inside it.
TEST(Procedural, OverlapAgreesWithDenseSampling) {
  const std::vector<Shape> shapes = {sphere({0.1f, -0.2f, 0.05f}, 0.6f), torus({0.f, 0.1f, -0.1f}, 0.55f, 0.2f),
                                     box({-0.1f, 0.2f, 0.f}, {0.3f, 0.5f, 0.2f})};
  const float h = 0.15f;  // box edge
  const int n = 10;       // samples per edge
  const float slack = 0.5f * std::sqrt(3.f) * h / float(n - 1);
  int overlaps = 0, disjoint = 0;
  for (const Shape& s : shapes)
    for (int z = -7; z < 7; ++z)
      for (int y = -7; y < 7; ++y)
        for (int x = -7; x < 7; ++x) {
          const Vec3f lo{x * h + 0.013f, y * h - 0.007f, z * h + 0.004f};
          const Box3f b{lo, lo + Vec3f{h, h, h}};
          float best = INFINITY;
          for (int k = 0; k < n; ++k)
            for (int j = 0; j < n; ++j)
              for (int i = 0; i < n; ++i)
                best = std::min(best, shape_distance(s, lo + Vec3f{float(i), float(j), float(k)} * (h / (n - 1))));
          if (shape_overlaps_box(s, b)) {
            ++overlaps;
            EXPECT_LE(best, slack + 1e-5f) << shape_kind_name(s.kind) << " " << x << "," << y << "," << z;
          } else {
            ++disjoint;
            EXPECT_GT(best, 0.f) << shape_kind_name(s.kind) << " " << x << "," << y << "," << z;
          }
        }
  EXPECT_GT(overlaps, 100);
  EXPECT_GT(disjoint, 100);
}

TEST(Procedural, SphereModelIsValidAndTight) {
  const SceneModel m = make_procedural_model("sphere", {sphere({0, 0, 0}, 1)}, small());
  EXPECT_TRUE(m.check_invariants().empty());
  EXPECT_EQ(m.block_count(), m.occupancy[int(Tier::Fine)].count());
  EXPECT_EQ(m.mlp_count(), m.occupancy[int(Tier::Coarse)].count());
  EXPECT_EQ(m.mlps_f32.size(), m.mlp_count());
  EXPECT_EQ(m.mlps_q8.size(), m.mlp_count());
  EXPECT_EQ(m.features_q4.size(), m.block_count() * kBlockVerts * 16 / 2);
  // Voxel edge h = 3/32 = 0.09375. The sphere spans micro voxels 5..26
  // (floor(0.5 / h) = 5, floor(2.5 / h) = 26), so the AABB is
  // [-1.5 + 5h, -1.5 + 27h] = [-1.03125, 1.03125] on each axis.
  for (int a = 0; a < 3; ++a) {
    EXPECT_FLOAT_EQ(m.object_aabb.lo[a], -1.03125f);
    EXPECT_FLOAT_EQ(m.object_aabb.hi[a], 1.03125f);
  }
  // The occupied voxels cover the sphere and lie within radius r + sqrt(3) h.
  const double h = 3.0 / 32, r = 1.0;
  const double n = double(m.occupancy[int(Tier::Micro)].count());
  EXPECT_GE(n * h * h * h, 4.0 / 3 * std::numbers::pi * r * r * r);
  EXPECT_LE(n * h * h * h, 4.0 / 3 * std::numbers::pi * std::pow(r + std::sqrt(3.0) * h, 3));
}

TEST(Procedural, FeaturesEncodeDensityAndColour) {
  Shape s = sphere({0, 0, 0}, 1);
  s.sigma = 20.f;
  s.color = {0.8f, 0.3f, 0.2f};
  const SceneModel m = make_procedural_model("sphere", {s}, small());
  // The sphere centre is micro (16, 16, 16): vertex 0 of the block of fine voxel (4, 4, 4).
  const int32_t b = m.fine_to_block[linear_index(4, 4, 4, m.fine_res())];
  ASSERT_GE(b, 0);
  EXPECT_NEAR(m.feature(size_t(b), 0, 0), 2.9957323f, 1e-5f);   // log 20
  EXPECT_NEAR(m.feature(size_t(b), 0, 1), 1.3862944f, 1e-5f);   // logit 0.8 = log 4
  EXPECT_NEAR(m.feature(size_t(b), 0, 2), -0.8472979f, 1e-5f);  // logit 0.3
  EXPECT_NEAR(m.feature(size_t(b), 0, 3), -1.3862944f, 1e-5f);  // logit 0.2
  for (int c = 4; c < 16; ++c) EXPECT_EQ(m.feature(size_t(b), 0, c), 0.f);
  // Every stored vertex farther than r from the centre is empty, every one
  // nearer holds log(sigma).
  size_t empty = 0, full = 0;
  for (size_t blk = 0; blk < m.block_count(); ++blk) {
    const uint32_t fi = m.block_fine_index[blk];
    const int fx = int(fi % 8), fy = int(fi / 8 % 8), fz = int(fi / 64);
    for (int v = 0; v < kBlockVerts; ++v) {
      const Vec3f p = Vec3f{float(4 * fx + v % 5), float(4 * fy + v / 5 % 5), float(4 * fz + v / 25)} * (3.f / 32) -
                      Vec3f{1.5f, 1.5f, 1.5f};
      const float d = length(p);
      if (d > 1.0001f) {
        ++empty;
        EXPECT_EQ(m.feature(blk, v, 0), kEmptyRawDensity);
      } else if (d < 0.9999f) {
        ++full;
        EXPECT_NEAR(m.feature(blk, v, 0), std::log(20.f), 1e-5f);
      }
      EXPECT_NEAR(m.feature(blk, v, 1), std::log(4.f), 1e-5f);  // colour is the same everywhere
    }
  }
  EXPECT_GT(empty, 0u);
  EXPECT_GT(full, 0u);
}

TEST(Procedural, MlpsPassTheFeaturesThrough) {
  const SceneModel m = make_procedural_model("box", procedural_shapes("box"), small());
  ASSERT_GT(m.mlp_count(), 0u);
  std::vector<float> f(16, 0.f);
  f[0] = 2.5f;
  f[1] = -1.f;
  f[2] = 0.f;
  f[3] = 3.f;
  f[7] = 9.f;  // unused channels do not matter
  float dir[15];
  encode_direction(normalize(Vec3f{0.3f, -0.5f, 0.8f}), 2, dir);
  const MlpOutput o = eval_mlp(m.mlp_arch, m.mlps_f32[0], f.data(), dir);
  EXPECT_EQ(o.raw_sigma, 2.5f);
  EXPECT_NEAR(o.rgb[0], 1 / (1 + std::exp(1.f)), 1e-6f);
  EXPECT_NEAR(o.rgb[1], 0.5f, 1e-6f);
  EXPECT_NEAR(o.rgb[2], 1 / (1 + std::exp(-3.f)), 1e-6f);
  // The INT8 MLP is exact: +-64 with scale 1/64.
  EXPECT_EQ(dequantize_mlp(m.mlps_q8[0]), m.mlps_f32[0]);
  for (const DenseQ& d : m.mlps_q8[0].density) {
    for (int8_t w : d.w) EXPECT_TRUE(w == 0 || w == 64 || w == -64);
    EXPECT_GT(d.in_scale, 0.f);
  }
  EXPECT_LE(m.mlp_arch.q8_bytes(), kMlpCacheBytes);
}

TEST(Procedural, FieldTakesTheNearestShape) {
  Shape a = sphere({-0.5f, 0, 0}, 0.3f);
  a.color = {1, 0, 0};
  a.sigma = 5;
  Shape b = sphere({0.5f, 0, 0}, 0.3f);
  b.color = {0, 0, 1};
  b.sigma = 7;
  const std::vector<Shape> shapes = {a, b};
  EXPECT_EQ(procedural_field(shapes, {-0.5f, 0, 0}).sigma, 5.f);
  EXPECT_EQ(procedural_field(shapes, {0.6f, 0.1f, 0}).sigma, 7.f);
  const FieldSample between = procedural_field(shapes, {0.1f, 0, 0});  // outside both, nearer b
  EXPECT_EQ(between.sigma, 0.f);
  EXPECT_EQ(between.color, (Vec3f{0, 0, 1}));
}

TEST(Procedural, NamedScenesAreValid) {
  for (const std::string& name : procedural_scene_names()) {
    const SceneModel m = make_procedural_model(name, procedural_shapes(name), small());
    EXPECT_TRUE(m.check_invariants().empty()) << name;
    EXPECT_GT(m.block_count(), 0u) << name;
    const auto meta = nlohmann::json::parse(m.metadata_json);
    EXPECT_EQ(meta["scene"], name);
    EXPECT_EQ(meta["shapes"].size(), procedural_shapes(name).size());
  }
  EXPECT_EQ(procedural_shapes("several").size(), 4u);
  const auto meta =
      nlohmann::json::parse(make_procedural_model("sphere", {sphere({0, 0, 0}, 1)}, small()).metadata_json);
  EXPECT_EQ(meta["shapes"][0]["kind"], "sphere");
  EXPECT_EQ(meta["shapes"][0]["radius"], 1.0);
  EXPECT_EQ(meta["micro_res"], 32);
}

TEST(Procedural, TorusHoleIsEmpty) {
  const SceneModel m = make_procedural_model("torus", {torus({0, 0, 0}, 0.9f, 0.3f)}, small());
  EXPECT_TRUE(m.check_invariants().empty());
  // Micro voxels around the centre (16, 16, 16) are in the hole (rho < 0.6 - h*sqrt 2).
  const Bitmap3& micro = m.occupancy[int(Tier::Micro)];
  for (int z = 14; z < 18; ++z)
    for (int y = 14; y < 18; ++y)
      for (int x = 14; x < 18; ++x) EXPECT_FALSE(micro.get(x, y, z));
  // The ring passes through (0.9, 0, 0): micro x = floor(2.4 / h) = 25, y = z = 16 (and 15).
  EXPECT_TRUE(micro.get(25, 16, 16));
  EXPECT_TRUE(micro.get(25, 15, 15));
  // z extent: |z| <= 0.3 covers micro 12..19 (floor(1.2 / h) = 12, floor(1.8 / h) = 19).
  EXPECT_FLOAT_EQ(m.object_aabb.lo.z, -1.5f + 12 * 0.09375f);
  EXPECT_FLOAT_EQ(m.object_aabb.hi.z, -1.5f + 20 * 0.09375f);
}

TEST(Procedural, SeedFillsUnusedChannelsConsistently) {
  ProceduralOptions o = small();
  o.seed = 7;
  const SceneModel m = make_procedural_model("sphere", {sphere({0, 0, 0}, 1)}, o);
  // Fine voxels (4,4,4) and (5,4,4) share the vertex at micro (20, 16, 16).
  const int32_t a = m.fine_to_block[linear_index(4, 4, 4, 8)], b = m.fine_to_block[linear_index(5, 4, 4, 8)];
  ASSERT_GE(a, 0);
  ASSERT_GE(b, 0);
  bool nonzero = false;
  for (int c = 4; c < 16; ++c) {
    const float va = m.feature(size_t(a), 4, c), vb = m.feature(size_t(b), 0, c);
    EXPECT_EQ(va, vb);
    EXPECT_GE(va, -1.f);
    EXPECT_LT(va, 1.f);
    nonzero |= va != 0.f;
  }
  EXPECT_TRUE(nonzero);
  // Channels 0..3 do not depend on the seed.
  const SceneModel z = make_procedural_model("sphere", {sphere({0, 0, 0}, 1)}, small());
  for (int c = 0; c < 4; ++c) EXPECT_EQ(m.feature(size_t(a), 62, c), z.feature(size_t(a), 62, c));
}

TEST(Procedural, QuantizedOnlyAndEmptyModels) {
  ProceduralOptions o = small();
  o.store_float = false;
  const SceneModel q = make_procedural_model("sphere", {sphere({0, 0, 0}, 1)}, o);
  EXPECT_TRUE(q.features_f32.empty());
  EXPECT_TRUE(q.mlps_f32.empty());
  EXPECT_FALSE(q.features_q4.empty());
  EXPECT_EQ(q.mlps_q8.size(), q.mlp_count());

  const SceneModel e = make_procedural_model("outside", {sphere({5, 5, 5}, 1)}, small());
  EXPECT_EQ(e.block_count(), 0u);
  EXPECT_EQ(e.mlp_count(), 0u);
  EXPECT_EQ(e.occupancy[int(Tier::Micro)].count(), 0u);
  EXPECT_TRUE(e.check_invariants().empty());
}

TEST(Procedural, BadParametersAreErrors) {
  EXPECT_THROW(procedural_shapes("cube"), Error);
  ProceduralOptions o = small();
  o.feature_channels = 3;
  EXPECT_THROW(make_procedural_model("sphere", {sphere({0, 0, 0}, 1)}, o), Error);
  o = small(48);  // not a multiple of 32
  EXPECT_THROW(make_procedural_model("sphere", {sphere({0, 0, 0}, 1)}, o), Error);
  try {
    make_procedural_model("sphere", {sphere({0, 0, 0}, -1)}, small());
    FAIL() << "negative radius accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("radius"), std::string::npos) << e.what();
  }
  Shape s = sphere({0, 0, 0}, 1);
  s.sigma = 0;
  EXPECT_THROW(validate_shape(s, "s"), Error);
  s.sigma = 1;
  s.color = {1.5f, 0, 0};
  EXPECT_THROW(validate_shape(s, "s"), Error);
}

}  // namespace
}  // namespace edrnr
