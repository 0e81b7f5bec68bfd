#include "core/custom_float.h"

#include <fmt/format.h>

#include "core/error.h"

namespace edrnr {

FloatFormat::FloatFormat(int exponent_bits, int significand_bits, bool subnormals, FloatSpecials specials)
    : exponent_bits_(exponent_bits), significand_bits_(significand_bits), subnormals_(subnormals), specials_(specials) {
  if (exponent_bits < 2 || exponent_bits > 8) {
    fail("float format: exponent_bits {} is out of range (2..8)", exponent_bits);
  }
  // 53 >= 2p + 2 keeps the double rounding of every operation innocuous.
  if (significand_bits < 2 || 2 * significand_bits + 2 > std::numeric_limits<double>::digits) {
    fail("float format: significand_bits {} is out of range (2..25, hidden bit included)", significand_bits);
  }
  const int p = significand_bits;
  drop_bits_ = std::numeric_limits<double>::digits - p;
  max_finite_ = std::ldexp(2.0 - std::ldexp(1.0, 1 - p), max_exponent());
  min_normal_ = std::ldexp(1.0, min_exponent());
  min_subnormal_ = std::ldexp(1.0, min_exponent() + 1 - p);
  overflow_threshold_ = std::ldexp(2.0 - std::ldexp(1.0, -p), max_exponent());
  ftz_threshold_ = std::ldexp(1.0 - std::ldexp(1.0, -(p + 1)), min_exponent());
  if (specials == FloatSpecials::Ieee) {
    overflow_value_ = std::numeric_limits<double>::infinity();
    nan_value_ = std::numeric_limits<double>::quiet_NaN();
  } else {
    overflow_value_ = max_finite_;
    nan_value_ = 0.0;
  }
}

std::string FloatFormat::name() const {
  return fmt::format("e{}p{} ({} bits, {}, {})", exponent_bits_, significand_bits_, total_bits(),
                     subnormals_ ? "subnormals" : "flush-to-zero",
                     specials_ == FloatSpecials::Ieee ? "IEEE infinities/NaN" : "saturating");
}

bool FloatFormat::is_representable(double x) const {
  const double r = round(x);
  if (x != x) return r != r;
  return std::bit_cast<uint64_t>(r) == std::bit_cast<uint64_t>(x);
}

double FloatFormat::min(double a, double b) const {
  if (a != a || b != b) return round(std::numeric_limits<double>::quiet_NaN());
  if (a == b) return std::signbit(a) ? a : b;
  return a < b ? a : b;
}

double FloatFormat::max(double a, double b) const {
  if (a != a || b != b) return round(std::numeric_limits<double>::quiet_NaN());
  if (a == b) return std::signbit(a) ? b : a;
  return a > b ? a : b;
}

double FloatFormat::from_fixed(int64_t q, int frac_bits) const {
  if (frac_bits > 2000) frac_bits = 2000;  // beyond any format's range either way
  if (frac_bits < -2000) frac_bits = -2000;
  const uint64_t mag = q < 0 ? uint64_t(0) - uint64_t(q) : uint64_t(q);
  const int width = std::bit_width(mag);
  double v;
  if (width <= 53) {
    v = double(mag);  // exact
  } else {
    // Round to odd at 53 bits, then the final rounding to p <= 51 bits is exact-correct.
    const int k = width - 53;
    uint64_t t = mag >> k;
    if ((mag & ((uint64_t(1) << k) - 1)) != 0) t |= 1;
    v = std::ldexp(double(t), k);
  }
  // Scaling by 2^-frac_bits is exact unless it leaves binary64's normal range,
  // where the format has long overflowed or underflowed; clamp there so the
  // double rounding cannot land on a format boundary.
  const int exp_after = width - 1 - frac_bits;
  if (width != 0 && exp_after > 1000)
    v = std::numeric_limits<double>::infinity();
  else if (width != 0 && exp_after < -1000)
    v = std::ldexp(1.0, -1000);
  else
    v = std::ldexp(v, -frac_bits);
  return round(q < 0 ? -v : v);
}

uint64_t FloatFormat::encode(double x) const {
  const double r = round(x);
  const int frac_bits = significand_bits_ - 1;
  const uint64_t sign = std::signbit(r) ? uint64_t(1) << (exponent_bits_ + frac_bits) : 0;
  const uint64_t exp_all_ones = (uint64_t(1) << exponent_bits_) - 1;
  const double ar = std::fabs(r);
  if (r != r) return sign | (exp_all_ones << frac_bits) | (uint64_t(1) << (frac_bits - 1));
  if (std::isinf(r)) return sign | (exp_all_ones << frac_bits);
  if (ar == 0.0) return sign;
  if (ar < min_normal_) return sign | uint64_t(ar / min_subnormal_);  // exact integer < 2^(p-1)
  const uint64_t b = std::bit_cast<uint64_t>(ar);
  const int e = int(b >> 52) - 1023;
  const uint64_t fraction = (b & ((uint64_t(1) << 52) - 1)) >> drop_bits_;
  return sign | (uint64_t(e + bias()) << frac_bits) | fraction;
}

double FloatFormat::decode(uint64_t bits) const {
  const int frac_bits = significand_bits_ - 1;
  const uint64_t fraction = bits & ((uint64_t(1) << frac_bits) - 1);
  const uint64_t exp_all_ones = (uint64_t(1) << exponent_bits_) - 1;
  const uint64_t e = (bits >> frac_bits) & exp_all_ones;
  const bool negative = ((bits >> (frac_bits + exponent_bits_)) & 1) != 0;
  double v;
  if (e == exp_all_ones) {
    v = fraction == 0 ? std::numeric_limits<double>::infinity() : std::numeric_limits<double>::quiet_NaN();
  } else if (e == 0) {
    v = double(fraction) * min_subnormal_;
  } else {
    v = std::ldexp(double(fraction | (uint64_t(1) << frac_bits)), int(e) - bias() - frac_bits);
  }
  return round(negative ? -v : v);
}

}  // namespace edrnr
