// The trainer's feature grids (pyramid and blocks: interpolation, gradients
// against central finite differences, total variation) and its occupancy
// helpers.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/error.h"
#include "test_random.h"
#include "train/feature_grid.h"
#include "train/occupancy.h"
#include "train/rng.h"

namespace edrnr::train {
namespace {

// --- feature grids ---

struct GridSamples {
  std::vector<float> pos;
  std::vector<int16_t> micro;
  std::vector<int32_t> ids;
};

GridSamples random_samples(int micro_res, int n, uint64_t seed) {
  GridSamples s;
  for (int i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      float p = rnd(seed, uint64_t(3 * i + a), 0.f, float(micro_res));
      s.pos.push_back(p);
      s.micro.push_back(int16_t(std::min(int(std::floor(p)), micro_res - 1)));
    }
    s.ids.push_back(i);
  }
  return s;
}

// One sample at a random point of every micro voxel in [lo, hi).
GridSamples samples_in_every_voxel(const Vec3i& lo, const Vec3i& hi, uint64_t seed) {
  GridSamples s;
  int id = 0;
  for (int z = lo.z; z < hi.z; ++z)
    for (int y = lo.y; y < hi.y; ++y)
      for (int x = lo.x; x < hi.x; ++x) {
        const int m[3] = {x, y, z};
        for (int a = 0; a < 3; ++a) {
          s.pos.push_back(float(m[a]) + rnd(seed, uint64_t(3 * id + a), 0.1f, 0.9f));
          s.micro.push_back(int16_t(m[a]));
        }
        s.ids.push_back(id++);
      }
  return s;
}

// Blocks of fine voxels (1, 2, 3) and (2, 2, 3) of a 32^3 micro grid (block
// 0's face x = 4 is block 1's face x = 0), F random channels.
BlockFeatures two_adjacent_blocks(int F, uint64_t seed) {
  std::vector<uint32_t> fine = {linear_index(1, 2, 3, 8), linear_index(2, 2, 3, 8)};
  std::vector<float> values(fine.size() * kBlockVerts * size_t(F));
  for (size_t i = 0; i < values.size(); ++i) values[i] = rnd(seed, i, -1.f, 1.f);
  return BlockFeatures(32, F, fine, values);
}

TEST(FeatureGrid, PyramidInterpolatesLinearFunctionsExactly) {
  // Vertex values a linear function of position: every level reproduces it.
  FeaturePyramid pyr(32, {8, 16, 32}, 7, 0.f);
  for (auto& L : pyr.levels()) {
    const int n = L.res + 1;
    const float cell = float(32 / L.res);
    for (int z = 0; z < n; ++z)
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x)
          for (int k = 0; k < kLevelChannels; ++k)
            L.value[L.vertex_index(x, y, z) * kLevelChannels + size_t(k)] =
                float(k + 1) * (x * cell) - 0.5f * (y * cell) + 0.25f * (z * cell);
  }
  const Vec3f p{10.3f, 21.7f, 3.9f};
  float out[12];
  pyr.interpolate(p, {10, 21, 3}, out);
  for (int li = 0; li < 3; ++li)
    for (int k = 0; k < 4; ++k)
      EXPECT_NEAR(out[li * 4 + k], float(k + 1) * p.x - 0.5f * p.y + 0.25f * p.z, 1e-4) << li << " " << k;
}

TEST(FeatureGrid, InactivePyramidLevelsReadZeroAndGetNoGradient) {
  const int R = 8;
  FeaturePyramid pyr(R, {2, 4, 8}, 23, 0.5f);
  const int F = pyr.channels();
  const Vec3f p{3.3f, 5.6f, 1.2f};
  std::vector<float> all(static_cast<size_t>(F)), some(static_cast<size_t>(F));
  pyr.interpolate(p, {3, 5, 1}, all.data());
  pyr.set_active_levels(0b101);  // level 1 off
  pyr.interpolate(p, {3, 5, 1}, some.data());
  for (int c = 0; c < F; ++c) {
    if (c / kLevelChannels == 1)
      EXPECT_EQ(some[size_t(c)], 0.f) << c;
    else
      EXPECT_EQ(some[size_t(c)], all[size_t(c)]) << c;
  }
  EXPECT_NE(all[4], 0.f);  // the level off has values
  const GridSamples s = samples_in_every_voxel({0, 0, 0}, {R, R, R}, 24);
  std::vector<float> r(s.ids.size() * size_t(F), 1.f);
  GradientSlabs slabs;
  slabs.build(R, pyr.slab_micro(), s.ids, s.micro);
  pyr.scatter_gradients(slabs, s.pos, s.micro, r);
  for (int li = 0; li < 3; ++li) {
    const PyramidLevel& L = pyr.levels()[size_t(li)];
    const bool any = std::any_of(L.adam.grad.begin(), L.adam.grad.end(), [](float g) { return g != 0.f; });
    EXPECT_EQ(any, li != 1) << li;
  }
}

TEST(FeatureGrid, PyramidTotalVariationCoversTheFinestLevelsAsked) {
  const int R = 8;
  for (int tv_levels : {1, 2}) {
    FeaturePyramid pyr(R, {2, 4, 8}, 21, 0.5f);
    const int F = pyr.channels();
    // A sample in every micro voxel touches every vertex of every level.
    const GridSamples s = samples_in_every_voxel({0, 0, 0}, {R, R, R}, 22);
    std::vector<float> r(s.ids.size() * size_t(F), 1.f);
    GradientSlabs slabs;
    slabs.build(R, pyr.slab_micro(), s.ids, s.micro);
    pyr.scatter_gradients(slabs, s.pos, s.micro, r);
    std::vector<std::vector<float>> before;
    for (const auto& L : pyr.levels()) before.push_back(L.adam.grad);
    const float weight = 0.2f;
    pyr.add_tv_gradient(weight, tv_levels);
    for (int li = 0; li < 3; ++li) {
      const PyramidLevel& L = pyr.levels()[size_t(li)];
      const int n = L.res + 1;
      const bool covered = li >= 3 - tv_levels;
      for (int z = 0; z < n; ++z)
        for (int y = 0; y < n; ++y)
          for (int x = 0; x < n; ++x)
            for (int k = 0; k < kLevelChannels; ++k) {
              // d/dv of sum over neighbour pairs (v - u)^2: 2 (v - u) per neighbour.
              const int c[3] = {x, y, z};
              const float v = L.value[L.vertex_index(x, y, z) * kLevelChannels + size_t(k)];
              double expect = 0;
              for (int a = 0; a < 3; ++a)
                for (int d = -1; d <= 1; d += 2) {
                  int q[3] = {c[0], c[1], c[2]};
                  q[a] += d;
                  if (q[a] < 0 || q[a] >= n) continue;
                  expect += 2.0 * weight * (v - L.value[L.vertex_index(q[0], q[1], q[2]) * kLevelChannels + size_t(k)]);
                }
              if (!covered) expect = 0;
              const size_t i = L.vertex_index(x, y, z) * kLevelChannels + size_t(k);
              EXPECT_NEAR(L.adam.grad[i] - before[size_t(li)][i], expect, 1e-5) << tv_levels << " " << li;
            }
    }
  }
}

TEST(FeatureGrid, PyramidSmoothingPullsTouchedVerticesTowardTheirNeighbours) {
  const int R = 8;
  FeaturePyramid pyr(R, {2, 4, 8}, 23, 0.5f);
  const int F = pyr.channels();
  // Samples in one corner region only: the vertices outside it are not touched.
  const GridSamples s = samples_in_every_voxel({0, 0, 0}, {4, 4, 4}, 24);
  std::vector<float> r(s.ids.size() * size_t(F), 1.f);
  GradientSlabs slabs;
  slabs.build(R, pyr.slab_micro(), s.ids, s.micro);
  pyr.scatter_gradients(slabs, s.pos, s.micro, r);
  std::vector<std::vector<float>> before;
  for (const auto& L : pyr.levels()) before.push_back(L.value);
  const float rate = 0.05f;
  pyr.smooth(rate, 1);
  size_t moved = 0;
  for (int li = 0; li < 3; ++li) {
    const PyramidLevel& L = pyr.levels()[size_t(li)];
    const std::vector<float>& old = before[size_t(li)];
    const int n = L.res + 1;
    for (int z = 0; z < n; ++z)
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x)
          for (int k = 0; k < kLevelChannels; ++k) {
            const size_t i = L.vertex_index(x, y, z) * kLevelChannels + size_t(k);
            // Touched: the finest level's vertices of the cells with samples.
            const bool touched = li == 2 && x <= 4 && y <= 4 && z <= 4;
            double expect = old[i];
            if (touched) {
              const int c[3] = {x, y, z};
              for (int a = 0; a < 3; ++a)
                for (int d = -1; d <= 1; d += 2) {
                  int q[3] = {c[0], c[1], c[2]};
                  q[a] += d;
                  if (q[a] < 0 || q[a] >= n) continue;
                  expect -= rate * (old[i] - old[L.vertex_index(q[0], q[1], q[2]) * kLevelChannels + size_t(k)]);
                }
            }
            EXPECT_NEAR(L.value[i], expect, 1e-6) << li << " " << x << "," << y << "," << z;
            moved += L.value[i] != old[i];
          }
  }
  EXPECT_GT(moved, 100u);
}

TEST(FeatureGrid, PyramidGradientMatchesFiniteDifferences) {
  const int R = 32;
  FeaturePyramid pyr(R, {8, 16, 32}, 11, 0.5f);
  const int F = pyr.channels();
  GridSamples s = random_samples(R, 300, 12);
  const int n = int(s.ids.size());
  std::vector<float> r(size_t(n) * F);
  for (size_t i = 0; i < r.size(); ++i) r[i] = rnd(13, i, -1.f, 1.f);
  auto loss = [&](const FeaturePyramid& p) {
    double L = 0;
    std::vector<float> f(static_cast<size_t>(F));
    for (int i = 0; i < n; ++i) {
      p.interpolate({s.pos[3 * size_t(i)], s.pos[3 * size_t(i) + 1], s.pos[3 * size_t(i) + 2]},
                    {s.micro[3 * size_t(i)], s.micro[3 * size_t(i) + 1], s.micro[3 * size_t(i) + 2]}, f.data());
      for (int c = 0; c < F; ++c) L += double(r[size_t(i) * F + c]) * f[size_t(c)];
    }
    return L;
  };
  GradientSlabs slabs;
  slabs.build(R, pyr.slab_micro(), s.ids, s.micro);
  pyr.scatter_gradients(slabs, s.pos, s.micro, r);
  // The loss is linear in the values: the finite difference is exact up to rounding.
  int touched = 0;
  for (size_t li = 0; li < pyr.levels().size(); ++li) {
    auto& L = pyr.levels()[li];
    for (size_t v = 0; v < L.value.size(); v += 37) {
      const float keep = L.value[v];
      L.value[v] = keep + 0.5f;
      const double lp = loss(pyr);
      L.value[v] = keep - 0.5f;
      const double lm = loss(pyr);
      L.value[v] = keep;
      const double fd = (lp - lm) / 1.0;
      EXPECT_NEAR(L.adam.grad[v], fd, 1e-3 * (1 + std::fabs(fd))) << "level " << li << " value " << v;
      if (L.adam.grad[v] != 0.f) ++touched;
    }
  }
  EXPECT_GT(touched, 50);
  // The touched lists name exactly the vertices with a non-zero gradient.
  for (const auto& L : pyr.levels()) {
    std::vector<uint8_t> listed(L.value.size() / kLevelChannels, 0);
    for (const auto& list : L.adam.touched_list)
      for (int32_t v : list) {
        EXPECT_EQ(listed[size_t(v)], 0) << "listed twice";
        listed[size_t(v)] = 1;
      }
    for (size_t v = 0; v < listed.size(); ++v) {
      const bool nonzero = L.adam.grad[4 * v] != 0.f || L.adam.grad[4 * v + 1] != 0.f ||
                           L.adam.grad[4 * v + 2] != 0.f || L.adam.grad[4 * v + 3] != 0.f;
      EXPECT_EQ(listed[v] != 0, nonzero) << "vertex " << v;
    }
  }
}

TEST(FeatureGrid, PyramidGradientDoesNotDependOnSlabSplit) {
  // Gradients from many threads are summed per vertex in sample order, so
  // they equal a plain serial accumulation bit for bit.
  const int R = 64;
  FeaturePyramid pyr(R, {16, 64}, 21, 0.5f);
  const int F = pyr.channels();
  GridSamples s = random_samples(R, 2000, 22);
  std::vector<float> r(s.ids.size() * size_t(F));
  for (size_t i = 0; i < r.size(); ++i) r[i] = rnd(23, i, -1.f, 1.f);
  GradientSlabs slabs;
  slabs.build(R, pyr.slab_micro(), s.ids, s.micro);
  pyr.scatter_gradients(slabs, s.pos, s.micro, r);
  for (size_t li = 0; li < pyr.levels().size(); ++li) {
    const auto& L = pyr.levels()[li];
    std::vector<float> serial(L.value.size(), 0.f);
    const float inv = 1.f / float(1 << L.shift);
    for (size_t i = 0; i < s.ids.size(); ++i) {
      const int cx = s.micro[3 * i] >> L.shift, cy = s.micro[3 * i + 1] >> L.shift, cz = s.micro[3 * i + 2] >> L.shift;
      float w[8];
      trilinear_weights(s.pos[3 * i] * inv - float(cx), s.pos[3 * i + 1] * inv - float(cy),
                        s.pos[3 * i + 2] * inv - float(cz), w);
      for (int c = 0; c < 8; ++c) {
        const size_t v = L.vertex_index(cx + (c & 1), cy + ((c >> 1) & 1), cz + (c >> 2));
        for (int k = 0; k < 4; ++k) serial[v * 4 + size_t(k)] += w[c] * r[i * size_t(F) + li * 4 + size_t(k)];
      }
    }
    EXPECT_EQ(serial, L.adam.grad) << "level " << li;
  }
}

TEST(FeatureGrid, BlockGradientMatchesFiniteDifferences) {
  const int R = 32, F = 4;
  BlockFeatures blk = two_adjacent_blocks(F, 31);
  GridSamples s;
  for (int i = 0; i < 200; ++i) {
    const float p[3] = {rnd(32, uint64_t(i), 4.f, 12.f), rnd(33, uint64_t(i), 8.f, 12.f),
                        rnd(34, uint64_t(i), 12.f, 16.f)};
    for (int a = 0; a < 3; ++a) {
      s.pos.push_back(p[a]);
      s.micro.push_back(int16_t(std::floor(p[a])));
    }
    s.ids.push_back(i);
  }
  std::vector<float> r(s.ids.size() * F);
  for (size_t i = 0; i < r.size(); ++i) r[i] = rnd(35, i, -1.f, 1.f);
  auto loss = [&](const BlockFeatures& b) {
    double L = 0;
    float f[F];
    for (size_t i = 0; i < s.ids.size(); ++i) {
      EXPECT_TRUE(b.interpolate({s.pos[3 * i], s.pos[3 * i + 1], s.pos[3 * i + 2]},
                                {s.micro[3 * i], s.micro[3 * i + 1], s.micro[3 * i + 2]}, f));
      for (int c = 0; c < F; ++c) L += double(r[i * F + size_t(c)]) * f[c];
    }
    return L;
  };
  GradientSlabs slabs;
  slabs.build(R, kMicroPerFine, s.ids, s.micro);
  blk.scatter_gradients(slabs, s.pos, s.micro, r);
  for (size_t v = 0; v < blk.values().size(); v += 3) {
    const float keep = blk.values()[v];
    blk.values()[v] = keep + 0.5f;
    const double lp = loss(blk);
    blk.values()[v] = keep - 0.5f;
    const double lm = loss(blk);
    blk.values()[v] = keep;
    EXPECT_NEAR(blk.adam().grad[v], lp - lm, 1e-3 * (1 + std::fabs(lp - lm))) << "value " << v;
  }
}

// two_adjacent_blocks (in a 32^3 micro grid) with a gradient scattered from
// one sample in every micro voxel of both blocks: every vertex is touched.
BlockFeatures touched_adjacent_blocks(int F, uint64_t seed) {
  BlockFeatures blk = two_adjacent_blocks(F, seed);
  const GridSamples s = samples_in_every_voxel({4, 8, 12}, {12, 12, 16}, seed + 1);
  std::vector<float> r(s.ids.size() * size_t(F), 1.f);
  GradientSlabs slabs;
  slabs.build(32, kMicroPerFine, s.ids, s.micro);
  blk.scatter_gradients(slabs, s.pos, s.micro, r);
  return blk;
}

TEST(FeatureGrid, BlockTotalVariationIsTheGradientOfItsEnergy) {
  const int F = 2;
  BlockFeatures blk = touched_adjacent_blocks(F, 41);
  const std::vector<float> before = blk.adam().grad;
  const float weight = 0.3f;
  blk.add_tv_gradient(weight);
  // The energy: squared differences of neighbours in a block, and of the two
  // copies of every vertex on the shared face.
  auto energy = [&](const std::vector<float>& v) {
    double E = 0;
    auto at = [&](int b, int x, int y, int z, int c) {
      return double(v[(size_t(b) * kBlockVerts + size_t(x + 5 * (y + 5 * z))) * F + size_t(c)]);
    };
    for (int b = 0; b < 2; ++b)
      for (int z = 0; z < 5; ++z)
        for (int y = 0; y < 5; ++y)
          for (int x = 0; x < 5; ++x)
            for (int c = 0; c < F; ++c) {
              if (x < 4) E += std::pow(at(b, x, y, z, c) - at(b, x + 1, y, z, c), 2);
              if (y < 4) E += std::pow(at(b, x, y, z, c) - at(b, x, y + 1, z, c), 2);
              if (z < 4) E += std::pow(at(b, x, y, z, c) - at(b, x, y, z + 1, c), 2);
            }
    for (int z = 0; z < 5; ++z)
      for (int y = 0; y < 5; ++y)
        for (int c = 0; c < F; ++c) E += std::pow(at(0, 4, y, z, c) - at(1, 0, y, z, c), 2);
    return E;
  };
  std::vector<float> v = blk.values();
  for (size_t i = 0; i < v.size(); ++i) {
    const float keep = v[i];
    v[i] = keep + 0.25f;
    const double ep = energy(v);
    v[i] = keep - 0.25f;
    const double em = energy(v);
    v[i] = keep;
    const double fd = weight * (ep - em) / 0.5;  // exact: the energy is quadratic
    EXPECT_NEAR(blk.adam().grad[i] - before[i], fd, 1e-4 * (1 + std::fabs(fd))) << "value " << i;
  }
}

TEST(FeatureGrid, BlockSmoothingIsAStepDownTheTotalVariation) {
  // smooth(rate) moves each touched vertex by -rate * sum(v - u) over the
  // neighbours add_tv_gradient uses: the step -rate / 2 * dE/dv on the energy
  // of the test above, from the values before the step.
  const int F = 2;
  BlockFeatures blk = touched_adjacent_blocks(F, 43);
  const std::vector<float> before_grad = blk.adam().grad;
  const std::vector<float> before = blk.values();
  const float rate = 0.04f;
  blk.add_tv_gradient(rate / 2);
  std::vector<float> step(before.size());
  for (size_t i = 0; i < step.size(); ++i) step[i] = blk.adam().grad[i] - before_grad[i];
  blk.smooth(rate);
  size_t moved = 0;
  for (size_t i = 0; i < before.size(); ++i) {
    EXPECT_NEAR(blk.values()[i], before[i] - step[i], 1e-6) << "value " << i;
    moved += blk.values()[i] != before[i];
  }
  EXPECT_GT(moved, before.size() / 2);
}

TEST(FeatureGrid, BlockInterpolationUsesTheMicroVoxelCorners) {
  // Block of fine voxel (0,0,0); vertex (i,j,k) holds i + 10 j + 100 k.
  std::vector<float> values(kBlockVerts);
  for (int v = 0; v < kBlockVerts; ++v) values[size_t(v)] = float(v % 5 + 10 * ((v / 5) % 5) + 100 * (v / 25));
  BlockFeatures blk(32, 1, {0}, values);
  float f;
  ASSERT_TRUE(blk.interpolate({2.25f, 1.5f, 3.75f}, {2, 1, 3}, &f));
  EXPECT_NEAR(f, 2.25f + 15.f + 375.f, 1e-4);
  EXPECT_FALSE(blk.interpolate({5.f, 1.f, 1.f}, {5, 1, 1}, &f));  // fine voxel (1,0,0) has no block
}

TEST(FeatureGrid, Int4QuantizerMatchesTheModelFormula) {
  // Range [-1, 2]: scale 0.2, zero point 5.
  Int4Channel q = int4_channel_for_range(-1.f, 2.f);
  EXPECT_FLOAT_EQ(q.scale, 0.2f);
  EXPECT_EQ(q.zero_point, 5);
  EXPECT_EQ(q.quantize(0.f), 5);
  EXPECT_EQ(q.quantize(2.f), 15);
  EXPECT_EQ(q.quantize(-1.f), 0);
  EXPECT_EQ(q.quantize(9.f), 15);  // saturates
  EXPECT_NEAR(q.fake(0.33f), 0.4f, 1e-6);
  EXPECT_NEAR(q.fake(0.29f), 0.2f, 1e-6);
  // A positive-only range still represents 0 exactly.
  Int4Channel p = int4_channel_for_range(0.5f, 1.5f);
  EXPECT_EQ(p.zero_point, 0);
  EXPECT_EQ(p.fake(0.f), 0.f);
}

TEST(FeatureGrid, Int4FitSaturatesAnOutlierInsteadOfCoarseningEveryStep) {
  // 100000 values evenly in [-1, 1] and one at 100. Min/max would give a step
  // of 101 / 15 and put every ordinary value in one code (mean error 0.5);
  // the [-1, 1] range has step 2 / 15 (mean error 1/30) and costs only the
  // outlier's saturation, so the fit must find a range about that tight.
  std::vector<float> v;
  for (int i = 0; i < 100000; ++i) v.push_back(-1.f + 2.f * float(i) / 99999.f);
  v.push_back(100.f);
  const Int4Channel q = fit_int4_channel(v.data(), v.size(), 1);
  EXPECT_LT(q.scale, 2.5f / 15.f);
  double err = 0;
  for (int i = 0; i < 100000; ++i) err += std::fabs(v[size_t(i)] - q.fake(v[size_t(i)]));
  EXPECT_LT(err / 100000, 0.05);
  // Without the outlier the range stays close to [-1, 1] (a sliver of each
  // tail may saturate: with codes on the range's ends, that lowers the error).
  v.pop_back();
  const Int4Channel full = fit_int4_channel(v.data(), v.size(), 1);
  EXPECT_NEAR(full.scale, 2.f / 15.f, 0.02f * 2.f / 15.f);
}

TEST(FeatureGrid, QuantizersMustMatchTheChannels) {
  std::vector<float> values(kBlockVerts * 2, 0.25f);
  BlockFeatures b(32, 2, {0}, values);
  EXPECT_THROW(b.set_quantization(std::vector<Int4Channel>(3)), Error);
  EXPECT_FALSE(b.quantized());
  b.set_quantization(std::vector<Int4Channel>(2));
  EXPECT_TRUE(b.quantized());
}

TEST(FeatureGrid, QuantizedBlockGradientIsStraightThrough) {
  std::vector<float> values(kBlockVerts * 2);
  for (size_t i = 0; i < values.size(); ++i) values[i] = rnd(41, i, -1.f, 1.f);
  BlockFeatures a(32, 2, {0}, values), b(32, 2, {0}, values);
  b.set_quantization(b.fit_quantization());
  GridSamples s = random_samples(4, 50, 42);
  std::vector<float> r(s.ids.size() * 2);
  for (size_t i = 0; i < r.size(); ++i) r[i] = rnd(43, i, -1.f, 1.f);
  GradientSlabs slabs;
  slabs.build(32, kMicroPerFine, s.ids, s.micro);
  a.scatter_gradients(slabs, s.pos, s.micro, r);
  b.scatter_gradients(slabs, s.pos, s.micro, r);
  EXPECT_EQ(a.adam().grad, b.adam().grad);
  // ... while the forward reads quantized values.
  float fa[2], fb[2];
  a.interpolate({0.f, 0.f, 0.f}, {0, 0, 0}, fa);
  b.interpolate({0.f, 0.f, 0.f}, {0, 0, 0}, fb);
  EXPECT_EQ(fb[0], b.quantization()[0].fake(values[0]));
  EXPECT_NE(fa[0], fb[0]);
}

TEST(Occupancy, OutlyingPartsAreDroppedAndPartsInsideTheObjectsBoxKept) {
  Bitmap3 m(64);
  auto fill = [&](Vec3i lo, Vec3i hi) {  // inclusive
    for (int z = lo.z; z <= hi.z; ++z)
      for (int y = lo.y; y <= hi.y; ++y)
        for (int x = lo.x; x <= hi.x; ++x) m.set(x, y, z);
  };
  // The object: a 30 x 30 x 2 plate and a 2 x 2 x 28 pillar on it (1912
  // voxels, box [10, 39]^3), and a voxel touching the plate's corner by a
  // corner only (26-neighbour: part of the object, so the box starts at 9).
  fill({10, 10, 10}, {39, 39, 11});
  fill({10, 10, 12}, {11, 11, 39});
  m.set(9, 9, 9);
  fill({25, 25, 25}, {26, 26, 26});  // 8 voxels inside the object's box, apart from it: kept
  fill({39, 30, 30}, {41, 30, 30});  // 3 voxels reaching out of the box: kept
  fill({0, 50, 0}, {7, 57, 0});      // 64 voxels, above 1 % of the object: a part of its own, kept
  fill({50, 50, 50}, {51, 51, 51});  // 8 voxels apart from every larger part: dropped
  m.set(63, 0, 0);                   // a lone voxel: dropped
  const size_t before = m.count();
  ASSERT_EQ(before, 1913u + 8 + 3 + 64 + 8 + 1);
  Bitmap3 off = m;
  EXPECT_EQ(drop_outlying_parts(off, 0.f), 0u);
  EXPECT_EQ(off, m);
  EXPECT_EQ(drop_outlying_parts(m, 0.01f), 9u);
  EXPECT_EQ(m.count(), before - 9);
  EXPECT_FALSE(m.get(50, 50, 50));
  EXPECT_FALSE(m.get(51, 51, 51));
  EXPECT_FALSE(m.get(63, 0, 0));
  EXPECT_TRUE(m.get(9, 9, 9));
  EXPECT_TRUE(m.get(25, 25, 25));
  EXPECT_TRUE(m.get(41, 30, 30));
  EXPECT_TRUE(m.get(7, 57, 0));
  // At 5 % the 64-voxel part (3.3 %) is apart too; the 8-voxel part inside
  // the object's box still stays.
  EXPECT_EQ(drop_outlying_parts(m, 0.05f), 64u);
  EXPECT_TRUE(m.get(25, 25, 25));
  EXPECT_FALSE(m.get(7, 57, 0));
}

}  // namespace
}  // namespace edrnr::train
