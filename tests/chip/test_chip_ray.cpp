#include <gtest/gtest.h>

#include <random>

#include "chip/abt.h"
#include "chip/chip_ray.h"
#include "chip/numerics.h"
#include "chip/tsps.h"

namespace edrnr::chip {
namespace {

const FloatFormat kTraversal = ChipNumerics{}.traversal_float;

TEST(RayMath, AxisAlignedRayByHand) {
  // o = (0.25, 10.5, 10.5), d = +x, step 1: t_k = k + 0.5, p_k.x = k + 0.75,
  // so candidate k lies in micro voxel x = k.
  RayMath m(kTraversal, 1.0, 64);
  ChipRay r{{0.25, 10.5, 10.5}, {1, 0, 0}};
  EXPECT_EQ(m.point(r, 0), (Vec3d{0.75, 10.5, 10.5}));
  EXPECT_EQ(m.micro_voxel(m.point(r, 5)), (Vec3i{5, 10, 10}));
  EXPECT_EQ(m.cell_exit(r, 0, 100, {0, 10, 10}, 1), 1);
  EXPECT_EQ(m.cell_exit(r, 0, 100, {0, 2, 2}, 4), 4);    // fine cell: x < 4
  EXPECT_EQ(m.cell_exit(r, 5, 100, {0, 0, 0}, 32), 32);  // CV: x < 32
  EXPECT_EQ(m.cell_exit(r, 5, 20, {0, 0, 0}, 32), 20);   // the box ends first
  // The last cell along an axis is only left through the box end.
  EXPECT_EQ(m.cell_exit(r, 40, 64, {1, 0, 0}, 32), 64);
  // Box [10, 20]: first candidate at x >= 10 is k = 10 (10.75); first past 20 is k = 20 (20.75).
  KInterval iv = m.box_interval(r, {10, 0, 0}, {20, 64, 64});
  EXPECT_EQ(iv.begin, 10);
  EXPECT_EQ(iv.end, 20);
  // A box the ray passes beside: y = 10.5 is outside [11, 20].
  EXPECT_TRUE(m.box_interval(r, {10, 11, 0}, {20, 20, 64}).empty());
}

TEST(RayMath, CandidateDistancesMatchTheFormatArithmeticBeyondTheTable) {
  // t_k = round(round(k + 0.5) * step), computed here with the format alone,
  // for k inside the table RayMath fills (16 Rm / step + 2 entries), across
  // its end and far past it.
  for (double step : {1.0, 0.37, 2.5}) {
    RayMath m(kTraversal, step, 64);
    const double s = kTraversal.round(step);
    auto expected = [&](int64_t k) { return kTraversal.mul(kTraversal.round(double(k) + 0.5), s); };
    const int64_t table_end = int64_t(16.0 * 64 / s + 2.0);
    for (int64_t k = 0; k < table_end + 64; ++k) ASSERT_EQ(m.t_of(k), expected(k)) << "step " << step << " k " << k;
    for (int64_t k : {int64_t(1) << 20, kMaxCandidate - 1, kMaxCandidate})
      EXPECT_EQ(m.t_of(k), expected(k)) << "step " << step << " k " << k;
  }
}

TEST(RayMath, HalfStepsAndNegativeDirection) {
  // d = -y, step 0.5: t_k = 0.5 k + 0.25, p_k.y = 30 - 0.5 k - 0.25.
  RayMath m(kTraversal, 0.5, 64);
  ChipRay r{{5.5, 30.0, 5.5}, {0, -1, 0}};
  EXPECT_EQ(m.coord(r, 3, 1), 28.25);
  // Micro voxel y = 29 holds p in [29, 30): k = 0 (29.75) and 1 (29.25); k = 2 is 28.75.
  EXPECT_EQ(m.cell_exit(r, 0, 1000, {5, 29, 5}, 1), 2);
  // Fine cell y = 7 is [28, 32): p >= 28 up to k = 3 (28.25), k = 4 is 27.75.
  EXPECT_EQ(m.cell_exit(r, 0, 1000, {1, 7, 1}, 4), 4);
  // Leaving the grid through y = 0: the last candidate with p >= 0 is k = 59 (0.25).
  KInterval iv = m.box_interval(r, {0, 0, 0}, {64, 64, 64});
  EXPECT_EQ(iv.begin, 0);
  EXPECT_EQ(iv.end, 60);
}

// Random rays from outside the grid towards it, in the chip's format.
std::vector<ChipRay> random_rays(const FloatFormat& f, int n, uint32_t seed, double res) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<ChipRay> rays;
  for (int i = 0; i < n; ++i) {
    Vec3d o{u(rng), u(rng), u(rng)};
    o = o * (1.6 * res / length(o)) + Vec3d{res / 2, res / 2, res / 2};
    Vec3d target{res / 2 + u(rng) * res / 2, res / 2 + u(rng) * res / 2, res / 2 + u(rng) * res / 2};
    Vec3d d = normalize(target - o);
    if (i % 7 == 0) d.y = 0;  // some rays in an axis plane
    rays.push_back({f.round(o), f.round(normalize(d))});
  }
  return rays;
}

// Brute force: walk every candidate of the box run and check each reported
// cell exit and the box run itself.
void check_against_brute_force(const FloatFormat& f, double step, int res) {
  RayMath m(f, step, res);
  int checked = 0;
  for (const ChipRay& r : random_rays(f, 60, 11, res)) {
    const Vec3d lo{0, 0, 0}, hi{double(res), double(res), double(res)};
    const KInterval iv = m.box_interval(r, lo, hi);
    // The run is exactly the candidates inside the closed box.
    auto inside = [&](int64_t k) {
      Vec3d p = m.point(r, k);
      return p.x >= 0 && p.y >= 0 && p.z >= 0 && p.x <= res && p.y <= res && p.z <= res;
    };
    const int64_t limit = int64_t(8 * res / step);
    int64_t first = -1, end = -1;
    for (int64_t k = 0; k < limit; ++k) {
      if (inside(k) && first < 0) first = k;
      if (first >= 0 && !inside(k)) {
        end = k;
        break;
      }
    }
    if (first < 0) {
      EXPECT_TRUE(iv.empty());
      continue;
    }
    ASSERT_EQ(iv.begin, first);
    ASSERT_EQ(iv.end, end);
    // Monotone coordinates, and exact exits at every tier.
    for (int cell : {1, 2, 4, 32}) {
      int64_t k = iv.begin;
      while (k < iv.end) {
        const Vec3i c = m.cell_at(r, k, cell);
        int64_t brute = k + 1;
        while (brute < iv.end && m.cell_at(r, brute, cell) == c) ++brute;
        ASSERT_EQ(m.cell_exit(r, k, iv.end, c, cell), brute) << "cell size " << cell << " k " << k;
        k = brute;
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 1000);
}

TEST(RayMath, ExitsAndBoxRunsMatchBruteForce) {
  check_against_brute_force(kTraversal, 1.0, 64);
  check_against_brute_force(kTraversal, 0.37, 32);
  check_against_brute_force(FloatFormat(), 0.5, 64);                                       // binary32
  check_against_brute_force(FloatFormat(8, 11, false, FloatSpecials::Saturate), 1.0, 32);  // coarse format
}

TEST(AbtTsps, DropsOnlyRaysWithoutCandidates) {
  const FloatFormat f = kTraversal;
  RayMath m(f, 1.0, 64);
  const Vec3d lo{20, 20, 20}, hi{40, 44, 36};
  Abt abt(lo, hi, ChipNumerics{}.ray_float);
  Tsps tsps(m, lo, hi);
  // By hand: a ray along +x at y = z = 30 hits, one at y = 50 misses, one
  // pointing away misses, one along an axis outside the slab misses.
  EXPECT_TRUE(abt.hits({{0, 30, 30}, {1, 0, 0}}));
  EXPECT_FALSE(abt.hits({{0, 50, 30}, {1, 0, 0}}));
  EXPECT_FALSE(abt.hits({{0, 30, 30}, {-1, 0, 0}}));
  EXPECT_FALSE(abt.hits({{30, 30, 50}, {0, 1, 0}}));
  KInterval iv = tsps.search({{0, 30, 30}, {1, 0, 0}});
  EXPECT_EQ(iv.begin, 20);  // x = 20.5
  EXPECT_EQ(iv.end, 40);    // x = 40.5 is past 40
  // Every ray the ABT drops has no candidate in the box.
  int dropped = 0, kept_empty = 0;
  for (const ChipRay& r : random_rays(f, 400, 5, 64)) {
    const bool hit = abt.hits(r);
    const KInterval run = tsps.search(r);
    if (!hit) {
      ++dropped;
      EXPECT_TRUE(run.empty());
    }
    kept_empty += hit && run.empty();
  }
  // Only grazing rays (within the one-voxel margin) pass the ABT without a candidate.
  EXPECT_GT(dropped, 50);
  EXPECT_LT(5 * kept_empty, dropped + kept_empty);
}

}  // namespace
}  // namespace edrnr::chip
