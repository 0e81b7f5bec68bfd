#include <gtest/gtest.h>
#include <hwy/targets.h>

#include <algorithm>
#include <random>
#include <vector>

#include "chip/cfiu_kernel.h"
#include "chip/tme_kernel.h"
#include "core/fixed_point.h"

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

// tme_dot_columns_pairs against the sums of products of its contract,
// formed here in 64-bit scalar arithmetic, on random int8 weights and int16
// inputs (their extremes included), odd and even input counts, on every SIMD
// target this build has and the CPU runs; and the pair layout refuses a
// weight outside int8.
TEST(TmeDotColumnsPairs, MatchesTheScalarSumsOnEveryTarget) {
  constexpr size_t kStride = 256, kOutPad = 32, kSamples = 4, kIn = 41;
  std::mt19937_64 rng(11);
  std::vector<int32_t> wt(kIn * kOutPad), x(kStride * kSamples), y(kStride * kSamples);
  for (int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    for (int rep = 0; rep < 60; ++rep) {
      for (int32_t& w : wt) w = rep % 5 == 0 ? (rng() % 2 ? 127 : -128) : int32_t(rng() % 256) - 128;
      for (int32_t& v : x) v = rep % 7 == 0 ? (rng() % 2 ? 32767 : -32768) : int32_t(rng() % 65536) - 32768;
      const std::vector<int16_t> pairs = tme_pair_weights(wt.data(), kIn, kOutPad);
      const size_t i_end = 1 + size_t(rep) % kIn;
      tme_dot_columns_pairs(pairs.data(), wt.data(), kOutPad, i_end, x.data(), kStride, kSamples, y.data(), kStride);
      for (size_t s = 0; s < kSamples; ++s)
        for (size_t j = 0; j < kOutPad; ++j) {
          int64_t sum = 0;
          for (size_t i = 0; i < i_end; ++i) sum += int64_t(wt[i * kOutPad + j]) * x[s * kStride + i];
          ASSERT_EQ(y[s * kStride + j], sum)
              << tme_kernel_target() << " sample " << s << " output " << j << " inputs " << i_end;
        }
    }
  }
  hwy::SetSupportedTargetsForTest(0);
  wt[3] = 128;
  EXPECT_THROW(tme_pair_weights(wt.data(), kIn, kOutPad), std::invalid_argument);
}

// tme_requant_signed against fx::requantize (the exact 128-bit product and
// its rounding) and fx::saturate, on random signed values, biases,
// multipliers and shifts, with floor and half-up rounding, a row length that
// leaves a partial vector (whose other lanes must stay unwritten), on every
// SIMD target this build has and the CPU runs.
TEST(TmeRequantSigned, MatchesRequantizeOnEveryTarget) {
  constexpr size_t kStride = 64, kCount = 45, kSamples = 4;
  std::mt19937_64 rng(11);
  std::vector<int32_t> x(kStride * kSamples), bias(kCount), y(kStride * kSamples);
  std::vector<uint32_t> mult(kCount);
  std::vector<uint64_t> half(kCount), shift(kCount);
  for (int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    for (int rep = 0; rep < 200; ++rep) {
      const int out_bits = rep % 3 == 0 ? 8 : 16;
      const fx::Rounding mode = rep % 2 ? fx::Rounding::HalfUp : fx::Rounding::Floor;
      for (int32_t& v : x) v = int32_t(rng() % (1u << 21)) - (1 << 20);
      std::vector<fx::Requant> q(kCount);
      for (size_t j = 0; j < kCount; ++j) {
        bias[j] = int32_t(rng() % (1u << 21)) - (1 << 20);
        q[j] = {int64_t(rng() >> 33), int(rng() % 63)};  // multiplier below 2^31
        mult[j] = uint32_t(q[j].multiplier);
        shift[j] = uint64_t(q[j].shift);
        half[j] = mode == fx::Rounding::HalfUp ? (uint64_t(1) << shift[j]) >> 1 : 0;
      }
      constexpr int32_t kUntouched = 0x5a5a5a5a;
      std::fill(y.begin(), y.end(), kUntouched);
      const uint64_t clamped = tme_requant_signed(x.data(), kStride, kSamples, kCount, bias.data(), mult.data(),
                                                  half.data(), shift.data(), out_bits, y.data(), kStride);
      for (size_t s = 0; s < kSamples; ++s)
        for (size_t j = kCount; j < kStride; ++j)
          ASSERT_EQ(y[s * kStride + j], kUntouched) << tme_kernel_target() << " sample " << s << " lane " << j;
      uint64_t expected_clamped = 0;
      for (size_t s = 0; s < kSamples; ++s)
        for (size_t j = 0; j < kCount; ++j) {
          const int64_t r = fx::requantize(int64_t(x[s * kStride + j]) + bias[j], q[j], mode);
          const int64_t c = fx::saturate(r, out_bits);
          expected_clamped += c != r;
          ASSERT_EQ(y[s * kStride + j], c)
              << tme_kernel_target() << " sample " << s << " value " << j << " rep " << rep;
        }
      ASSERT_EQ(clamped, expected_clamped) << tme_kernel_target() << " rep " << rep;
    }
  }
  hwy::SetSupportedTargetsForTest(0);
}

// Eight corners' first bytes below `span` and coefficients summing to 2^24
// (the largest the CFIU uses).
void random_corners(std::mt19937_64& rng, size_t span, size_t* first, int32_t* coef) {
  int32_t left = int32_t(1) << 24;
  for (int c = 0; c < 8; ++c) {
    first[c] = rng() % span;
    coef[c] = c == 7 ? left : int32_t(rng() % uint64_t(left + 1));
    left -= coef[c];
  }
}

// cfiu_corner_sums and cfiu_corner_features against their contracts'
// formulas, with the largest coefficients the CFIU uses (2^24 in all), row
// lengths with and without a partial vector, zero-point terms up to
// 15 * 2^24 of either sign, floor (half 0) and half-up rounding and clamp
// bounds that bite, on every target.
TEST(CfiuKernels, MatchTheScalarFormulasOnEveryTarget) {
  std::mt19937_64 rng(5);
  std::vector<uint8_t> q4(4096);
  for (uint8_t& b : q4) b = uint8_t(rng());
  const int64_t zero_bound = int64_t(15) << 24;
  for (int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    for (size_t bytes : {size_t(1), size_t(8), size_t(13), size_t(32)}) {
      for (int rep = 0; rep < 50; ++rep) {
        size_t first[8];
        int32_t coef[8];
        random_corners(rng, q4.size() - bytes, first, coef);
        std::vector<int32_t> even(bytes), odd(bytes), zero_even(bytes), zero_odd(bytes), out(2 * bytes);
        for (size_t b = 0; b < bytes; ++b) {
          zero_even[b] = int32_t(int64_t(rng() % uint64_t(2 * zero_bound + 1)) - zero_bound);
          zero_odd[b] = int32_t(int64_t(rng() % uint64_t(2 * zero_bound + 1)) - zero_bound);
        }
        const int shift = 1 + int(rng() % 24);
        const int32_t half = rep % 2 ? int32_t(1) << (shift - 1) : 0;
        const int32_t lo = -(int32_t(1) << 7), hi = (int32_t(1) << 7) - 1;
        cfiu_corner_sums(q4.data(), first, coef, bytes, even.data(), odd.data());
        cfiu_corner_features(q4.data(), first, coef, bytes, zero_even.data(), zero_odd.data(), half, shift, lo, hi,
                             out.data());
        // floor((x + half) / 2^shift), clamped
        auto finish = [&](int64_t x) {
          const int64_t v = x + half;
          const int64_t q = v >= 0 ? v / (int64_t(1) << shift) : -((-v + (int64_t(1) << shift) - 1) >> shift);
          return std::clamp<int64_t>(q, lo, hi);
        };
        for (size_t b = 0; b < bytes; ++b) {
          int64_t e = 0, o = 0;
          for (int c = 0; c < 8; ++c) {
            e += int64_t(coef[c]) * (q4[first[c] + b] & 15);
            o += int64_t(coef[c]) * (q4[first[c] + b] >> 4);
          }
          ASSERT_EQ(even[b], e) << tme_kernel_target() << " byte " << b;
          ASSERT_EQ(odd[b], o) << tme_kernel_target() << " byte " << b;
          ASSERT_EQ(out[2 * b], finish(e - zero_even[b])) << tme_kernel_target() << " byte " << b;
          ASSERT_EQ(out[2 * b + 1], finish(o - zero_odd[b])) << tme_kernel_target() << " byte " << b;
        }
      }
    }
  }
  hwy::SetSupportedTargetsForTest(0);
}

}  // namespace
}  // namespace edrnr::chip
