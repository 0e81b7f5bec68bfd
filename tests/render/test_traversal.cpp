#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "model/procedural.h"
#include "render/traversal.h"

namespace edrnr {
namespace {

// The samples of a ray straight from the sampling rule: every candidate k up
// to t = t_max, its point from MicroRay::point, kept iff in an occupied voxel.
std::vector<int64_t> samples_by_definition(const SceneModel& m, const MicroRay& r, double t_max) {
  std::vector<int64_t> ks;
  const Bitmap3& micro = m.occupancy[int(Tier::Micro)];
  for (int64_t k = 0; r.t_of(k) <= t_max; ++k) {
    Vec3i v;
    if (micro_voxel_of(r.point(k), m.micro_res, v) && micro.get(v.x, v.y, v.z)) ks.push_back(k);
  }
  return ks;
}

std::vector<int64_t> march(const SceneModel& m, const Ray& ray, const MicroRay& r, bool tiers, uint64_t* checks) {
  SampleMarcher sm(m, ray, r, tiers);
  std::vector<int64_t> ks;
  MarchSample s;
  const Bitmap3& micro = m.occupancy[int(Tier::Micro)];
  while (sm.next(s)) {
    ks.push_back(s.k);
    EXPECT_TRUE(micro.get(s.voxel.x, s.voxel.y, s.voxel.z));
    EXPECT_EQ(s.p_micro, r.point(s.k));
  }
  if (checks) *checks = sm.occupancy_checks();
  return ks;
}

TEST(Traversal, SpacingAndMicroRay) {
  SceneModel m;
  m.micro_res = 64;
  EXPECT_FLOAT_EQ(sample_spacing(m, 1.f), 3.f / 64);
  EXPECT_FLOAT_EQ(sample_spacing(m, 0.5f), 1.5f / 64);
  // Origin at the box corner's far side: (1.5, -1.5, 0) is micro (64, 0, 32).
  const MicroRay r = make_micro_ray(m, Ray{{1.5, -1.5, 0}, {-1, 0, 0}}, 3.f / 64);
  EXPECT_EQ(r.origin, (Vec3f{64, 0, 32}));
  EXPECT_FLOAT_EQ(r.dir.x, -64.f / 3);
  EXPECT_FLOAT_EQ(r.t_of(0), 1.5f / 64);
  // Candidate k sits k + 0.5 micro voxels along -x.
  EXPECT_FLOAT_EQ(r.point(0).x, 63.5f);
  EXPECT_FLOAT_EQ(r.point(10).x, 53.5f);
}

// The tiered march and the plain march yield exactly the candidates the
// definition gives, for random rays, rays inside the box, and rays that run
// along grid planes (where float rounding decides between two voxels).
TEST(Traversal, TieredMarchFindsExactlyTheDefinedSamples) {
  ProceduralOptions o;
  o.micro_res = 64;
  const SceneModel m = make_procedural_model("several", procedural_shapes("several"), o);
  std::mt19937 rng(12345);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const float delta = sample_spacing(m, 1.f);
  uint64_t tier_checks = 0, plain_checks = 0;
  size_t total = 0;
  for (int i = 0; i < 600; ++i) {
    Ray ray;
    if (i < 300) {  // from outside towards a random point in the box
      const Vec3d from = normalize(Vec3d{u(rng), u(rng), u(rng)}) * 4.0;
      ray = {from, normalize(Vec3d{u(rng), u(rng), u(rng)} * 1.2 - from)};
    } else if (i < 450) {  // from inside the box
      ray = {Vec3d{u(rng), u(rng), u(rng)} * 1.4, normalize(Vec3d{u(rng), u(rng), u(rng)})};
    } else {  // on a micro grid plane, along or nearly along an axis
      const int plane = int((u(rng) + 1) * 32);
      const double x = -1.5 + plane * (3.0 / 64);
      Vec3d d{0, 1, 0};
      if (i % 3 == 1) d = normalize(Vec3d{1e-7, 1, 0.3});
      if (i % 3 == 2) d = normalize(Vec3d{0, u(rng), 1});
      ray = {Vec3d{x, -3, u(rng)}, d};
      if (i % 3 == 2) ray.origin = {x, u(rng), -3};
    }
    const MicroRay r = make_micro_ray(m, ray, delta);
    const std::vector<int64_t> expected = samples_by_definition(m, r, 10.0);
    uint64_t c1 = 0, c2 = 0;
    EXPECT_EQ(march(m, ray, r, true, &c1), expected) << "ray " << i;
    EXPECT_EQ(march(m, ray, r, false, &c2), expected) << "ray " << i;
    tier_checks += c1;
    plain_checks += c2;
    total += expected.size();
  }
  EXPECT_GT(total, 1000u);
  EXPECT_LT(tier_checks, plain_checks);
}

TEST(Traversal, RayBehindTheCameraHasNoSamples) {
  ProceduralOptions o;
  o.micro_res = 32;
  const SceneModel m = make_procedural_model("sphere", procedural_shapes("sphere"), o);
  const Ray away{{0, 0, 3}, {0, 0, 1}};
  const MicroRay r = make_micro_ray(m, away, sample_spacing(m, 1.f));
  EXPECT_TRUE(march(m, away, r, true, nullptr).empty());
  EXPECT_TRUE(march(m, away, r, false, nullptr).empty());
  // Straight through the centre: samples in increasing k, as many as the definition has.
  const Ray through{{0, 0, 3}, {0, 0, -1}};
  const MicroRay rt = make_micro_ray(m, through, sample_spacing(m, 1.f));
  const auto ks = march(m, through, rt, true, nullptr);
  EXPECT_EQ(ks, samples_by_definition(m, rt, 10.0));
  EXPECT_TRUE(std::is_sorted(ks.begin(), ks.end()));
  // The sphere covers micro z 5..26 along the axis: 22 voxels, one candidate each.
  EXPECT_EQ(ks.size(), 22u);
}

}  // namespace
}  // namespace edrnr
