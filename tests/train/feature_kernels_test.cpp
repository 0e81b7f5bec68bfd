// The block features' Highway kernels against the scalar loops they replace:
// the same bits for every row width (full vectors and the tail), zero and
// negative-zero rows included, and the touched mask as the scalar loop
// decides it.
#include "train/feature_kernels.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "train/adam.h"
#include "train/feature_grid.h"

namespace edrnr::train {
namespace {

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

std::vector<float> random_row(std::mt19937& rng, size_t n, float zero_share) {
  std::uniform_real_distribution<float> u(-1.f, 1.f), pick(0.f, 1.f);
  std::vector<float> v(n);
  for (float& x : v) {
    const float r = pick(rng);
    x = r < zero_share / 2 ? 0.f : r < zero_share ? -0.f : u(rng) * std::ldexp(1.f, int(rng() % 20) - 10);
  }
  return v;
}

TEST(FeatureKernels, BlendMatchesTheScalarSum) {
  std::mt19937 rng(3);
  for (size_t F : {1, 4, 5, 16, 19, 32, 37}) {
    for (int trial = 0; trial < 50; ++trial) {
      std::vector<std::vector<float>> rows(8);
      const float* ptr[8];
      for (int c = 0; c < 8; ++c) {
        rows[size_t(c)] = random_row(rng, F, 0.2f);
        ptr[c] = rows[size_t(c)].data();
      }
      const std::vector<float> wv = random_row(rng, 8, 0.1f);
      std::vector<float> want(F, 0.f), got(F, 7.f);
      for (int c = 0; c < 8; ++c)
        for (size_t k = 0; k < F; ++k) want[k] += wv[size_t(c)] * ptr[c][k];
      feature_blend_rows(ptr, wv.data(), F, got.data());
      ASSERT_TRUE(same_bits(want, got)) << "F " << F << " trial " << trial;
    }
  }
}

TEST(FeatureKernels, FakeQuantBlendMatchesInt4ChannelFake) {
  // Each value through its channel's quantize-dequantize, then blended: the
  // scalar Int4Channel::fake for every channel, with values on rounding
  // ties, far outside the range, and NaN among them.
  std::mt19937 rng(13);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  for (size_t F : {1, 5, 16, 19}) {
    std::vector<Int4Channel> q(F);
    std::vector<float> scale(F), inv(F), zp(F);
    for (size_t k = 0; k < F; ++k) {
      q[k] = int4_channel_for_range(-0.5f * (1.f + u(rng)), 0.7f * (1.f + u(rng)));
      scale[k] = q[k].scale, inv[k] = q[k].inv_scale, zp[k] = float(q[k].zero_point);
    }
    for (int trial = 0; trial < 100; ++trial) {
      std::vector<std::vector<float>> rows(8, std::vector<float>(F));
      const float* ptr[8];
      for (int c = 0; c < 8; ++c) {
        for (size_t k = 0; k < F; ++k) {
          float& x = rows[size_t(c)][k];
          switch (rng() % 6) {
            case 0:
              x = (float(int(rng() % 30) - 15) + 0.5f) * q[k].scale;
              break;  // about a tie
            case 1:
              x = u(rng) * 1e6f;
              break;  // clamped
            case 2:
              x = rng() % 50 == 0 ? std::nanf("") : -0.f;
              break;
            default:
              x = u(rng);
          }
        }
        ptr[c] = rows[size_t(c)].data();
      }
      float wv[8];
      for (float& x : wv) x = u(rng);
      std::vector<float> want(F, 0.f), got(F, 3.f);
      for (int c = 0; c < 8; ++c)
        for (size_t k = 0; k < F; ++k) want[k] += wv[c] * q[k].fake(ptr[c][k]);
      feature_blend_rows_fake_quant(ptr, wv, F, scale.data(), inv.data(), zp.data(), got.data());
      ASSERT_TRUE(same_bits(want, got)) << "F " << F << " trial " << trial;
    }
  }
}

TEST(FeatureKernels, ScatterMatchesTheScalarLoopAndItsTouchedRows) {
  std::mt19937 rng(5);
  int touched_seen = 0, untouched_seen = 0;
  for (size_t F : {1, 4, 5, 16, 19, 32}) {
    for (int trial = 0; trial < 200; ++trial) {
      // Rows that are all zeros (either sign) half the time; gradients that
      // are zero, or cancel a row exactly, now and then.
      std::vector<std::vector<float>> want(8), got(8);
      const std::vector<float> g = random_row(rng, F, trial % 5 == 0 ? 1.f : 0.1f);
      std::vector<float> wv = random_row(rng, 8, 0.2f);
      for (int c = 0; c < 8; ++c) {
        auto& r = want[size_t(c)];
        r = random_row(rng, F, rng() % 2 ? 1.f : 0.1f);
        if (trial % 7 == 1 && c == 3) {  // row = -(w g): the sum returns to zero
          wv[3] = 1.f;
          for (size_t k = 0; k < F; ++k) r[k] = -g[k];
        }
        got[size_t(c)] = r;
      }
      uint32_t want_mask = 0;
      for (int c = 0; c < 8; ++c) {
        float* gv = want[size_t(c)].data();
        bool was_zero = true, now_zero = true;
        for (size_t k = 0; k < F; ++k) {
          was_zero = was_zero && gv[k] == 0.f;
          gv[k] += wv[size_t(c)] * g[k];
          now_zero = now_zero && gv[k] == 0.f;
        }
        if (was_zero && !now_zero) want_mask |= 1u << c;
      }
      float* ptr[8];
      for (int c = 0; c < 8; ++c) ptr[c] = got[size_t(c)].data();
      const uint32_t mask = feature_scatter_rows(ptr, wv.data(), g.data(), F);
      ASSERT_EQ(mask, want_mask) << "F " << F << " trial " << trial;
      for (int c = 0; c < 8; ++c) ASSERT_TRUE(same_bits(want[size_t(c)], got[size_t(c)])) << "F " << F;
      touched_seen += std::popcount(mask);
      untouched_seen += 8 - std::popcount(mask);
    }
  }
  EXPECT_GT(touched_seen, 100);
  EXPECT_GT(untouched_seen, 100);
}

TEST(FeatureKernels, AdamRowsMatchAdamStepUpdate) {
  std::mt19937 rng(9);
  AdamSettings settings;
  for (size_t F : {1, 4, 5, 16, 19}) {
    const size_t vertices = 40;
    std::vector<float> p = random_row(rng, vertices * F, 0.05f), m = random_row(rng, vertices * F, 0.2f),
                       v = random_row(rng, vertices * F, 0.2f), g = random_row(rng, vertices * F, 0.2f);
    for (float& x : v) x = std::abs(x);  // second moments are never negative
    std::vector<int32_t> list;
    for (int32_t i = 0; i < int32_t(vertices); i += 1 + int32_t(rng() % 3)) list.push_back(i);
    for (int64_t t : {1, 7, 300}) {
      const AdamStep step(settings, 0.02f, t);
      std::vector<float> wp = p, wm = m, wv = v, wg = g;
      for (int32_t vtx : list)
        for (size_t k = 0; k < F; ++k) {
          const size_t i = size_t(vtx) * F + k;
          step.update(wp[i], wm[i], wv[i], wg[i]);
          wg[i] = 0.f;
        }
      std::vector<float> gp = p, gm = m, gv = v, gg = g;
      feature_adam_rows(gp.data(), gm.data(), gv.data(), gg.data(), list.data(), list.size(), F, step);
      ASSERT_TRUE(same_bits(wp, gp)) << "F " << F << " t " << t;
      ASSERT_TRUE(same_bits(wm, gm)) << "F " << F << " t " << t;
      ASSERT_TRUE(same_bits(wv, gv)) << "F " << F << " t " << t;
      ASSERT_TRUE(same_bits(wg, gg)) << "F " << F << " t " << t;
      ASSERT_NE(gp, p);  // the step moved the parameters
    }
  }
}

}  // namespace
}  // namespace edrnr::train
