// Custom float formats against hand-computed values, an exact rational
// reference in 128-bit integers, and the machine's own IEEE binary32/binary16.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "core/custom_float.h"
#include "core/error.h"

namespace edrnr {
namespace {

using u128 = unsigned __int128;

bool same_bits(double a, double b) {
  if (a != a && b != b) return true;
  return std::bit_cast<uint64_t>(a) == std::bit_cast<uint64_t>(b);
}

int bit_width128(u128 x) {
  int n = 0;
  while (x != 0) {
    x >>= 1;
    ++n;
  }
  return n;
}

// The correctly rounded (ties to even) value of (-1)^neg * num / den * 2^exp2
// in format f, computed with integer division only. Needs num/den well
// inside 128 bits after the shifts (operands below 2^60 suffice).
double ref_round(const FloatFormat& f, bool neg, u128 num, u128 den, int exp2) {
  const double sign = neg ? -1.0 : 1.0;
  if (num == 0) return sign * 0.0;
  // E = floor(log2(num / den)).
  int e = bit_width128(num) - bit_width128(den);
  if (e >= 0 ? num < (den << e) : (num << -e) < den) --e;
  const int value_exp = e + exp2;  // value in [2^value_exp, 2^(value_exp+1))
  const int p = f.significand_bits();
  const double overflow = f.specials() == FloatSpecials::Ieee ? INFINITY : f.max_finite();
  if (value_exp > f.max_exponent()) return sign * overflow;
  if (value_exp < f.min_exponent() - p - 1) return sign * 0.0;  // below half the smallest subnormal
  const int quantum_exp =
      (f.subnormals() ? std::max(value_exp, f.min_exponent()) : value_exp) - p + 1;  // result = m 2^quantum_exp
  const int sh = exp2 - quantum_exp;
  u128 n = num, d = den;
  if (sh >= 0)
    n <<= sh;
  else
    d <<= -sh;
  u128 m = n / d;
  const u128 r = n % d;
  if (2 * r > d || (2 * r == d && (m & 1) != 0)) ++m;
  const double v = std::ldexp(double(uint64_t(m)), quantum_exp);
  if (v > f.max_finite()) return sign * overflow;
  if (!f.subnormals() && v < f.min_normal()) return sign * 0.0;
  return sign * v;
}

// A random value of format f: m 2^e with m < 2^p, exponent in [lo, hi].
struct Exact {
  bool neg;
  uint64_t m;  // significand as an integer
  int e;       // value = m 2^e
  double value() const { return (neg ? -1.0 : 1.0) * std::ldexp(double(m), e); }
};

Exact random_value(const FloatFormat& f, std::mt19937_64& rng, int lo, int hi) {
  const int p = f.significand_bits();
  Exact x;
  x.neg = (rng() & 1) != 0;
  const int value_exp = lo + int(rng() % uint64_t(hi - lo + 1));
  if (value_exp < f.min_exponent()) {  // subnormal (or zero without subnormals)
    x.m = f.subnormals() ? rng() % (uint64_t(1) << (p - 1)) : 0;
    x.e = f.min_exponent() - p + 1;
  } else {
    x.m = (uint64_t(1) << (p - 1)) | (rng() % (uint64_t(1) << (p - 1)));
    x.e = value_exp - p + 1;
  }
  return x;
}

std::vector<FloatFormat> test_formats() {
  return {
      FloatFormat(8, 16, false, FloatSpecials::Saturate),  // the chip's default
      FloatFormat(8, 16, true, FloatSpecials::Ieee),      FloatFormat(4, 4, true, FloatSpecials::Saturate),
      FloatFormat(4, 4, false, FloatSpecials::Ieee),      FloatFormat(5, 11, true, FloatSpecials::Ieee),  // binary16
      FloatFormat(8, 25, true, FloatSpecials::Ieee),  // the widest allowed significand
      FloatFormat(3, 2, true, FloatSpecials::Saturate),   FloatFormat(6, 12, false, FloatSpecials::Saturate),
  };
}

TEST(CustomFloat, FormatConstants) {
  const FloatFormat chip(8, 16);
  EXPECT_EQ(chip.total_bits(), 24);
  EXPECT_EQ(chip.bias(), 127);
  EXPECT_EQ(chip.min_exponent(), -126);
  EXPECT_EQ(chip.max_exponent(), 127);
  EXPECT_EQ(chip.max_finite(), std::ldexp(2.0 - std::ldexp(1.0, -15), 127));
  EXPECT_EQ(chip.min_normal(), std::ldexp(1.0, -126));
  EXPECT_EQ(chip.min_positive(), std::ldexp(1.0, -126));
  EXPECT_EQ(chip.epsilon(), std::ldexp(1.0, -15));
  const FloatFormat half(5, 11, true, FloatSpecials::Ieee);  // IEEE binary16's well-known limits
  EXPECT_EQ(half.total_bits(), 16);
  EXPECT_EQ(half.max_finite(), 65504.0);
  EXPECT_EQ(half.min_normal(), 6.103515625e-05);
  EXPECT_EQ(half.min_positive(), 5.9604644775390625e-08);
  const FloatFormat tiny(4, 4, true);
  EXPECT_EQ(tiny.max_finite(), 240.0);  // 1.111b * 2^7
  EXPECT_EQ(tiny.min_normal(), 0.015625);
  EXPECT_EQ(tiny.min_positive(), 0.001953125);
  EXPECT_NE(chip.name().find("e8p16"), std::string::npos);
  EXPECT_EQ(FloatFormat(), FloatFormat(8, 24, true, FloatSpecials::Ieee));
  EXPECT_NE(FloatFormat(8, 16, true), FloatFormat(8, 16, false));
}

TEST(CustomFloat, ConstructorRejectsUnsafeWidths) {
  EXPECT_THROW(FloatFormat(1, 10), Error);
  EXPECT_THROW(FloatFormat(9, 10), Error);
  EXPECT_THROW(FloatFormat(8, 1), Error);
  EXPECT_THROW(FloatFormat(8, 26), Error);  // 2 * 26 + 2 > 53: double rounding could bite
  try {
    FloatFormat(8, 26);
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("significand_bits"), std::string::npos);
  }
}

TEST(CustomFloat, TiesToEvenAndNeighbours) {
  const FloatFormat f(8, 16);  // spacing 2^-15 in [1, 2)
  const double u = std::ldexp(1.0, -15);
  const double tie_down = 1.0 + u / 2;    // between 1 (even) and 1 + u (odd)
  const double tie_up = 1.0 + 3 * u / 2;  // between 1 + u (odd) and 1 + 2u (even)
  EXPECT_EQ(f.round(tie_down), 1.0);
  EXPECT_EQ(f.round(tie_up), 1.0 + 2 * u);
  EXPECT_EQ(f.round(std::nextafter(tie_down, 2.0)), 1.0 + u);
  EXPECT_EQ(f.round(std::nextafter(tie_up, 0.0)), 1.0 + u);
  EXPECT_EQ(f.round(-tie_down), -1.0);
  EXPECT_EQ(f.round(-tie_up), -(1.0 + 2 * u));
  EXPECT_EQ(f.round(std::nextafter(-tie_down, -2.0)), -(1.0 + u));
  // A carry into the exponent: halfway between the largest value below 2 and 2.
  EXPECT_EQ(f.round(2.0 - u / 2), 2.0);
  EXPECT_EQ(f.round(std::nextafter(2.0 - u / 2, 0.0)), 2.0 - u);
  // Integers: 65537 lies halfway between 65536 and 65538 (spacing 2 above 2^16).
  EXPECT_EQ(f.round(65537.0), 65536.0);
  EXPECT_EQ(f.round(65539.0), 65540.0);
  EXPECT_EQ(f.round(65538.0), 65538.0);
  EXPECT_TRUE(f.is_representable(65538.0));
  EXPECT_FALSE(f.is_representable(65537.0));
}

TEST(CustomFloat, SubnormalBoundaries) {
  const FloatFormat f(4, 4, true);  // min subnormal s = 2^-9, min normal 2^-6 = 8 s
  const double s = std::ldexp(1.0, -9);
  EXPECT_EQ(f.round(s / 2), 0.0);  // tie between 0 (even) and s
  EXPECT_FALSE(std::signbit(f.round(s / 2)));
  EXPECT_TRUE(std::signbit(f.round(-s / 2)));  // -0
  EXPECT_EQ(f.round(std::nextafter(s / 2, 1.0)), s);
  EXPECT_EQ(f.round(1.5 * s), 2 * s);  // tie to even multiple
  EXPECT_EQ(f.round(2.5 * s), 2 * s);
  EXPECT_EQ(f.round(3.5 * s), 4 * s);
  EXPECT_EQ(f.round(7 * s), 7 * s);    // largest subnormal
  EXPECT_EQ(f.round(7.5 * s), 8 * s);  // tie to the (even) smallest normal
  EXPECT_EQ(f.round(std::nextafter(7.5 * s, 0.0)), 7 * s);
  EXPECT_EQ(f.round(8.5 * s), 8 * s);  // first normal binade has the same spacing
  EXPECT_EQ(f.round(9.5 * s), 10 * s);
  EXPECT_EQ(f.round(-3.25 * s), -3 * s);
  EXPECT_EQ(f.round(1e-300), 0.0);
  EXPECT_EQ(f.round(4.9e-324), 0.0);  // a binary64 subnormal

  const FloatFormat ftz(4, 4, false);  // flush to zero
  const double mn = 8 * s;
  const double threshold = mn * (1 - std::ldexp(1.0, -5));  // rounds (unbounded) to min normal: a tie to even
  EXPECT_EQ(ftz.round(threshold), mn);
  EXPECT_EQ(ftz.round(std::nextafter(threshold, 0.0)), 0.0);
  EXPECT_EQ(ftz.round(0.9 * mn), 0.0);
  EXPECT_EQ(ftz.round(7 * s), 0.0);
  EXPECT_TRUE(std::signbit(ftz.round(-0.5 * mn)));
  EXPECT_EQ(ftz.round(mn), mn);
  EXPECT_EQ(ftz.mul(mn, 0.5), 0.0);  // the exact product is below min normal
  EXPECT_EQ(ftz.decode(0x01), 0.0);  // a subnormal pattern reads as zero
  EXPECT_EQ(f.decode(0x01), s);
}

TEST(CustomFloat, OverflowPolicies) {
  const FloatFormat sat(4, 4, true, FloatSpecials::Saturate);  // max 240, next would be 256
  const FloatFormat ieee(4, 4, true, FloatSpecials::Ieee);
  EXPECT_EQ(sat.round(247.999), 240.0);
  EXPECT_EQ(sat.round(248.0), 240.0);  // the tie goes to 256, which overflows
  EXPECT_EQ(sat.round(1e9), 240.0);
  EXPECT_EQ(sat.round(-1e9), -240.0);
  EXPECT_EQ(sat.round(INFINITY), 240.0);
  EXPECT_EQ(sat.round(-INFINITY), -240.0);
  EXPECT_EQ(sat.round(NAN), 0.0);
  EXPECT_EQ(ieee.round(std::nextafter(248.0, 0.0)), 240.0);
  EXPECT_EQ(ieee.round(248.0), INFINITY);
  EXPECT_EQ(ieee.round(-248.0), -INFINITY);
  EXPECT_TRUE(std::isnan(ieee.round(NAN)));
  EXPECT_EQ(sat.mul(16.0, 16.0), 240.0);
  EXPECT_EQ(ieee.mul(16.0, 16.0), INFINITY);
  EXPECT_EQ(sat.add(240.0, 8.0), 240.0);
  EXPECT_EQ(ieee.add(240.0, 7.0), 240.0);  // 247 rounds down
  // Division by zero and invalid operations.
  EXPECT_EQ(sat.div(1.0, 0.0), 240.0);
  EXPECT_EQ(sat.div(-1.0, 0.0), -240.0);
  EXPECT_EQ(sat.div(1.0, -0.0), -240.0);
  EXPECT_EQ(sat.div(0.0, 0.0), 0.0);
  EXPECT_EQ(sat.sqrt(-1.0), 0.0);
  EXPECT_TRUE(std::signbit(sat.sqrt(-0.0)));
  EXPECT_EQ(ieee.div(1.0, 0.0), INFINITY);
  EXPECT_TRUE(std::isnan(ieee.div(0.0, 0.0)));
  EXPECT_TRUE(std::isnan(ieee.sqrt(-1.0)));
}

TEST(CustomFloat, OperationsMatchExactRationalReference) {
  std::mt19937_64 rng(2024);
  for (const FloatFormat& f : test_formats()) {
    SCOPED_TRACE(f.name());
    const int lo = f.min_exponent() - f.significand_bits();  // reach into subnormals
    const int hi = f.max_exponent();
    for (int i = 0; i < 4000; ++i) {
      const Exact a = random_value(f, rng, lo, hi);
      const Exact b = random_value(f, rng, lo, hi);
      // mul: exact product m_a m_b 2^(e_a + e_b).
      const double mul_ref = ref_round(f, a.neg != b.neg, u128(a.m) * b.m, 1, a.e + b.e);
      ASSERT_TRUE(same_bits(f.mul(a.value(), b.value()), mul_ref)) << a.value() << " * " << b.value();
      // div: m_a / m_b 2^(e_a - e_b).
      if (b.m != 0) {
        const double div_ref = ref_round(f, a.neg != b.neg, a.m, b.m, a.e - b.e);
        ASSERT_TRUE(same_bits(f.div(a.value(), b.value()), div_ref)) << a.value() << " / " << b.value();
      }
      // sqrt of |a|: m 2^e with e even, isqrt of the significand scaled by 4^k.
      if (a.m != 0) {
        int e = a.e;
        u128 m = a.m;
        if (e % 2 != 0) {
          m <<= 1;
          --e;
        }
        m <<= 80;  // sqrt keeps 40 extra bits: far more than p + 2, and no tie is possible
        e -= 80;
        u128 s = u128(std::sqrt(double(m)));
        while (s * s > m) --s;
        while ((s + 1) * (s + 1) <= m) ++s;
        // Round-to-odd the truncated root (sticky bit), then the reference rounds it.
        const u128 odd = (s * s == m) ? s << 1 : (s << 1) | 1;
        const double sqrt_ref = ref_round(f, false, odd, 1, e / 2 - 1);
        ASSERT_TRUE(same_bits(f.sqrt(std::fabs(a.value())), sqrt_ref)) << "sqrt " << std::fabs(a.value());
      }
      // add / sub / fma with operands whose exponents are within 40 of each other.
      const Exact c = random_value(f, rng, std::max(lo, a.e + f.significand_bits() - 40),
                                   std::min(hi, a.e + f.significand_bits() + 40));
      const int base = std::min(a.e, c.e);
      const __int128 sa = (a.neg ? -1 : 1) * (__int128(a.m) << (a.e - base));
      const __int128 sc = (c.neg ? -1 : 1) * (__int128(c.m) << (c.e - base));
      for (int op = 0; op < 2; ++op) {
        const __int128 sum = op == 0 ? sa + sc : sa - sc;
        const bool neg = sum < 0;
        // An exact zero sum is +0 (round to nearest), except (-0) + (-0).
        double ref = ref_round(f, neg, u128(neg ? -sum : sum), 1, base);
        const double got = op == 0 ? f.add(a.value(), c.value()) : f.sub(a.value(), c.value());
        if (sum == 0) {
          ASSERT_EQ(got, 0.0);
        } else {
          ASSERT_TRUE(same_bits(got, ref)) << a.value() << (op == 0 ? " + " : " - ") << c.value();
        }
      }
      // fma: a * b + c with c near the product's magnitude.
      const int prod_e = a.e + b.e;
      const int d_lo = std::max(lo, prod_e + 2 * f.significand_bits() - 45);
      const int d_hi = std::min(hi, prod_e + 2 * f.significand_bits() + 10);
      if (d_lo > d_hi) continue;  // the product is far outside the format's range
      const Exact d = random_value(f, rng, d_lo, d_hi);
      const int fbase = std::min(prod_e, d.e);
      if (a.m != 0 && b.m != 0 && d.e - fbase <= 60 && prod_e - fbase <= 60) {
        const __int128 sp = ((a.neg != b.neg) ? -1 : 1) * (__int128(u128(a.m) * b.m) << (prod_e - fbase));
        const __int128 sd = (d.neg ? -1 : 1) * (__int128(d.m) << (d.e - fbase));
        const __int128 sum = sp + sd;
        const bool neg = sum < 0;
        const double got = f.fma(a.value(), b.value(), d.value());
        if (sum == 0) {
          ASSERT_EQ(got, 0.0);
        } else {
          const double ref = ref_round(f, neg, u128(neg ? -sum : sum), 1, fbase);
          ASSERT_TRUE(same_bits(got, ref)) << a.value() << " * " << b.value() << " + " << d.value();
        }
      }
    }
  }
}

TEST(CustomFloat, KnownResults) {
  const FloatFormat f(8, 16);
  // 1/3 in p = 16: 0.0101...b; 2^17/3 = 43690.67 -> 43691 * 2^-17.
  EXPECT_EQ(f.div(1.0, 3.0), 43691.0 / 131072.0);
  // 1/10: 2^19/10 = 52428.8 -> 52429 * 2^-19.
  EXPECT_EQ(f.div(1.0, 10.0), 52429.0 / 524288.0);
  EXPECT_EQ(f.round(0.1), 52429.0 / 524288.0);
  // 255 * 257 = 65535 needs 16 bits: exact. 257 * 257 = 66049 rounds to a multiple of 2: 66048 (tie to even).
  EXPECT_EQ(f.mul(255.0, 257.0), 65535.0);
  EXPECT_EQ(f.mul(257.0, 257.0), 66048.0);
  // Absorption: 1 + 2^-40 is 1.
  EXPECT_EQ(f.add(1.0, std::ldexp(1.0, -40)), 1.0);
  EXPECT_EQ(f.sub(1.0, std::ldexp(1.0, -40)), 1.0);
  EXPECT_EQ(f.sub(1.0, 1.0), 0.0);
  // Perfect squares are exact.
  for (int k = 0; k < 256; ++k) EXPECT_EQ(f.sqrt(double(k) * k), double(k));
  EXPECT_EQ(f.sqrt(2.25), 1.5);
  EXPECT_EQ(f.sqrt(std::ldexp(1.0, -100)), std::ldexp(1.0, -50));
  // sqrt 2 = 1.0110101000001001111...b -> 1.011010100000101b (rounded up).
  EXPECT_EQ(f.sqrt(2.0), 46341.0 / 32768.0);
  EXPECT_EQ(f.neg(1.5), -1.5);
  EXPECT_EQ(f.abs(-1.5), 1.5);
}

TEST(CustomFloat, FusedMultiplyAddRoundsOnce) {
  const FloatFormat f(4, 4);
  // 1.125 * 1.125 = 1.265625 (1.010001b) rounds to 1.25 on its own, so
  // mul then add gives 0, but the exact a * b - 1.25 is 2^-6.
  EXPECT_EQ(f.sub(f.mul(1.125, 1.125), 1.25), 0.0);
  EXPECT_EQ(f.fma(1.125, 1.125, -1.25), 0.015625);
  // 0.75 * 0.875 = 21/32 = 1.0101b * 2^-1 is a midpoint of the p = 4 grid
  // (0.625 and 0.6875). Adding 2^-60 moves the exact sum just above it, which
  // the binary64 sum alone would lose (and then round the tie to even 0.625).
  const FloatFormat g(8, 4);
  EXPECT_EQ(g.fma(0.75, 0.875, 0.0), 0.625);
  EXPECT_EQ(g.fma(0.75, 0.875, std::ldexp(1.0, -60)), 0.6875);
  EXPECT_EQ(g.fma(0.75, 0.875, -std::ldexp(1.0, -60)), 0.625);
  EXPECT_EQ(g.fma(-0.75, 0.875, -std::ldexp(1.0, -60)), -0.6875);
  const Vec3d r = f.fma(Vec3d{1.125, 2.0, -1.0}, 1.125, Vec3d{-1.25, 0.5, 0.25});
  EXPECT_EQ(r, (Vec3d{0.015625, 2.75, -0.875}));
}

TEST(CustomFloat, MatchesHardwareBinary32) {
  const FloatFormat f;  // binary32
  std::mt19937_64 rng(99);
  auto random_float = [&] {
    const uint32_t bits = uint32_t(rng());
    float x;
    std::memcpy(&x, &bits, 4);
    return x;
  };
  for (int i = 0; i < 200000; ++i) {
    const float a = random_float(), b = random_float(), c = random_float();
    ASSERT_TRUE(same_bits(f.add(a, b), double(a + b))) << a << " + " << b;
    ASSERT_TRUE(same_bits(f.sub(a, b), double(a - b))) << a << " - " << b;
    ASSERT_TRUE(same_bits(f.mul(a, b), double(a * b))) << a << " * " << b;
    ASSERT_TRUE(same_bits(f.div(a, b), double(a / b))) << a << " / " << b;
    ASSERT_TRUE(same_bits(f.sqrt(a), double(std::sqrt(a)))) << "sqrt " << a;
    ASSERT_TRUE(same_bits(f.fma(a, b, c), double(std::fma(a, b, c)))) << a << " * " << b << " + " << c;
    uint64_t db = rng();
    double d;
    std::memcpy(&d, &db, 8);
    ASSERT_TRUE(same_bits(f.round(d), double(float(d)))) << d;
    if (a == a) {
      ASSERT_EQ(f.encode(a), std::bit_cast<uint32_t>(a));
    }
  }
}

TEST(CustomFloat, EncodeDecodeBinary16Exhaustive) {
  const FloatFormat h(5, 11, true, FloatSpecials::Ieee);
  for (uint32_t bits = 0; bits < 65536; ++bits) {
    _Float16 x;
    const uint16_t b16 = uint16_t(bits);
    std::memcpy(&x, &b16, 2);
    const double v = h.decode(bits);
    ASSERT_TRUE(same_bits(v, double(x))) << bits;
    if (v == v) {
      ASSERT_EQ(h.encode(v), bits);
    }
  }
}

TEST(CustomFloat, EncodeChipFormat) {
  const FloatFormat f(8, 16);  // 1 + 8 + 15 bits
  EXPECT_EQ(f.encode(1.0), 0x3F8000u);
  EXPECT_EQ(f.encode(-2.5), 0xC02000u);  // sign, exponent 128, fraction 0.25 * 2^15
  EXPECT_EQ(f.encode(0.0), 0u);
  EXPECT_EQ(f.encode(-0.0), 0x800000u);
  EXPECT_EQ(f.encode(f.max_finite()), 0x7F7FFFu);
  EXPECT_EQ(f.encode(1e300), 0x7F7FFFu);  // saturates
  // Every pattern below the infinity exponent reads back to itself.
  for (uint64_t bits = 0; bits < (uint64_t(1) << 24); bits += 997) {
    const uint64_t e = (bits >> 15) & 0xFF;
    if (e == 0 || e == 0xFF) continue;
    ASSERT_EQ(f.encode(f.decode(bits)), bits) << bits;
  }
  EXPECT_EQ(f.decode(0x7F8000), f.max_finite());  // the infinity pattern saturates
}

TEST(CustomFloat, FromFixedRoundsOnce) {
  const FloatFormat f(8, 16);
  EXPECT_EQ(f.from_fixed(799, 0), 799.0);
  EXPECT_EQ(f.from_fixed(3, 1), 1.5);
  EXPECT_EQ(f.from_fixed(-40, 4), -2.5);
  EXPECT_EQ(f.from_fixed(65537, 0), 65536.0);  // tie to even
  EXPECT_EQ(f.from_fixed(65537, -1), 131072.0);
  // 2^62 + 2^46 + 1: just above the midpoint of 2^62 and 2^62 + 2^47. A plain
  // conversion to double would drop the 1 and round the tie down.
  const int64_t q = (int64_t(1) << 62) + (int64_t(1) << 46) + 1;
  EXPECT_EQ(f.from_fixed(q, 0), std::ldexp(1.0, 62) + std::ldexp(1.0, 47));
  EXPECT_EQ(f.from_fixed(-q, 0), -(std::ldexp(1.0, 62) + std::ldexp(1.0, 47)));
  EXPECT_EQ(f.from_fixed(std::numeric_limits<int64_t>::min(), 0), -std::ldexp(1.0, 63));
  EXPECT_EQ(f.from_fixed(1, 5000), 0.0);
  EXPECT_EQ(f.from_fixed(1, -5000), f.max_finite());
  EXPECT_EQ(f.from_fixed(0, 3), 0.0);
}

TEST(CustomFloat, MinMaxAndFloor) {
  const FloatFormat f(8, 16);
  const FloatFormat ieee(8, 16, true, FloatSpecials::Ieee);
  EXPECT_EQ(f.min(1.0, -2.0), -2.0);
  EXPECT_EQ(f.max(1.0, -2.0), 1.0);
  EXPECT_TRUE(std::signbit(f.min(0.0, -0.0)));
  EXPECT_TRUE(std::signbit(f.min(-0.0, 0.0)));
  EXPECT_FALSE(std::signbit(f.max(-0.0, 0.0)));
  EXPECT_FALSE(std::signbit(f.max(0.0, -0.0)));
  EXPECT_EQ(f.min(NAN, 1.0), 0.0);
  EXPECT_TRUE(std::isnan(ieee.max(1.0, NAN)));
  EXPECT_EQ(floor_to_int(-0.5), -1);
  EXPECT_EQ(floor_to_int(2.999), 2);
  EXPECT_EQ(floor_to_int(-3.0), -3);
  EXPECT_EQ(floor_to_int(NAN), 0);
  EXPECT_EQ(floor_to_int(1e30), std::numeric_limits<int64_t>::max());
  EXPECT_EQ(fx::to_fixed(f.round(1.2), 8, 16, fx::Rounding::HalfUp), 307);  // 1.2 -> 39322 * 2^-15, * 256 = 307.2
}

TEST(CustomFloat, RoundingIsMonotoneAndWithinHalfUlp) {
  const FloatFormat f(8, 16);
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> dist(-300.0, 300.0);
  for (int i = 0; i < 100000; ++i) {
    double x = dist(rng), y = dist(rng);
    if (x > y) std::swap(x, y);
    const double rx = f.round(x), ry = f.round(y);
    ASSERT_LE(rx, ry) << x << " " << y;
    // |round(x) - x| <= half a unit in the last place: 2^(floor(log2|x|) - 16).
    if (x != 0.0) {
      const double half_ulp = std::ldexp(1.0, std::ilogb(x) - 16);
      ASSERT_LE(std::fabs(rx - x), half_ulp) << x;
    }
  }
}

}  // namespace
}  // namespace edrnr
