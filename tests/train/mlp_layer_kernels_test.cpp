// The training MLP's Highway layer kernels against their contracts written
// out here as scalar loops in the contracts' order: the same bits on every
// SIMD target this build has and the CPU runs (ReLU and mask at zero,
// negative zero and NaN, rounding ties and clamps included).
#include "train/mlp_layer_kernels.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "hwy_targets.h"

namespace edrnr::train {
namespace {

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

std::vector<float> random_values(std::mt19937& rng, size_t n, float special_share) {
  std::uniform_real_distribution<float> u(-1.f, 1.f), pick(0.f, 1.f);
  std::vector<float> v(n);
  for (float& x : v) {
    const float r = pick(rng);
    x = r < special_share / 3       ? 0.f
        : r < 2 * special_share / 3 ? -0.f
        : r < special_share         ? std::numeric_limits<float>::quiet_NaN()
                                    : u(rng) * std::ldexp(1.f, int(rng() % 16) - 8);
  }
  return v;
}

float relu_of(float a) { return a > 0.f ? a : 0.f; }

TEST(MlpLayerKernels, ForwardIsTheContractsSumOnEveryTarget) {
  std::mt19937 rng(5);
  for (auto [in, out] : {std::pair{16, 16}, {23, 16}, {16, 8}, {16, 3}, {1, 1}, {7, 5}}) {
    const std::vector<float> W = random_values(rng, size_t(in) * out, 0.05f), b = random_values(rng, out, 0.1f);
    const std::vector<float> x = random_values(rng, size_t(in) * kLanes, 0.05f);
    for (bool relu : {false, true}) {
      std::vector<float> want(size_t(out) * kLanes);
      for (int o = 0; o < out; ++o)
        for (int l = 0; l < kLanes; ++l) {
          float a = b[o];
          for (int i = 0; i < in; ++i) a += W[size_t(o) * in + i] * x[size_t(i) * kLanes + l];
          want[size_t(o) * kLanes + l] = relu ? relu_of(a) : a;
        }
      on_every_target([&](const char* name) {
        std::vector<float> got(want.size(), 9.f);
        mlp_layer_forward(W.data(), b.data(), in, out, x.data(), got.data(), relu);
        ASSERT_TRUE(same_bits(want, got)) << name << " " << in << "x" << out << " relu " << relu;
      });
    }
  }
}

TEST(MlpLayerKernels, InputGradientIsTheContractsSumOnEveryTarget) {
  std::mt19937 rng(6);
  for (auto [in, out] : {std::pair{16, 16}, {23, 16}, {16, 3}, {5, 9}}) {
    const std::vector<float> W = random_values(rng, size_t(in) * out, 0.05f);
    const std::vector<float> dy = random_values(rng, size_t(out) * kLanes, 0.05f);
    const std::vector<float> mask = random_values(rng, size_t(in) * kLanes, 0.3f);
    for (bool masked : {false, true}) {
      std::vector<float> want(size_t(in) * kLanes);
      for (int i = 0; i < in; ++i)
        for (int l = 0; l < kLanes; ++l) {
          float a = 0.f;
          for (int o = 0; o < out; ++o) a += W[size_t(o) * in + i] * dy[size_t(o) * kLanes + l];
          want[size_t(i) * kLanes + l] = masked && !(mask[size_t(i) * kLanes + l] > 0.f) ? 0.f : a;
        }
      on_every_target([&](const char* name) {
        std::vector<float> got(want.size(), 9.f);
        mlp_layer_input_grad(W.data(), in, out, dy.data(), masked ? mask.data() : nullptr, got.data());
        ASSERT_TRUE(same_bits(want, got)) << name << " " << in << "x" << out << " masked " << masked;
      });
    }
  }
}

// The lane sum of the contract: runs of 8 lanes added lane by lane, then a
// pairwise tree.
float lane_sum(const float* p) {
  float r[8];
  for (int j = 0; j < 8; ++j) r[j] = ((p[j] + p[8 + j]) + p[16 + j]) + p[24 + j];
  return ((r[0] + r[4]) + (r[2] + r[6])) + ((r[1] + r[5]) + (r[3] + r[7]));
}

TEST(MlpLayerKernels, ParameterGradientSumsLanesInTheFixedOrderOnEveryTarget) {
  std::mt19937 rng(7);
  for (auto [in, out] : {std::pair{16, 16}, {23, 16}, {16, 3}, {3, 2}}) {
    const std::vector<float> x = random_values(rng, size_t(in) * kLanes, 0.02f);
    const std::vector<float> dy = random_values(rng, size_t(out) * kLanes, 0.02f);
    const std::vector<float> gW0 = random_values(rng, size_t(in) * out, 0.f), gb0 = random_values(rng, out, 0.f);
    std::vector<float> wantW = gW0, wantb = gb0;
    for (int o = 0; o < out; ++o) {
      wantb[o] += lane_sum(dy.data() + size_t(o) * kLanes);
      for (int i = 0; i < in; ++i) {
        float p[kLanes];
        for (int l = 0; l < kLanes; ++l) p[l] = dy[size_t(o) * kLanes + l] * x[size_t(i) * kLanes + l];
        wantW[size_t(o) * in + i] += lane_sum(p);
      }
    }
    on_every_target([&](const char* name) {
      std::vector<float> gW = gW0, gb = gb0;
      mlp_layer_param_grad(x.data(), dy.data(), in, out, gW.data(), gb.data());
      ASSERT_TRUE(same_bits(wantW, gW)) << name << " " << in << "x" << out;
      ASSERT_TRUE(same_bits(wantb, gb)) << name << " " << in << "x" << out;
    });
  }
}

TEST(MlpLayerKernels, QuantizeRowsRoundsHalfUpAndClampsOnEveryTarget) {
  std::mt19937 rng(8);
  const float step = 0.03125f * 3.f, lo = -128.f, hi = 127.f;
  std::vector<float> v = random_values(rng, size_t(5) * kLanes, 0.1f);
  // Ties (half a step above a code and below), far outside the range.
  v[1] = 2.5f * step;
  v[2] = -2.5f * step;
  v[3] = 1000.f;
  v[4] = -1000.f;
  v[5] = 0.49999997f * step;
  std::vector<float> want = v;
  const float inv = 1.f / step;
  for (float& x : want) x = std::clamp(std::floor(x * inv + 0.5f), lo, hi) * step;
  EXPECT_EQ(want[1], 3.f * step);
  EXPECT_EQ(want[2], -2.f * step);
  EXPECT_EQ(want[3], hi * step);
  EXPECT_EQ(want[4], lo * step);
  on_every_target([&](const char* name) {
    std::vector<float> got = v;
    quantize_block(got.data(), 5, step, lo, hi);
    ASSERT_TRUE(same_bits(want, got)) << name;
  });
}

}  // namespace
}  // namespace edrnr::train
