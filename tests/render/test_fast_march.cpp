// The fast renderer's march near the surfaces: the reach field against a
// brute-force search, the samples against the reference march on a scene of
// small solids, the records the renderer takes, and the march over a given
// candidate range of an occupancy grid (the trainer's).
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <vector>

#include "fast_scenes.h"
#include "model/mlp.h"
#include "render/fast_march.h"
#include "render/traversal.h"

namespace edrnr {
namespace {

using fast_test::dust_model;
using fast_test::expect_reference_samples;
using fast_test::several_model;
using fast_test::views;

// The reach of every fine voxel against a brute-force search of the micro
// bitmap: 0 for occupied fine voxels; else the Chebyshev gap from the fine
// voxel's micro voxels to the nearest occupied micro voxel, capped at 4 r
// (r: the fine distance) for r <= kExactReach and taken as 4 (r - 1)
// beyond. Below the caps the gap is exact, so the box widened by it touches
// an occupied micro voxel. The several scene and small solids.
TEST(Fast, SkipGridReachIsTheMicroGap) {
  for (const SceneModel& m : {several_model(64, false), dust_model(64)}) {
    const FastSkipGrid g(m);
    const Bitmap3& micro = m.occupancy[int(Tier::Micro)];
    std::vector<Vec3i> occupied;
    for (int z = 0; z < m.micro_res; ++z)
      for (int y = 0; y < m.micro_res; ++y)
        for (int x = 0; x < m.micro_res; ++x)
          if (micro.get(x, y, z)) occupied.push_back(Vec3i{x, y, z});
    ASSERT_GT(occupied.size(), 100u);
    const int res = g.res;
    ASSERT_EQ(g.reach.size(), size_t(res) * res * res + 3);
    int fractional = 0;  // near voxels whose reach is not a multiple of 4
    for (int fz = 0; fz < res; ++fz)
      for (int fy = 0; fy < res; ++fy)
        for (int fx = 0; fx < res; ++fx) {
          const size_t f = size_t(fx) + size_t(res) * (size_t(fy) + size_t(res) * size_t(fz));
          const int r = g.at(fx, fy, fz);
          const int e = g.reach[f];
          if (r == 0) {
            ASSERT_EQ(e, 0) << fx << "," << fy << "," << fz;
            continue;
          }
          // The gap along an axis from micro coordinate u to [4 f, 4 f + 4).
          const auto gap = [](int u, int fc) { return u < 4 * fc ? 4 * fc - 1 - u : std::max(0, u - 4 * fc - 4); };
          int best = 1 << 20;
          for (const Vec3i& u : occupied) best = std::min(best, std::max({gap(u.x, fx), gap(u.y, fy), gap(u.z, fz)}));
          const int want = r <= FastSkipGrid::kExactReach ? std::min(best, 4 * r) : 4 * (r - 1);
          ASSERT_EQ(e, want) << fx << "," << fy << "," << fz << " r " << r;
          ASSERT_LE(e, best);  // the widened box is empty
          fractional += r <= FastSkipGrid::kExactReach && e % 4 != 0;
        }
    EXPECT_GT(fractional, 10);
  }
}

// The jumps by micro gaps (FastSkipGrid::reach) near the surfaces skip no
// sample: every pixel ray of larger images of small solids, at two steps,
// yields the reference march's samples.
TEST(Fast, MarchNearSmallSolidsYieldsTheReferenceSamples) {
  const SceneModel m = dust_model(128);
  ASSERT_NEAR(m.scene_box.size().x, 3.f, 1e-6f);
  const FastSkipGrid skip(m);
  for (float step : {1.f, 0.43f}) {
    const float delta = sample_spacing(m, step);
    size_t total = 0;
    int64_t k_max = 0;
    for (const Camera& cam : views(61, 47)) {
      SCOPED_TRACE(testing::Message() << "step " << step);
      expect_reference_samples(m, skip, cam, delta, &total, &k_max);
      if (HasFatalFailure()) return;
    }
    EXPECT_GT(total, 2000u) << step;
  }
}

// fast_march_records hands out the samples of fast_march_group as the
// renderer's records: per sample the ray, the MLP of its coarse voxel, its
// block vertex and its point's position in the micro voxel, computed here
// from the MarchSample as the renderer used to (the same calls, rays and
// limits; ended the same).
TEST(Fast, MarchRecordsAreTheGroupedSamples) {
  const SceneModel m = dust_model(128);
  const FastSkipGrid skip(m);
  const float delta = sample_spacing(m, 0.43f);
  const int cr = m.coarse_res(), cv = kMicroPerFine * kFinePerCoarse;
  size_t total = 0;
  for (const Camera& cam : {views(29, 23)[0], views(29, 23)[3]})
    for (int limit : {1, 3, 8})
      for (int y = 0; y < cam.height; ++y)
        for (int x0 = 0; x0 < cam.width; x0 += kFastMarchGroup) {
          const int n = std::min(kFastMarchGroup, cam.width - x0);
          std::vector<FastMarcher> a, b;
          uint32_t rays[kFastMarchGroup];
          for (int i = 0; i < n; ++i) {
            const Ray ray = cam.pixel_ray(x0 + i, y);
            a.emplace_back(m, skip, ray, make_micro_ray(m, ray, delta));
            b.emplace_back(m, skip, ray, make_micro_ray(m, ray, delta));
            rays[i] = uint32_t(7 * (x0 + i) + y);
          }
          std::vector<FastMarcher*> pa, pb;
          for (int i = 0; i < n; ++i) {
            pa.push_back(&a[size_t(i)]);
            pb.push_back(&b[size_t(i)]);
          }
          std::vector<MarchSample> samples(size_t(kFastMarchGroup * limit));
          std::vector<int32_t> blocks(samples.size());
          std::vector<FastSample> records(samples.size());
          for (int call = 0; call < 10000; ++call) {
            int ca[kFastMarchGroup], cb[kFastMarchGroup];
            bool ea[kFastMarchGroup], eb[kFastMarchGroup];
            uint64_t missing = 0;
            fast_march_group(pa.data(), n, limit, samples.data(), blocks.data(), ca, ea);
            fast_march_records(pb.data(), rays, n, limit, records.data(), cb, eb, &missing);
            ASSERT_EQ(missing, 0u);
            bool all = true;
            for (int i = 0; i < n; ++i) {
              ASSERT_EQ(cb[i], ca[i]);
              ASSERT_EQ(eb[i], ea[i]);
              for (int j = 0; j < ca[i]; ++j) {
                const MarchSample& s = samples[size_t(i * limit + j)];
                const FastSample& r = records[size_t(i * limit + j)];
                const Vec3i& v = s.voxel;
                ASSERT_EQ(r.ray, rays[i]);
                ASSERT_EQ(int32_t(r.mlp), m.coarse_to_mlp[linear_index(v.x / cv, v.y / cv, v.z / cv, cr)]);
                const int local = (v.x % 4) + kBlockVertsPerAxis * ((v.y % 4) + kBlockVertsPerAxis * (v.z % 4));
                ASSERT_EQ(r.vertex, uint32_t(blocks[size_t(i * limit + j)] * kBlockVerts + local));
                ASSERT_EQ(std::bit_cast<uint32_t>(r.fx), std::bit_cast<uint32_t>(s.p_micro.x - float(v.x)));
                ASSERT_EQ(std::bit_cast<uint32_t>(r.fy), std::bit_cast<uint32_t>(s.p_micro.y - float(v.y)));
                ASSERT_EQ(std::bit_cast<uint32_t>(r.fz), std::bit_cast<uint32_t>(s.p_micro.z - float(v.z)));
                ++total;
              }
              all = all && (ea[i] || ca[i] == 0);
            }
            if (all) break;
          }
        }
  EXPECT_GT(total, 1000u);
}

// The grid built from the occupancy alone (the trainer's) is the model's
// without blocks and MLPs, and a march over any candidate range of it
// (set_up_range, several calls of a few samples each, as the trainer's
// rounds) yields exactly the candidates of the range whose float points lie
// in occupied micro voxels, found here one by one.
TEST(Fast, MarchOverARangeYieldsItsOccupiedCandidates) {
  const SceneModel m = dust_model(128);
  const FastSkipGrid from_model(m);
  const FastSkipGrid skip(m.occupancy[int(Tier::Fine)], m.occupancy[int(Tier::Micro)]);
  ASSERT_EQ(skip.micro_res, m.micro_res);
  ASSERT_EQ(skip.distance, from_model.distance);
  ASSERT_EQ(skip.reach, from_model.reach);
  ASSERT_EQ(skip.fine_words.size(), from_model.fine_words.size());
  for (size_t f = 0; f < skip.fine_words.size(); f += FastSkipGrid::kCellWords) {
    ASSERT_EQ(skip.fine_words[f], from_model.fine_words[f]);
    ASSERT_EQ(skip.fine_words[f + 1], from_model.fine_words[f + 1]);
    ASSERT_EQ(skip.fine_words[f + FastSkipGrid::kCellBlock], uint32_t(-1));
  }
  const Bitmap3& micro = m.occupancy[int(Tier::Micro)];
  const float delta = sample_spacing(m, 0.5f);
  size_t total = 0, rays = 0;
  for (const Camera& cam : {views(61, 47)[0], views(61, 47)[1], views(61, 47)[2]})
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        const MicroRay r = make_micro_ray(m, cam.pixel_ray(x, y), delta);
        // Ranges that start and end anywhere, also in empty space and outside the grid.
        const int64_t k0 = (x * 37 + y * 11) % 500, k1 = k0 + 300 + (x * y) % 900;
        std::vector<MarchSample> want;
        for (int64_t k = k0; k <= k1; ++k) {
          MarchSample s;
          s.k = k;
          s.p_micro = r.point(k);
          if (micro_voxel_of(s.p_micro, m.micro_res, s.voxel) && micro.get(s.voxel.x, s.voxel.y, s.voxel.z))
            want.push_back(s);
        }
        FastMarcher fm;
        fm.set_up_range(skip, r, k0, k1);
        FastMarcher* group[1] = {&fm};
        std::vector<MarchSample> got;
        for (int call = 0; call < 100000; ++call) {
          MarchSample out[5];
          int32_t blocks[5];
          int count = 0;
          bool ended = false;
          fast_march_group(group, 1, 5, out, blocks, &count, &ended);
          got.insert(got.end(), out, out + count);
          if (ended) break;
          ASSERT_EQ(count, 5);
        }
        ASSERT_EQ(got.size(), want.size()) << x << "," << y;
        for (size_t i = 0; i < got.size(); ++i) {
          ASSERT_EQ(got[i].k, want[i].k);
          ASSERT_EQ(got[i].voxel, want[i].voxel);
          for (int a = 0; a < 3; ++a)
            ASSERT_EQ(std::bit_cast<uint32_t>(got[i].p_micro[a]), std::bit_cast<uint32_t>(want[i].p_micro[a]));
        }
        total += got.size();
        rays += !got.empty();
      }
  EXPECT_GT(total, 1500u);
  EXPECT_GT(rays, 300u);
}

}  // namespace
}  // namespace edrnr
