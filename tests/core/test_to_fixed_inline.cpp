// fx::to_fixed / fx::to_fixed_unsigned (inline, floor by integer truncation)
// against the library-floor formulation they replace, kept here: every
// rounding mode, ties, values next to ties, saturation, underflow, NaN,
// infinities and the whole range of scales.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "core/fixed_point.h"

namespace edrnr::fx {
namespace {

// The previous implementation: std::floor, then the fraction decides.
int64_t previous_round_scaled(double v, int frac_bits, Rounding mode) {
  constexpr int64_t kMax = std::numeric_limits<int64_t>::max();
  constexpr int64_t kMin = std::numeric_limits<int64_t>::min();
  if (v != v) return 0;
  if (frac_bits > 1000) frac_bits = 1000;
  if (frac_bits < -1000) frac_bits = -1000;
  const double s = std::ldexp(v, frac_bits);
  if (s == 0.0) return (v < 0.0 && mode == Rounding::Floor) ? -1 : 0;
  const double fl = std::floor(s);
  constexpr double kTwo63 = 9223372036854775808.0;
  if (fl >= kTwo63) return kMax;
  if (fl < -kTwo63) return kMin;
  const double frac = s - fl;
  int64_t q = int64_t(fl);
  bool up = false;
  switch (mode) {
    case Rounding::Floor:
      break;
    case Rounding::HalfUp:
      up = frac >= 0.5;
      break;
    case Rounding::HalfEven:
      up = frac > 0.5 || (frac == 0.5 && (q & 1) != 0);
      break;
  }
  if (up) {
    if (q == kMax) return kMax;
    ++q;
  }
  return q;
}

constexpr Rounding kModes[] = {Rounding::Floor, Rounding::HalfUp, Rounding::HalfEven};

// Values that stress the rounding: integers and half-integers at many
// scales (ties), their neighbouring doubles, powers of two around 2^52,
// 2^53 and 2^63, subnormals, zeros, infinities, NaN and random values.
std::vector<double> interesting_values() {
  std::vector<double> base;
  const double inf = std::numeric_limits<double>::infinity();
  for (int i = -40; i <= 40; ++i) {
    base.push_back(i);
    base.push_back(i + 0.5);
    base.push_back(i * 0.25);
    base.push_back(i * 0.125 + 0.0625);
  }
  for (int e = -1080; e <= 1030; e += 7) base.push_back(std::ldexp(1.0, e));
  for (int e : {51, 52, 53, 54, 62, 63, 64}) {
    base.push_back(std::ldexp(1.0, e));
    base.push_back(std::ldexp(1.0, e) + std::ldexp(1.0, e - 52));
    base.push_back(std::ldexp(1.0, e) - 0.5);
    base.push_back(std::ldexp(1.0, e) + 0.5);
    base.push_back(std::ldexp(1.0, e) - 1.5);
  }
  base.push_back(std::numeric_limits<double>::denorm_min());
  base.push_back(std::numeric_limits<double>::min());
  base.push_back(std::numeric_limits<double>::max());
  base.push_back(inf);
  base.push_back(std::numeric_limits<double>::quiet_NaN());
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 3000; ++i) base.push_back(std::ldexp(u(rng), int(rng() % 140) - 70));
  std::vector<double> out;
  for (double b : base)
    for (double x : {b, -b})
      for (double y : {x, std::nextafter(x, -inf), std::nextafter(x, inf)}) out.push_back(y);
  return out;
}

TEST(ToFixedInline, MatchesThePreviousImplementation) {
  const std::vector<double> values = interesting_values();
  uint64_t compared = 0, ties = 0, saturated = 0;
  for (double v : values) {
    for (int frac_bits : {-1200, -1000, -64, -10, -1, 0, 1, 3, 8, 15, 16, 30, 52, 62, 63, 64, 200, 1000, 1100}) {
      for (Rounding mode : kModes) {
        const int64_t want = previous_round_scaled(v, frac_bits, mode);
        const double s = std::ldexp(v, std::clamp(frac_bits, -1000, 1000));
        ties += std::isfinite(s) && s - std::floor(s) == 0.5;
        for (int bits : {1, 2, 8, 9, 16, 17, 32, 63, 64}) {
          ASSERT_EQ(to_fixed(v, frac_bits, bits, mode), saturate(want, bits))
              << "v " << v << " frac_bits " << frac_bits << " bits " << bits << " mode " << int(mode);
          saturated += to_fixed(v, frac_bits, bits, mode) != want;
          ++compared;
        }
        for (int bits : {0, 1, 8, 9, 16, 17, 32, 62, 63}) {
          ASSERT_EQ(to_fixed_unsigned(v, frac_bits, bits, mode), saturate_unsigned(want, bits))
              << "v " << v << " frac_bits " << frac_bits << " bits " << bits << " mode " << int(mode);
          ++compared;
        }
      }
    }
  }
  EXPECT_GT(compared, 1000000u);
  EXPECT_GT(ties, 1000u);        // ties of the rounding were among the scaled values
  EXPECT_GT(saturated, 10000u);  // and values past the N-bit range
}

TEST(ToFixedInline, SampleFractionsOfEveryWidth) {
  // The sample coordinate calculator's use: a fraction in [0, 1] to
  // frac_bits bits with one bit to spare; every multiple of 2^-(frac_bits+2)
  // (ties included) and its neighbours.
  for (int frac_bits = 1; frac_bits <= 20; ++frac_bits) {
    const int64_t n = int64_t(1) << (frac_bits + 2);
    for (int64_t i = 0; i <= n; i += 1 + i / 4096) {
      const double f = double(i) / double(n);
      for (double x : {f, std::nextafter(f, 0.0), std::nextafter(f, 1.0)}) {
        for (Rounding mode : kModes)
          ASSERT_EQ(to_fixed_unsigned(x, frac_bits, frac_bits + 1, mode),
                    saturate_unsigned(previous_round_scaled(x, frac_bits, mode), frac_bits + 1))
              << "x " << x << " frac_bits " << frac_bits;
      }
    }
  }
}

}  // namespace
}  // namespace edrnr::fx
