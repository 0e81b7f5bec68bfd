// The occupancy grid's Highway kernels and the occupancy refresh's row
// interpolation against their definitions written out here as scalar loops
// (and FeaturePyramid::interpolate): the same bits on every SIMD target this
// build has and the CPU runs; and the grid's bitmaps against a voxel-by-voxel
// reading of their contract.
#include "train/occupancy_kernels.h"

#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "hwy_targets.h"
#include "train/feature_grid.h"
#include "train/occupancy.h"

namespace edrnr::train {
namespace {

// Densities as the refresh leaves them: mostly small, some large, some not
// evaluated yet (-1), and a share of -0, NaN and values at `threshold` exactly.
std::vector<float> random_densities(std::mt19937& rng, size_t n, float threshold) {
  std::uniform_real_distribution<float> u(0.f, 1.f);
  std::vector<float> d(n);
  for (float& x : d) {
    const float r = u(rng);
    x = r < 0.02f   ? -1.f
        : r < 0.03f ? -0.f
        : r < 0.04f ? std::numeric_limits<float>::quiet_NaN()
        : r < 0.05f ? threshold
        : r < 0.25f ? 50.f * u(rng)
                    : 0.5f * threshold * u(rng);
  }
  return d;
}

bool bit_of(float d, float threshold) { return d < 0.f || d > threshold; }

TEST(OccupancyKernels, SumIsTheContractsOrderOnEveryTarget) {
  std::mt19937 rng(3);
  for (size_t n : {size_t(0), size_t(1), size_t(7), size_t(8), size_t(9), size_t(1000), size_t(4103)}) {
    // Exponents far apart, so that the order of the sums shows in their bits
    // (sums of floats of nearby exponents are exact in double whatever the order).
    std::vector<float> d = random_densities(rng, n, 1.f);
    for (float& x : d)
      if (x > 0.f) x = std::ldexp(x, int(rng() % 120) - 60);
    double part[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    size_t want_count = 0;
    for (size_t i = 0; i < n; ++i)
      if (d[i] >= 0.f) {
        part[i % 8] += double(d[i]);
        ++want_count;
      }
    double want = 0;
    for (double p : part) want += p;
    on_every_target([&](const char* name) {
      double sum = -1;
      size_t count = 0;
      occupancy_sum_nonnegative(d.data(), n, &sum, &count);
      EXPECT_EQ(std::memcmp(&sum, &want, sizeof sum), 0) << name << " n " << n << ": " << sum << " vs " << want;
      EXPECT_EQ(count, want_count) << name << " n " << n;
    });
  }
}

TEST(OccupancyKernels, ThresholdWordsSetTheBitsOfTheContractOnEveryTarget) {
  std::mt19937 rng(4);
  const float threshold = 0.75f;
  const size_t n_words = 37;
  const std::vector<float> d = random_densities(rng, 64 * n_words, threshold);
  on_every_target([&](const char* name) {
    std::vector<uint64_t> words(n_words, 0x5555);
    occupancy_threshold_words(d.data(), n_words, threshold, words.data());
    for (size_t i = 0; i < d.size(); ++i)
      ASSERT_EQ((words[i / 64] >> (i % 64)) & 1u, bit_of(d[i], threshold) ? 1u : 0u)
          << name << " value " << i << " = " << d[i];
  });
}

// Every cell of sweep part rows through refresh_interpolate_row against
// FeaturePyramid::interpolate at the same points, bit for bit.
void expect_rows_match_the_pyramid(const FeaturePyramid& pyr, uint64_t seed) {
  const int R = pyr.micro_res();
  std::vector<PyramidLevelView> views;
  for (size_t li = 0; li < pyr.levels().size(); ++li) {
    const PyramidLevel& L = pyr.levels()[li];
    views.push_back({L.value.data(), L.res, L.shift, pyr.level_active(li)});
  }
  const int F = pyr.channels();
  std::mt19937 rng{uint32_t(seed)};
  std::uniform_real_distribution<float> u(0.f, 1.f);
  // Rows in the middle and on the grid's last faces; chunks from the row's
  // start (either parity), at its end and partly filled.
  const int rows[][2] = {{0, 0}, {R / 2 + 1, R / 3}, {R - 1, R - 2}, {R - 2, R - 1}, {R - 1, R - 1}};
  on_every_target([&](const char* name) {
    for (const auto& row : rows) {
      const int y = row[0], z = row[1];
      for (int x_first : {0, 1, R / 2 - 1, R - 2 * kLanes + 1, R - 2 * kLanes, R - 9, R - 2, R - 1}) {
        if (x_first < 0) continue;
        const int nl = std::min(kLanes, (R - 1 - x_first) / 2 + 1);
        float px[kLanes], py[kLanes], pz[kLanes];
        for (int i = 0; i < kLanes; ++i) {
          // A point of the cell, its corners and its faces included.
          auto in_cell = [&](int m) {
            const float r = u(rng);
            return float(m) + (r < 0.05f ? 0.f : r < 0.1f ? 0.99999994f : u(rng));
          };
          px[i] = in_cell(x_first + 2 * i);
          py[i] = in_cell(y);
          pz[i] = in_cell(z);
        }
        std::vector<float> x0(size_t(F) * kLanes, 7.f);
        refresh_interpolate_row(views.data(), int(views.size()), x_first, y, z, nl, px, py, pz, x0.data());
        std::vector<float> want(static_cast<size_t>(F));
        for (int i = 0; i < kLanes; ++i) {
          if (i < nl) pyr.interpolate({px[i], py[i], pz[i]}, {x_first + 2 * i, y, z}, want.data());
          for (int c = 0; c < F; ++c) {
            const float got = x0[size_t(c) * kLanes + size_t(i)], w = i < nl ? want[size_t(c)] : 0.f;
            ASSERT_EQ(std::memcmp(&got, &w, sizeof got), 0)
                << name << " row (" << y << ", " << z << ") x_first " << x_first << " lane " << i << " channel " << c
                << ": " << got << " vs " << w;
          }
        }
      }
    }
  });
}

TEST(OccupancyKernels, RowInterpolationIsThePyramidsOnEveryTarget) {
  // Shifts 3, 2, 1 and 0: every way the kernel reads a level.
  FeaturePyramid pyr(64, {8, 16, 32, 64}, 11, 0.5f);
  expect_rows_match_the_pyramid(pyr, 1);
  pyr.set_active_levels(0b1011);  // level 2 off: it reads zero
  expect_rows_match_the_pyramid(pyr, 2);
  FeaturePyramid coarse(128, {4, 32}, 12, 0.5f);  // shifts 5 and 2
  expect_rows_match_the_pyramid(coarse, 3);
}

TEST(OccupancyKernels, GridBitmapsFollowTheirDefinition) {
  std::mt19937 rng(8);
  const float threshold = 2.f;
  for (int res : {32, 64, 128}) {
    OccupancyGrid g(res);
    g.density = random_densities(rng, size_t(res) * res * res, threshold);
    struct Box {
      bool known;
      Vec3i lo, hi;
    };
    const Box boxes[] = {{false, {0, 0, 0}, {0, 0, 0}},
                         {true, {0, 0, 0}, {res - 1, res - 1, res - 1}},
                         {true, {3, 5, 1}, {res - 7, res - 2, res / 2}},
                         {true, {63 % res, 2, 2}, {64 % res + res / 2, 2, res - 1}},
                         {true, {5, 5, 5}, {5, 5, 5}}};
    for (const Box& b : boxes) {
      g.aabb_known = b.known;
      g.aabb_lo = b.lo;
      g.aabb_hi = b.hi;
      g.rebuild(threshold);
      Bitmap3 fine(res / 4);
      for (int z = 0; z < res; ++z)
        for (int y = 0; y < res; ++y)
          for (int x = 0; x < res; ++x) {
            const bool inside =
                !b.known || (x >= b.lo.x && y >= b.lo.y && z >= b.lo.z && x <= b.hi.x && y <= b.hi.y && z <= b.hi.z);
            const bool want = inside && bit_of(g.density[g.micro.index(x, y, z)], threshold);
            ASSERT_EQ(g.micro.get(x, y, z), want) << "res " << res << " voxel " << x << " " << y << " " << z;
            if (want) fine.set(x / 4, y / 4, z / 4);
          }
      EXPECT_EQ(g.fine, fine) << "res " << res;
    }
  }
}

TEST(OccupancyKernels, MeanDensityIsTheMeanOfTheEvaluatedVoxelsForAnyThreadCount) {
  std::mt19937 rng(9);
  OccupancyGrid g(128);
  g.density = random_densities(rng, g.density.size(), 1.f);
  for (float& d : g.density)
    if (std::isnan(d)) d = -1.f;  // the refresh never stores NaN
  long double sum = 0;
  size_t n = 0;
  for (float d : g.density)
    if (d >= 0.f) {
      sum += d;
      ++n;
    }
  const double want = double(sum / n);
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const double one = g.mean_density();
  omp_set_num_threads(3);
  const double three = g.mean_density();
  omp_set_num_threads(threads);
  EXPECT_NEAR(one, want, 1e-12 * want);
  EXPECT_EQ(std::memcmp(&one, &three, sizeof one), 0);
}

}  // namespace
}  // namespace edrnr::train
