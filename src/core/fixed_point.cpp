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

}  // namespace edrnr::fx
