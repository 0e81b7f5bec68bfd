// CTU + FTU (with the LFAU) against a brute-force walk of every candidate.
#include <gtest/gtest.h>

#include <map>
#include <random>

#include "chip/ctu.h"
#include "chip/ftu.h"
#include "chip/numerics.h"
#include "chip/tsps.h"

namespace edrnr::chip {
namespace {

// A 64^3 model with random blobs of occupied micro voxels (no features: the
// traversal needs only the bitmaps and the block lookup).
SceneModel blob_model() {
  SceneModel m;
  m.micro_res = 64;
  m.init_grids();
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> pos(8, 55), size(1, 6);
  Bitmap3& micro = m.occupancy[int(Tier::Micro)];
  for (int b = 0; b < 150; ++b) {
    const int x0 = pos(rng), y0 = pos(rng), z0 = pos(rng), s = size(rng);
    for (int z = z0; z < z0 + s; ++z)
      for (int y = y0; y < y0 + s; ++y)
        for (int x = x0; x < x0 + s; ++x)
          if ((x + y + z) % 3 != 0) micro.set(x, y, z);  // holes, so micro checks matter
  }
  m.rebuild_upper_tiers();
  const Bitmap3& fine = m.occupancy[int(Tier::Fine)];
  for (size_t i = 0; i < fine.size(); ++i)
    if (fine.get(i)) m.block_fine_index.push_back(uint32_t(i));
  for (size_t i = 0; i < m.occupancy[0].size(); ++i)
    if (m.occupancy[0].get(i)) m.mlp_coarse_index.push_back(uint32_t(i));
  m.finalize();
  return m;
}

// Four nearly parallel rays, as a 2x2 pixel quad would give.
RayPacket make_packet(const RayMath& math, const Vec3d& origin, const Vec3d& dir, double spread, Tsps& tsps) {
  const FloatFormat& f = math.format();
  RayPacket p;
  for (int r = 0; r < 4; ++r) {
    RayState& s = p.rays[size_t(r)];
    Vec3d d = dir + Vec3d{spread * (r & 1), spread * (r >> 1), -spread * (r & 1)};
    s.valid = true;
    s.ray = {f.round(origin), f.round(normalize(d))};
    KInterval iv = tsps.search(s.ray);
    s.k = iv.begin;
    s.k_end = iv.end;
  }
  p.travel_sign = {dir.x < 0 ? -1 : 1, dir.y < 0 ? -1 : 1, dir.z < 0 ? -1 : 1};
  return p;
}

TEST(Traversal, SamplesAreExactlyTheOccupiedCandidates) {
  const SceneModel m = blob_model();
  const RayMath math(ChipNumerics{}.traversal_float, 0.75, m.micro_res);
  const Vec3d lo{0, 0, 0}, hi{64, 64, 64};
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  uint64_t total = 0;
  for (bool lag_first : {true, false}) {
    Ctu ctu(m, math, lag_first);
    Ftu ftu(m, math, lag_first, 16);
    Tsps tsps(math, lo, hi);
    for (int t = 0; t < 60; ++t) {
      Vec3d o = normalize(Vec3d{u(rng), u(rng), u(rng)}) * 100.0 + Vec3d{32, 32, 32};
      Vec3d target{32 + 20 * u(rng), 32 + 20 * u(rng), 32 + 20 * u(rng)};
      RayPacket p = make_packet(math, o, normalize(target - o), t % 2 ? 0.01 : 0.002, tsps);
      // Brute force per ray: every candidate of the box run in an occupied micro voxel.
      std::map<int, std::vector<int64_t>> expect, got;
      for (int r = 0; r < 4; ++r) {
        const RayState& s = p.rays[size_t(r)];
        for (int64_t k = s.k; k < s.k_end; ++k) {
          const Vec3i v = math.micro_voxel(math.point(s.ray, k));
          if (m.occupancy[int(Tier::Micro)].get(v.x, v.y, v.z)) expect[r].push_back(k);
        }
      }
      // The chip's walk: CTU to a CV, FTU batches until the RP leaves it, repeat.
      for (int guard = 0; guard < 10000; ++guard) {
        const CtuResult c = ctu.run(p);
        if (!c.found) break;
        SampleBatch b;
        while (ftu.run(p, 0, c.cv_tag, b)) {
          EXPECT_EQ(b.cv_tag, c.cv_tag);
          const uint32_t fr = uint32_t(m.fine_res());
          const Vec3i f{int(b.fine_index % fr), int(b.fine_index / fr % fr), int(b.fine_index / (fr * fr))};
          for (const SampleRef& s : b.samples) {
            // Each sample lies in the batch's fine voxel.
            EXPECT_EQ(math.cell_at(p.rays[s.ray].ray, s.k, 4), f);
            got[s.ray].push_back(s.k);
          }
        }
      }
      EXPECT_EQ(p.live_mask(), 0);
      EXPECT_EQ(got, expect) << "packet " << t << (lag_first ? " lag first" : "");
      for (auto& [r, ks] : expect) total += ks.size();
    }
    // Rays of one voxel always advance together: between 1 and 4 per iteration.
    EXPECT_GE(ctu.counters().rays_advanced, ctu.counters().iterations);
    EXPECT_LE(ctu.counters().rays_advanced, 4 * ctu.counters().iterations);
    EXPECT_EQ(ctu.counters().coarse_checks, ctu.counters().iterations);
    EXPECT_EQ(ftu.counters().fine_checks, ftu.counters().iterations);
    EXPECT_GT(ftu.counters().micro_word_hits, 0u);
  }
  EXPECT_GT(total, 1000u);
}

TEST(Traversal, MicroWordHoldsTheFineVoxelsMicroBits) {
  const SceneModel m = blob_model();
  const RayMath math(ChipNumerics{}.traversal_float, 1.0, m.micro_res);
  const Ftu ftu(m, math, true);
  const Bitmap3& micro = m.occupancy[int(Tier::Micro)];
  const int fr = m.fine_res();
  int words = 0;
  for (int z = 0; z < fr; ++z)
    for (int y = 0; y < fr; ++y)
      for (int x = 0; x < fr; ++x) {
        const uint64_t w = ftu.micro_word(linear_index(x, y, z, fr));
        for (int b = 0; b < 64; ++b)
          ASSERT_EQ((w >> b) & 1, uint64_t(micro.get(4 * x + b % 4, 4 * y + b / 4 % 4, 4 * z + b / 16)));
        words += w != 0;
      }
  EXPECT_EQ(size_t(words), m.occupancy[int(Tier::Fine)].count());
}

TEST(Traversal, LagFirstKeepsRaysTogether) {
  // The same packets with and without lag-first: lag first advances at least
  // as many rays per coarse iteration on average.
  const SceneModel m = blob_model();
  const RayMath math(ChipNumerics{}.traversal_float, 1.0, m.micro_res);
  double per_iteration[2];
  for (int lag = 0; lag < 2; ++lag) {
    Ctu ctu(m, math, lag == 1);
    Ftu ftu(m, math, lag == 1);
    Tsps tsps(math, {0, 0, 0}, {64, 64, 64});
    std::mt19937 rng(21);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int t = 0; t < 80; ++t) {
      Vec3d o = normalize(Vec3d{u(rng), u(rng), u(rng)}) * 100.0 + Vec3d{32, 32, 32};
      RayPacket p = make_packet(math, o, normalize(Vec3d{32, 32, 32} - o), 0.02, tsps);
      for (;;) {
        const CtuResult c = ctu.run(p);
        if (!c.found) break;
        SampleBatch b;
        while (ftu.run(p, 0, c.cv_tag, b)) {
        }
      }
    }
    per_iteration[lag] = double(ctu.counters().rays_advanced) / double(ctu.counters().iterations);
  }
  EXPECT_GE(per_iteration[1], per_iteration[0]);
}

}  // namespace
}  // namespace edrnr::chip
