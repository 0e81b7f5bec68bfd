#include "core/fixed_point.h"

#include <bit>

#include "core/error.h"

namespace edrnr::fx {

Requant requant_from_scale(double scale, int multiplier_bits) {
  if (multiplier_bits < 1 || multiplier_bits > 62) {
    fail("requantization multiplier width {} bits is out of range (1..62)", multiplier_bits);
  }
  if (!(scale > 0.0) || !std::isfinite(scale)) fail("requantization scale {} must be finite and > 0", scale);
  int exponent = 0;
  std::frexp(scale, &exponent);  // scale = f * 2^exponent, f in [0.5, 1)
  // multiplier = scale * 2^shift lies in [2^(bits-1), 2^bits) before rounding.
  int shift = multiplier_bits - exponent;
  if (shift > 63) shift = 63;
  if (shift < 0) fail("requantization scale {} needs more than {} multiplier bits", scale, multiplier_bits);
  int64_t m = to_fixed(scale, shift, 64, Rounding::HalfEven);
  if (m == (int64_t(1) << multiplier_bits)) {  // rounded up to the next power of two
    if (shift == 0) fail("requantization scale {} needs more than {} multiplier bits", scale, multiplier_bits);
    m >>= 1;
    --shift;
  }
  return Requant{m, shift};
}

namespace {

// round(v * 2^frac_bits) as an int64_t (saturated), before the N-bit clamp.
int64_t round_scaled(double v, int frac_bits, Rounding mode) {
  constexpr int64_t kMax = std::numeric_limits<int64_t>::max();
  constexpr int64_t kMin = std::numeric_limits<int64_t>::min();
  if (v != v) return 0;
  if (frac_bits > 1000) frac_bits = 1000;
  if (frac_bits < -1000) frac_bits = -1000;
  // v * 2^frac_bits, as std::ldexp gives it (both are the correctly rounded
  // product; 2^frac_bits is a normal double for |frac_bits| <= 1000).
  const double s = v * std::bit_cast<double>(uint64_t(1023 + frac_bits) << 52);
  if (s == 0.0) {
    // A negative v whose scaled value underflowed lies in (-1, 0).
    return (v < 0.0 && mode == Rounding::Floor) ? -1 : 0;
  }
  const double fl = std::floor(s);
  constexpr double kTwo63 = 9223372036854775808.0;
  if (fl >= kTwo63) return kMax;
  if (fl < -kTwo63) return kMin;
  const double frac = s - fl;  // exact: the fraction bits of s, in [0, 1)
  int64_t q = int64_t(fl);
  bool up = false;
  switch (mode) {
    case Rounding::Floor:
      up = false;
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

}  // namespace

int64_t to_fixed(double v, int frac_bits, int bits, Rounding mode) {
  return saturate(round_scaled(v, frac_bits, mode), bits);
}

int64_t to_fixed_unsigned(double v, int frac_bits, int bits, Rounding mode) {
  return saturate_unsigned(round_scaled(v, frac_bits, mode), bits);
}

}  // namespace edrnr::fx
