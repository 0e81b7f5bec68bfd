#include <gtest/gtest.h>
#include <hwy/targets.h>

#include <algorithm>
#include <random>
#include <vector>

#include "chip/tme_kernel.h"

namespace edrnr::chip {
namespace {

// tme_requant_relu against the formula of its contract, evaluated here in
// 64-bit scalar arithmetic, on random sums, biases, multipliers and shifts,
// with floor (half 0) and half-up rounding, on every SIMD target this build
// has and the CPU runs.
TEST(TmeRequantRelu, MatchesTheScalarFormulaOnEveryTarget) {
  constexpr size_t kStride = 256, kOutPad = 48, kSamples = 5;
  std::mt19937_64 rng(7);
  std::vector<int32_t> sum(kStride * kSamples), bias(kOutPad), y(kStride * kSamples);
  std::vector<uint32_t> mult(kOutPad);
  std::vector<uint64_t> half(kOutPad), shift(kOutPad);
  for (int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    for (int rep = 0; rep < 200; ++rep) {
      const int out_bits = rep % 3 == 0 ? 8 : 16;
      for (int32_t& v : sum) v = int32_t(rng() % (1u << 21)) - (1 << 20);
      for (size_t j = 0; j < kOutPad; ++j) {
        bias[j] = int32_t(rng() % (1u << 21)) - (1 << 20);
        mult[j] = uint32_t(rng() >> 33);  // below 2^31
        shift[j] = rng() % 63;
        half[j] = rep % 2 ? (uint64_t(1) << shift[j]) >> 1 : 0;
      }
      const uint64_t clamped = tme_requant_relu(sum.data(), kStride, kSamples, bias.data(), mult.data(), half.data(),
                                                shift.data(), kOutPad, out_bits, y.data(), kStride);
      const int64_t max_out = (int64_t(1) << (out_bits - 1)) - 1;
      uint64_t expected_clamped = 0;
      for (size_t s = 0; s < kSamples; ++s)
        for (size_t j = 0; j < kOutPad; ++j) {
          const int64_t v = std::max<int64_t>(int64_t(sum[s * kStride + j]) + bias[j], 0);
          const int64_t r = (v * int64_t(mult[j]) + int64_t(half[j])) >> shift[j];
          expected_clamped += r > max_out;
          ASSERT_EQ(y[s * kStride + j], std::min(r, max_out))
              << tme_kernel_target() << " sample " << s << " neuron " << j << " rep " << rep;
        }
      ASSERT_EQ(clamped, expected_clamped) << tme_kernel_target() << " rep " << rep;
    }
  }
  hwy::SetSupportedTargetsForTest(0);
}

}  // namespace
}  // namespace edrnr::chip
