#include "chip/activation_lut.h"

#include <cmath>
#include <limits>

#include "core/error.h"

namespace edrnr::chip {

namespace {
// ln 2 split so that n * kLn2Hi is exact for |n| < 2^20 (fdlibm's constants).
constexpr double kLn2Hi = 6.93147180369123816490e-01;
constexpr double kLn2Lo = 1.90821492927058770002e-10;
constexpr double kInvLn2 = 1.44269504088896338700e+00;
using det_trig_constants::kInvPio2;
using det_trig_constants::kPio2Hi;
using det_trig_constants::kPio2Lo;

// sin and cos of |r| <= pi/4 by their Taylor series (terms below 1e-20).
double sin_small(double r) {
  const double r2 = r * r;
  double s = 1.0;
  for (int i = 23; i >= 3; i -= 2) s = 1.0 - s * r2 / double(i * (i - 1));
  return r * s;
}
double cos_small(double r) {
  const double r2 = r * r;
  double s = 1.0;
  for (int i = 22; i >= 2; i -= 2) s = 1.0 - s * r2 / double(i * (i - 1));
  return s;
}
// x = n pi/2 + r with |r| <= pi/4 (about), for |x| < 2^20.
double reduce_pio2(double x, int& quadrant) {
  const double n = std::floor(x * kInvPio2 + 0.5);
  quadrant = int(int64_t(n) & 3);
  return (x - n * kPio2Hi) - n * kPio2Lo;
}
}  // namespace

double det_exp(double x) {
  if (x != x) return x;
  if (x > 709.0) return std::numeric_limits<double>::infinity();
  if (x < -745.0) return 0.0;
  const double n = std::floor(x * kInvLn2 + 0.5);
  const double r = (x - n * kLn2Hi) - n * kLn2Lo;  // |r| <= 0.35
  double s = 1.0;
  for (int i = 22; i >= 1; --i) s = 1.0 + s * r / double(i);
  return std::ldexp(s, int(n));
}

double det_log(double x) {
  if (!(x > 0.0) || !std::isfinite(x)) fail("det_log: argument {} must be positive and finite", x);
  int e;
  const double m = std::frexp(x, &e);  // exact: x = m 2^e, m in [0.5, 1)
  double y = double(e) * kLn2Hi + (m - 1.0);
  for (int i = 0; i < 8; ++i) {  // Halley steps on exp(y) = x, cubic convergence
    const double ey = det_exp(y);
    y = y + 2.0 * (x - ey) / (x + ey);
  }
  return y;
}

double det_sin(double x) {
  if (!(std::fabs(x) < 1048576.0)) fail("det_sin: argument {} outside the supported range", x);
  int q;
  const double r = reduce_pio2(x, q);
  switch (q) {
    case 0:
      return sin_small(r);
    case 1:
      return cos_small(r);
    case 2:
      return -sin_small(r);
    default:
      return -cos_small(r);
  }
}

double det_cos(double x) {
  if (!(std::fabs(x) < 1048576.0)) fail("det_cos: argument {} outside the supported range", x);
  int q;
  const double r = reduce_pio2(x, q);
  switch (q) {
    case 0:
      return cos_small(r);
    case 1:
      return -sin_small(r);
    case 2:
      return -cos_small(r);
    default:
      return sin_small(r);
  }
}

ActivationLut::ActivationLut(const std::function<double(double)>& f, double lo, double hi, int in_frac_bits,
                             int address_bits, int out_bits, fx::Rounding rounding)
    : rounding_(rounding) {
  if (!(hi > lo)) fail("activation LUT range [{}, {}] is empty", lo, hi);
  if (address_bits < 1 || address_bits > 20) fail("activation LUT address bits {} outside 1..20", address_bits);
  const int64_t entries = int64_t(1) << address_bits;
  base_ = int64_t(std::floor(std::ldexp(lo, in_frac_bits)));
  const int64_t span = int64_t(std::ceil(std::ldexp(hi, in_frac_bits))) - base_;
  while (((entries - 1) << shift_) < span) ++shift_;
  table_.resize(size_t(entries));
  for (int64_t i = 0; i < entries; ++i) {
    const double x = std::ldexp(double(base_ + (i << shift_)), -in_frac_bits);
    const double y = f(x);
    table_[size_t(i)] = fx::to_fixed_unsigned(y, out_bits - 1, out_bits, rounding);
  }
}

ActivationLut make_alpha_lut(double delta, int in_frac_bits, int address_bits, int out_bits, fx::Rounding rounding) {
  if (!(delta > 0.0)) fail("alpha LUT: sample spacing {} must be positive", delta);
  const double bits_ln2 = double(out_bits) * 0.6931471805599453;
  // exp(raw) delta from 2^-out_bits (alpha below half a step) to
  // (out_bits + 1) ln 2 (alpha above 1 - half a step).
  const double lo = -bits_ln2 - det_log(delta);
  const double hi = det_log(bits_ln2 + 0.6931471805599453) - det_log(delta);
  return ActivationLut([delta](double raw) { return 1.0 - det_exp(-det_exp(raw) * delta); }, lo, hi, in_frac_bits,
                       address_bits, out_bits, rounding);
}

ActivationLut make_sigmoid_lut(int in_frac_bits, int address_bits, int out_bits, fx::Rounding rounding) {
  const double edge = double(out_bits) * 0.6931471805599453;
  return ActivationLut([](double x) { return 1.0 / (1.0 + det_exp(-x)); }, -edge, edge, in_frac_bits, address_bits,
                       out_bits, rounding);
}

}  // namespace edrnr::chip
