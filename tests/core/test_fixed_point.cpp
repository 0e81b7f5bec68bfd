// Fixed-point helpers against hand-computed values and exact integer references.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "core/error.h"
#include "core/fixed_point.h"

namespace edrnr::fx {
namespace {

constexpr int64_t kMax64 = std::numeric_limits<int64_t>::max();
constexpr int64_t kMin64 = std::numeric_limits<int64_t>::min();

// Exact reference: x / d rounded with `mode`, for d > 0, by floor division and
// remainder (no shifts involved).
int64_t ref_div_round(__int128 x, __int128 d, Rounding mode) {
  __int128 q = x / d;  // truncates toward zero
  __int128 r = x - q * d;
  if (r < 0) {  // make it floor division with 0 <= r < d
    q -= 1;
    r += d;
  }
  switch (mode) {
    case Rounding::Floor:
      break;
    case Rounding::HalfUp:
      if (2 * r >= d) q += 1;
      break;
    case Rounding::HalfEven:
      if (2 * r > d || (2 * r == d && (q % 2 != 0))) q += 1;
      break;
  }
  return int64_t(q);
}

constexpr Rounding kModes[] = {Rounding::Floor, Rounding::HalfUp, Rounding::HalfEven};

TEST(FixedPoint, RangeLimits) {
  EXPECT_EQ(max_signed(8), 127);
  EXPECT_EQ(min_signed(8), -128);
  EXPECT_EQ(max_unsigned(8), 255);
  EXPECT_EQ(max_signed(20), 524287);
  EXPECT_EQ(min_signed(20), -524288);
  EXPECT_EQ(max_unsigned(4), 15);
  EXPECT_EQ(max_signed(64), kMax64);
  EXPECT_EQ(min_signed(64), kMin64);
  EXPECT_EQ(max_signed(1), 0);
  EXPECT_EQ(min_signed(1), -1);
  EXPECT_EQ(max_unsigned(0), 0);
  static_assert(saturate(300, 8) == 127, "usable in constant expressions");
}

TEST(FixedPoint, SaturateBothEnds) {
  EXPECT_EQ(saturate(200, 8), 127);
  EXPECT_EQ(saturate(-200, 8), -128);
  EXPECT_EQ(saturate(127, 8), 127);
  EXPECT_EQ(saturate(-128, 8), -128);
  EXPECT_EQ(saturate(128, 8), 127);
  EXPECT_EQ(saturate(-129, 8), -128);
  EXPECT_EQ(saturate(524288, 20), 524287);
  EXPECT_EQ(saturate(-524289, 20), -524288);
  EXPECT_EQ(saturate(kMax64, 64), kMax64);
  EXPECT_EQ(saturate(kMin64, 16), -32768);
  EXPECT_EQ(saturate_unsigned(-1, 4), 0);
  EXPECT_EQ(saturate_unsigned(16, 4), 15);
  EXPECT_EQ(saturate_unsigned(15, 4), 15);
  EXPECT_EQ(saturate_unsigned(kMin64, 16), 0);
  EXPECT_EQ(saturate_unsigned(kMax64, 63), kMax64);
  EXPECT_TRUE(fits(-128, 8));
  EXPECT_FALSE(fits(128, 8));
  EXPECT_TRUE(fits_unsigned(255, 8));
  EXPECT_FALSE(fits_unsigned(-1, 8));
}

TEST(FixedPoint, WrapMatchesModularArithmetic) {
  EXPECT_EQ(wrap(128, 8), -128);
  EXPECT_EQ(wrap(255, 8), -1);
  EXPECT_EQ(wrap(256, 8), 0);
  EXPECT_EQ(wrap(-129, 8), 127);
  EXPECT_EQ(wrap_unsigned(-1, 4), 15);
  EXPECT_EQ(wrap_unsigned(17, 4), 1);
  EXPECT_EQ(wrap(kMin64, 64), kMin64);
  EXPECT_EQ(wrap(kMax64, 63), -1);  // 2^63 - 1 = 2^62 + (2^62 - 1), the low 63 bits all ones
  for (int bits = 1; bits <= 20; ++bits) {
    const int64_t m = int64_t(1) << bits;
    for (int64_t x = -3000; x <= 3000; x += 7) {
      const int64_t u = ((x % m) + m) % m;  // Euclidean remainder
      EXPECT_EQ(wrap_unsigned(x, bits), u) << x << " " << bits;
      EXPECT_EQ(wrap(x, bits), u >= m / 2 ? u - m : u) << x << " " << bits;
    }
  }
}

TEST(FixedPoint, RoundingModesOnHalves) {
  // -5 / 2 = -2.5, -7 / 2 = -3.5, 5 / 2 = 2.5, -6 / 4 = -1.5
  EXPECT_EQ(shift_right_round(-5, 1, Rounding::Floor), -3);
  EXPECT_EQ(shift_right_round(-5, 1, Rounding::HalfUp), -2);
  EXPECT_EQ(shift_right_round(-5, 1, Rounding::HalfEven), -2);
  EXPECT_EQ(shift_right_round(-7, 1, Rounding::Floor), -4);
  EXPECT_EQ(shift_right_round(-7, 1, Rounding::HalfUp), -3);
  EXPECT_EQ(shift_right_round(-7, 1, Rounding::HalfEven), -4);
  EXPECT_EQ(shift_right_round(5, 1, Rounding::HalfUp), 3);
  EXPECT_EQ(shift_right_round(5, 1, Rounding::HalfEven), 2);
  EXPECT_EQ(shift_right_round(-6, 2, Rounding::HalfUp), -1);
  EXPECT_EQ(shift_right_round(-6, 2, Rounding::HalfEven), -2);
  EXPECT_EQ(shift_right_round(-6, 2, Rounding::Floor), -2);
  // Not a tie: -1.25 and -1.75.
  EXPECT_EQ(shift_right_round(-5, 2, Rounding::HalfUp), -1);
  EXPECT_EQ(shift_right_round(-7, 2, Rounding::HalfEven), -2);
}

TEST(FixedPoint, ShiftRightRoundMatchesDivision) {
  for (Rounding mode : kModes) {
    for (int s = 0; s <= 12; ++s) {
      for (int64_t x = -1000; x <= 1000; ++x) {
        ASSERT_EQ(shift_right_round(x, s, mode), ref_div_round(x, __int128(1) << s, mode)) << x << " >> " << s;
      }
    }
    std::mt19937_64 rng(7);
    for (int i = 0; i < 20000; ++i) {
      const int64_t x = int64_t(rng());
      const int s = int(rng() % 64);
      ASSERT_EQ(shift_right_round(x, s, mode), ref_div_round(x, __int128(1) << s, mode)) << x << " >> " << s;
    }
  }
}

TEST(FixedPoint, ShiftExtremes) {
  // INT64_MIN / 2^64 = -0.5 exactly; INT64_MIN / 2^63 = -1 exactly.
  EXPECT_EQ(shift_right_round(kMin64, 64, Rounding::HalfUp), 0);
  EXPECT_EQ(shift_right_round(kMin64, 64, Rounding::HalfEven), 0);
  EXPECT_EQ(shift_right_round(kMin64, 64, Rounding::Floor), -1);
  EXPECT_EQ(shift_right_round(kMin64, 63, Rounding::HalfEven), -1);
  EXPECT_EQ(shift_right_round(kMax64, 63, Rounding::HalfUp), 1);
  EXPECT_EQ(shift_right_round(kMax64, 63, Rounding::Floor), 0);
  EXPECT_EQ(shift_right_round(-1, 100, Rounding::Floor), -1);
  EXPECT_EQ(shift_right_round(-1, 100, Rounding::HalfUp), 0);
  EXPECT_EQ(shift_right_round(12345, 1000, Rounding::HalfEven), 0);
  // Negative shifts multiply and saturate.
  EXPECT_EQ(shift_right_round(3, -2, Rounding::HalfUp), 12);
  EXPECT_EQ(shift_right_round(-3, -2, Rounding::Floor), -12);
  EXPECT_EQ(shift_right_round(int64_t(1) << 62, -1, Rounding::HalfUp), kMax64);
  EXPECT_EQ(shift_right_round(-(int64_t(1) << 62), -1, Rounding::HalfUp), kMin64);
  EXPECT_EQ(shift_right_round(-(int64_t(1) << 62) - 1, -1, Rounding::HalfUp), kMin64);
  EXPECT_EQ(shift_right_round(1, -63, Rounding::HalfUp), kMax64);
  EXPECT_EQ(shift_right_round(0, -200, Rounding::HalfUp), 0);
}

TEST(FixedPoint, MultiplyShiftMatchesDivision) {
  std::mt19937_64 rng(11);
  for (Rounding mode : kModes) {
    for (int i = 0; i < 20000; ++i) {
      const int64_t a = int64_t(int32_t(rng()));
      const int64_t b = int64_t(int32_t(rng()));
      const int s = int(rng() % 40);
      ASSERT_EQ(multiply_shift(a, b, s, mode), ref_div_round(__int128(a) * b, __int128(1) << s, mode))
          << a << " * " << b << " >> " << s;
    }
  }
  EXPECT_EQ(multiply_shift(kMax64, kMax64, 0, Rounding::HalfUp), kMax64);
  EXPECT_EQ(multiply_shift(kMin64, kMax64, 0, Rounding::HalfUp), kMin64);
  EXPECT_EQ(multiply_shift(kMin64, kMin64, 126, Rounding::HalfUp), 1);  // 2^126 / 2^126
  EXPECT_EQ(multiply_shift(kMin64, 3, 64, Rounding::HalfEven), -2);     // -1.5 -> -2
  EXPECT_EQ(multiply_shift(kMin64, 3, 64, Rounding::HalfUp), -1);       // -1.5 -> -1
}

// A row saturated to `bits` and requantized, against saturate() and the
// 128-bit requantize() value by value: accumulators of 8 to 40 bits,
// multipliers inside and outside 32 bits, shifts 0 to 63, values over the
// whole int32 range and exact halves, in every rounding mode.
template <Rounding M>
void check_saturate_requantize_row() {
  std::mt19937_64 rng(11 + uint64_t(M));
  std::vector<int32_t> x(64);
  std::vector<int64_t> out(64);
  for (int bits : {8, 20, 24, 32, 40}) {
    for (int rep = 0; rep < 200; ++rep) {
      Requant q;
      q.shift = int(rng() % 64);
      q.multiplier = rep % 7 == 0 ? int64_t(rng() >> 20) : int64_t(rng() >> 33);  // 44 or 31 bits
      for (size_t j = 0; j < x.size(); ++j) {
        const uint64_t r = rng();
        x[j] = j % 4 == 0 ? int32_t(r) : int32_t(int64_t(r % 2000001) - 1000000) >> (r % 16);
        if (j % 8 == 1 && q.shift > 0 && q.multiplier % 2 == 1)  // a product exactly half way
          x[j] = int32_t(int64_t(1) << (q.shift - 1 < 30 ? q.shift - 1 : 30));
      }
      const uint64_t saturations = saturate_requantize_row<M>(x.data(), x.size(), bits, q, out.data());
      uint64_t expected_saturations = 0;
      for (size_t j = 0; j < x.size(); ++j) {
        const int64_t s = saturate(x[j], bits);
        expected_saturations += s != x[j];
        ASSERT_EQ(out[j], requantize(s, q, M))
            << "bits " << bits << " x " << x[j] << " q " << q.multiplier << " >> " << q.shift;
      }
      EXPECT_EQ(saturations, expected_saturations);
    }
  }
}

TEST(FixedPoint, SaturateRequantizeRowMatchesTheValueByValueFormulas) {
  check_saturate_requantize_row<Rounding::Floor>();
  check_saturate_requantize_row<Rounding::HalfUp>();
  check_saturate_requantize_row<Rounding::HalfEven>();
}

TEST(FixedPoint, RequantFromDyadicScaleIsExact) {
  // 0.75 = 49152 * 2^-16 with a 16-bit multiplier in [2^15, 2^16).
  const Requant q = requant_from_scale(0.75, 16);
  EXPECT_EQ(q.multiplier, 49152);
  EXPECT_EQ(q.shift, 16);
  EXPECT_EQ(q.scale(), 0.75);
  for (int64_t x = -20000; x <= 20000; ++x) {
    ASSERT_EQ(requantize(x, q, Rounding::HalfUp), ref_div_round(3 * x, 4, Rounding::HalfUp)) << x;
    ASSERT_EQ(requantize(x, q, Rounding::HalfEven), ref_div_round(3 * x, 4, Rounding::HalfEven)) << x;
  }
  // A power of two needs only one multiplier bit: 2^-5 -> (1, 5).
  const Requant p = requant_from_scale(1.0 / 32, 1);
  EXPECT_EQ(p.multiplier, 1);
  EXPECT_EQ(p.shift, 5);
}

TEST(FixedPoint, RequantOneThird) {
  // 2^17 / 3 = 43690.67 -> 43691; the pair's error is x / 393216
  // (43691 * 3 - 2^17 = 1), below 1/6 for |x| < 65536, and x / 3 is never
  // closer than 1/6 to a rounding boundary: requantize is exactly round(x / 3).
  const Requant q = requant_from_scale(1.0 / 3.0, 16);
  EXPECT_EQ(q.multiplier, 43691);
  EXPECT_EQ(q.shift, 17);
  for (int64_t x = -65535; x <= 65535; ++x) {
    ASSERT_EQ(requantize(x, q, Rounding::HalfUp), ref_div_round(x, 3, Rounding::HalfUp)) << x;
  }
}

TEST(FixedPoint, RequantRationalScalesWithinBound) {
  std::mt19937_64 rng(3);
  for (int bits : {8, 16, 24, 31}) {
    for (int i = 0; i < 2000; ++i) {
      const int64_t num = 1 + int64_t(rng() % 100000);
      const int64_t den = 1 + int64_t(rng() % 100000);
      if (num >= (den << (bits - 1))) continue;  // scales >= 2^(bits-1) need a left shift
      const Requant q = requant_from_scale(double(num) / double(den), bits);
      ASSERT_GE(q.multiplier, int64_t(1) << (bits - 1));
      ASSERT_LT(q.multiplier, int64_t(1) << bits);
      // |m 2^-s - num/den| <= (num/den) 2^-bits, up to the double rounding of
      // num/den (relative 2^-53, below bound * 2^-21 for bits <= 31) and the
      // integer truncation of the bound: checked in integers with that slack.
      const __int128 lhs = (__int128(q.multiplier) * den - (__int128(num) << q.shift));
      const __int128 abs_lhs = lhs < 0 ? -lhs : lhs;
      const __int128 bound = (__int128(num) << q.shift) >> bits;
      ASSERT_LE(abs_lhs, bound + bound / (__int128(1) << 20) + 2) << num << "/" << den << " bits " << bits;
      // Within 1 of the exactly rounded product while |x * scale| <= 2^(bits-1).
      for (int j = 0; j < 20; ++j) {
        const int64_t limit = std::max<int64_t>(1, ((int64_t(1) << (bits - 1)) * den) / num);
        const int64_t x = int64_t(rng() % uint64_t(2 * limit + 1)) - limit;
        const int64_t exact = ref_div_round(__int128(x) * num, den, Rounding::HalfUp);
        ASSERT_LE(std::abs(requantize(x, q, Rounding::HalfUp) - exact), 1) << x << " * " << num << "/" << den;
      }
    }
  }
}

TEST(FixedPoint, RequantEdgeCases) {
  // Rounds up to the next power of two: 1 - 2^-20 with 16 bits -> 2^16, kept as (2^15, 15) = 1.0.
  const Requant one = requant_from_scale(1.0 - std::ldexp(1.0, -20), 16);
  EXPECT_EQ(one.multiplier, 32768);
  EXPECT_EQ(one.shift, 15);
  // The largest scale with shift 0.
  const Requant big = requant_from_scale(32768.0, 16);
  EXPECT_EQ(big.multiplier, 32768);
  EXPECT_EQ(big.shift, 0);
  // Tiny scales hit the 63-bit shift limit and lose significant bits.
  const Requant tiny = requant_from_scale(std::ldexp(1.0, -70), 16);
  EXPECT_EQ(tiny.shift, 63);
  EXPECT_EQ(tiny.multiplier, 0);
  EXPECT_THROW(requant_from_scale(65536.0, 16), Error);
  EXPECT_THROW(requant_from_scale(0.0, 16), Error);
  EXPECT_THROW(requant_from_scale(-0.5, 16), Error);
  EXPECT_THROW(requant_from_scale(std::nan(""), 16), Error);
  EXPECT_THROW(requant_from_scale(INFINITY, 16), Error);
  EXPECT_THROW(requant_from_scale(0.5, 0), Error);
  EXPECT_THROW(requant_from_scale(0.5, 63), Error);
}

TEST(FixedPoint, ToFixedRoundsOnceAndSaturates) {
  EXPECT_EQ(to_fixed(-2.5, 0, 8, Rounding::HalfEven), -2);
  EXPECT_EQ(to_fixed(-2.5, 0, 8, Rounding::HalfUp), -2);
  EXPECT_EQ(to_fixed(-2.5, 0, 8, Rounding::Floor), -3);
  EXPECT_EQ(to_fixed(-3.5, 0, 8, Rounding::HalfEven), -4);
  EXPECT_EQ(to_fixed(-3.5, 0, 8, Rounding::HalfUp), -3);
  EXPECT_EQ(to_fixed(2.5, 0, 8, Rounding::HalfUp), 3);
  EXPECT_EQ(to_fixed(2.5, 0, 8, Rounding::HalfEven), 2);
  EXPECT_EQ(to_fixed(-2.4999999, 0, 8, Rounding::HalfEven), -2);
  EXPECT_EQ(to_fixed(-2.5000001, 0, 8, Rounding::HalfUp), -3);
  // Q4.4: 1.03125 * 16 = 16.5
  EXPECT_EQ(to_fixed(1.03125, 4, 8, Rounding::HalfEven), 16);
  EXPECT_EQ(to_fixed(1.03125, 4, 8, Rounding::HalfUp), 17);
  // Negative frac_bits: 40 / 16 = 2.5.
  EXPECT_EQ(to_fixed(40.0, -4, 8, Rounding::HalfEven), 2);
  // Saturation at both ends, signed and unsigned.
  EXPECT_EQ(to_fixed(1000.0, 0, 8, Rounding::HalfUp), 127);
  EXPECT_EQ(to_fixed(-1000.0, 0, 8, Rounding::HalfUp), -128);
  EXPECT_EQ(to_fixed(127.5, 0, 8, Rounding::HalfUp), 127);
  EXPECT_EQ(to_fixed(-128.5, 0, 8, Rounding::Floor), -128);
  EXPECT_EQ(to_fixed_unsigned(-1.0, 0, 4, Rounding::HalfUp), 0);
  EXPECT_EQ(to_fixed_unsigned(300.0, 0, 8, Rounding::HalfUp), 255);
  EXPECT_EQ(to_fixed_unsigned(0.99998, 15, 16, Rounding::HalfUp), 32767);  // 32766.3
  // Specials and the int64 limits.
  EXPECT_EQ(to_fixed(std::nan(""), 0, 16, Rounding::HalfUp), 0);
  EXPECT_EQ(to_fixed(INFINITY, 0, 16, Rounding::HalfUp), 32767);
  EXPECT_EQ(to_fixed(-INFINITY, 0, 16, Rounding::HalfUp), -32768);
  EXPECT_EQ(to_fixed(1e30, 0, 64, Rounding::HalfUp), kMax64);
  EXPECT_EQ(to_fixed(-9223372036854775808.0, 0, 64, Rounding::HalfUp), kMin64);
  EXPECT_EQ(to_fixed(-1e30, 0, 64, Rounding::HalfUp), kMin64);
  EXPECT_EQ(to_fixed(4503599627370497.0, 0, 64, Rounding::HalfEven), 4503599627370497);  // 2^52 + 1
  // A tiny negative value floors to -1 even when the scaling underflows.
  EXPECT_EQ(to_fixed(-1e-300, 0, 8, Rounding::Floor), -1);
  EXPECT_EQ(to_fixed(-1e-300, -1000, 8, Rounding::Floor), -1);
  EXPECT_EQ(to_fixed(-1e-300, -1000, 8, Rounding::HalfUp), 0);
  EXPECT_EQ(from_fixed(-40, 4), -2.5);
  EXPECT_EQ(from_fixed(3, -2), 12.0);
}

TEST(FixedPoint, ToFixedMatchesIntegerRounding) {
  // v = n / 2^k exactly; v * 2^f rounded must equal n * 2^f / 2^k rounded.
  std::mt19937_64 rng(5);
  for (Rounding mode : kModes) {
    for (int i = 0; i < 20000; ++i) {
      const int64_t n = int64_t(int32_t(rng()));
      const int k = int(rng() % 30);
      const int f = int(rng() % 20);
      const double v = std::ldexp(double(n), -k);
      const int64_t expect = f >= k ? n << (f - k) : ref_div_round(n, __int128(1) << (k - f), mode);
      ASSERT_EQ(to_fixed(v, f, 64, mode), expect) << n << " 2^-" << k << " frac " << f;
    }
  }
}

}  // namespace
}  // namespace edrnr::fx
