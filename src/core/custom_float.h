#pragma once
// Custom binary floating point, emulated exactly.
//
// A FloatFormat is an IEEE-754-style binary format with `exponent_bits`
// exponent bits and a `significand_bits`-bit significand p (the hidden bit
// included), so a value takes 1 + exponent_bits + (p - 1) bits. The bias is
// 2^(exponent_bits-1) - 1, normal exponents run from 1 - bias to bias, and the
// all-ones exponent is reserved for infinities and NaN (in both policies, so
// the finite values are the same). Rounding is always to nearest, ties to
// even.
//
// A value is a plain double that holds a number representable in the format
// (the result of round() or of one of the operations below). Each operation
// computes the exact result's double rounding (IEEE binary64, round to nearest
// even) and rounds that once more to the format. Because 53 >= 2p + 2 (the
// constructor enforces p <= 25) and the format's exponent range lies well
// inside binary64's, the second rounding equals a single correct rounding of
// the exact result for +, -, *, / and sqrt (Figueroa 1995, "When is double
// rounding innocuous?"; the product of two p-bit significands is even exact in
// binary64). The fused multiply-add rounds the double sum to odd first, which
// is correct for any p <= 51 (Boldo & Melquiond 2008). Correct rounding is
// monotone: x <= y implies round(x) <= round(y).
//
// Operands must be values of this format. Results are bit-identical on every
// IEEE-754 machine that evaluates double expressions in double (checked
// below), whatever the compiler, because correctly rounded results are unique.
#include <bit>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include "core/fixed_point.h"
#include "core/vec.h"

namespace edrnr {

static_assert(std::numeric_limits<double>::is_iec559 && std::numeric_limits<double>::digits == 53,
              "custom float emulation needs IEEE-754 binary64 doubles");
static_assert(FLT_EVAL_METHOD == 0, "custom float emulation needs double expressions evaluated in double (no x87)");

// What happens to results outside the finite range and to invalid operations.
//   Saturate: no infinities or NaN are ever produced. Overflow (and an
//             infinite input) gives +-max_finite; x / 0 gives +-max_finite
//             (0 / 0 gives 0); NaN inputs and invalid operations (0 / 0,
//             sqrt of a negative) give +0. Typical of hardware datapaths.
//   Ieee:     as IEEE 754: overflow gives +-infinity, invalid gives NaN (one
//             canonical quiet NaN).
enum class FloatSpecials { Saturate, Ieee };

class FloatFormat {
 public:
  // IEEE binary32 (exponent 8, p 24, subnormals, Ieee specials).
  FloatFormat() : FloatFormat(8, 24, true, FloatSpecials::Ieee) {}
  // Throws edrnr::Error unless 2 <= exponent_bits <= 8 and
  // 2 <= significand_bits <= 25. subnormals = false flushes every result whose
  // magnitude, rounded to p bits with an unbounded exponent, is below
  // min_normal() to a zero of the same sign.
  FloatFormat(int exponent_bits, int significand_bits, bool subnormals = false,
              FloatSpecials specials = FloatSpecials::Saturate);

  int exponent_bits() const { return exponent_bits_; }
  int significand_bits() const { return significand_bits_; }  // p, hidden bit included
  bool subnormals() const { return subnormals_; }
  FloatSpecials specials() const { return specials_; }
  int total_bits() const { return exponent_bits_ + significand_bits_; }  // sign + exponent + stored fraction
  int bias() const { return (1 << (exponent_bits_ - 1)) - 1; }
  int min_exponent() const { return 1 - bias(); }  // of normal numbers
  int max_exponent() const { return bias(); }
  double max_finite() const { return max_finite_; }
  double min_normal() const { return min_normal_; }
  // The least magnitude that rounds past max_finite(), and the binary64
  // fraction bits below the format's (53 - p): with min_normal(), what
  // rounding a normal value takes (round() on the bit pattern).
  double overflow_threshold() const { return overflow_threshold_; }
  int drop_bits() const { return drop_bits_; }
  // Smallest positive value: the smallest subnormal, or min_normal() without subnormals.
  double min_positive() const { return subnormals_ ? min_subnormal_ : min_normal_; }
  // Spacing of the format at 1: 2^(1-p).
  double epsilon() const { return std::ldexp(1.0, 1 - significand_bits_); }
  // For example "e8p16 (24 bits, flush-to-zero, saturating)".
  std::string name() const;

  // The format value nearest to x (ties to even), with the overflow, NaN and
  // subnormal policies applied.
  double round(double x) const;
  bool is_representable(double x) const;

  // Arithmetic, each correctly rounded once.
  double add(double a, double b) const { return round(a + b); }
  double sub(double a, double b) const { return round(a - b); }
  double mul(double a, double b) const { return round(a * b); }
  double div(double a, double b) const { return round(a / b); }
  double sqrt(double a) const { return round(std::sqrt(a)); }
  // a * b + c with a single rounding (a fused multiply-add unit).
  double fma(double a, double b, double c) const;
  // Exact operations (the results are always representable).
  double neg(double a) const { return -a; }
  double abs(double a) const { return std::fabs(a); }
  // Smaller / larger operand; -0 counts as below +0; a NaN operand gives NaN.
  // Comparisons are exact: use the built-in operators on the values.
  double min(double a, double b) const;
  double max(double a, double b) const;

  // The correctly rounded value of q * 2^-frac_bits (e.g. an integer pixel
  // coordinate with frac_bits = 0), even when |q| >= 2^53.
  double from_fixed(int64_t q, int frac_bits) const;

  // Component-wise versions for positions and directions.
  Vec3d round(const Vec3d& v) const { return {round(v.x), round(v.y), round(v.z)}; }
  Vec3d add(const Vec3d& a, const Vec3d& b) const { return {add(a.x, b.x), add(a.y, b.y), add(a.z, b.z)}; }
  Vec3d sub(const Vec3d& a, const Vec3d& b) const { return {sub(a.x, b.x), sub(a.y, b.y), sub(a.z, b.z)}; }
  Vec3d mul(const Vec3d& a, double s) const { return {mul(a.x, s), mul(a.y, s), mul(a.z, s)}; }
  // a * s + c per component, each with a single rounding.
  Vec3d fma(const Vec3d& a, double s, const Vec3d& c) const {
    return {fma(a.x, s, c.x), fma(a.y, s, c.y), fma(a.z, s, c.z)};
  }

  // The packed bit pattern: sign | exponent | p-1 fraction bits (rounds x first).
  uint64_t encode(double x) const;
  // The value of a bit pattern (only the low total_bits() are used), put
  // through round(), so subnormal patterns read as zero without subnormals
  // and infinity/NaN patterns follow the specials policy.
  double decode(uint64_t bits) const;

  bool operator==(const FloatFormat& o) const {
    return exponent_bits_ == o.exponent_bits_ && significand_bits_ == o.significand_bits_ &&
           subnormals_ == o.subnormals_ && specials_ == o.specials_;
  }

 private:
  int exponent_bits_ = 8;
  int significand_bits_ = 24;
  bool subnormals_ = true;
  FloatSpecials specials_ = FloatSpecials::Ieee;
  // Derived constants.
  int drop_bits_ = 29;             // binary64 fraction bits below the format's: 53 - p
  double max_finite_ = 0;          // 2^emax (2 - 2^(1-p))
  double min_normal_ = 0;          // 2^emin
  double min_subnormal_ = 0;       // 2^(emin + 1 - p)
  double overflow_threshold_ = 0;  // 2^emax (2 - 2^-p): at and above it a value rounds past max_finite
  double overflow_value_ = 0;      // infinity or max_finite
  double ftz_threshold_ = 0;       // 2^emin (1 - 2^-(p+1)): the least value rounding (unbounded) to min_normal
  double nan_value_ = 0;           // NaN or 0
};

// floor(x) as an integer, saturated to int64_t; NaN gives 0. Conversion of a
// format value to fixed point is fx::to_fixed (exact input, one rounding).
inline int64_t floor_to_int(double x) { return fx::to_fixed(x, 0, 64, fx::Rounding::Floor); }

inline double FloatFormat::round(double x) const {
  if (x != x) return nan_value_;
  const double ax = std::fabs(x);
  if (ax >= overflow_threshold_) return std::copysign(overflow_value_, x);
  if (ax >= min_normal_) {
    // Round the binary64 significand to p bits, ties to even, on the bit
    // pattern; a carry moves into the exponent as it should.
    uint64_t b = std::bit_cast<uint64_t>(ax);
    const uint64_t half_minus_one = (uint64_t(1) << (drop_bits_ - 1)) - 1;
    b += half_minus_one + ((b >> drop_bits_) & 1);
    b &= ~((uint64_t(1) << drop_bits_) - 1);
    return std::copysign(std::bit_cast<double>(b), x);
  }
  if (!subnormals_) return std::copysign(ax >= ftz_threshold_ ? min_normal_ : 0.0, x);
  // Subnormal range: round to a multiple of min_subnormal. ax is a normal
  // binary64 here or rounds to zero.
  if (ax <= 0.5 * min_subnormal_) return std::copysign(0.0, x);
  const uint64_t b = std::bit_cast<uint64_t>(ax);
  const int e = int(b >> 52) - 1023;                                         // ax in [2^e, 2^(e+1))
  const uint64_t m = (b & ((uint64_t(1) << 52) - 1)) | (uint64_t(1) << 52);  // ax = m 2^(e-52)
  const int drop = (min_exponent() + 1 - significand_bits_) - (e - 52);      // 1..53
  const uint64_t q = m >> drop;
  const uint64_t rem = m & ((uint64_t(1) << drop) - 1);
  const uint64_t half = uint64_t(1) << (drop - 1);
  const uint64_t r = q + ((rem > half || (rem == half && (q & 1) != 0)) ? 1 : 0);
  return std::copysign(double(r) * min_subnormal_, x);
}

inline double FloatFormat::fma(double a, double b, double c) const {
  // a * b is exact in binary64 (at most 2p <= 50 significant bits, exponents
  // far from binary64's limits). The sum is rounded to nearest; TwoSum gives
  // its exact error, and a nonzero error turns the result into the
  // round-to-odd sum (the neighbour toward the exact value when the rounded
  // sum has an even last bit). Rounding a round-to-odd value with >= p + 2 bits
  // to p bits equals rounding the exact value.
  const double prod = a * b;
  double s = prod + c;
  if (!std::isfinite(s)) return round(s);
  const double bv = s - prod;
  const double err = (prod - (s - bv)) + (c - bv);
  uint64_t bits = std::bit_cast<uint64_t>(s);
  if (err != 0.0 && (bits & 1) == 0) {
    // s != 0 here (a zero sum is exact). Step the magnitude toward the error.
    const bool away_from_zero = (err > 0.0) == (s > 0.0);
    bits = away_from_zero ? bits + 1 : bits - 1;
    s = std::bit_cast<double>(bits);
  }
  return round(s);
}

}  // namespace edrnr
