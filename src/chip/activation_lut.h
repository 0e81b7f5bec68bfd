#pragma once
// The TME's activation look-up tables, and the deterministic elementary
// functions that fill them.
//
// A table maps a signed fixed-point input code (in_frac_bits fraction bits) to
// an unsigned output code in Q1.(out_bits-1): 2^address_bits entries spaced
// 2^shift input codes apart from a base code, with linear interpolation
// between neighbours in fixed point (one rounding). Inputs below the first
// entry take the first value, inputs past the last take the last. The spacing
// is the smallest power of two that lets the entries cover the requested
// input range.
//
// The tables are filled with det_exp / det_log / det_sin / det_cos: range reduction and
// Taylor series in IEEE double with only +, -, *, / (no library calls whose
// last bit may differ between C libraries), so every machine builds the same
// tables.
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "core/fixed_point.h"

namespace edrnr::chip {

double det_exp(double x);
double det_log(double x);  // x > 0
double det_sin(double x);
double det_cos(double x);
// sin_out[i] = det_sin(x[i]) and cos_out[i] = det_cos(x[i]), the same bits,
// several arguments at a time (SIMD lanes, runtime dispatch). Throws Error
// for an argument outside det_sin's range.
void det_sin_cos(const double* x, size_t count, double* sin_out, double* cos_out);

// pi / 2 split so that n * kPio2Hi is exact for |n| < 2^20 (fdlibm's constants).
namespace det_trig_constants {
inline constexpr double kPio2Hi = 1.57079632673412561417e+00;
inline constexpr double kPio2Lo = 6.07710050650619224932e-11;
inline constexpr double kInvPio2 = 6.36619772367581382433e-01;
}  // namespace det_trig_constants

class ActivationLut {
 public:
  // Covers real inputs [lo, hi]; f maps a real input to [0, 1].
  ActivationLut(const std::function<double(double)>& f, double lo, double hi, int in_frac_bits, int address_bits,
                int out_bits, fx::Rounding rounding);

  int64_t operator()(int64_t code) const {
    const int64_t off = code - base_;
    if (off <= 0) return table_.front();
    const int64_t i = off >> shift_;
    if (i >= int64_t(table_.size()) - 1) return table_.back();
    const int64_t frac = off & ((int64_t(1) << shift_) - 1);
    const int64_t a = table_[size_t(i)], b = table_[size_t(i + 1)];
    return a + fx::shift_right_round((b - a) * frac, shift_, rounding_);
  }

  int64_t base_code() const { return base_; }
  int shift() const { return shift_; }
  const std::vector<int64_t>& table() const { return table_; }

 private:
  int64_t base_ = 0;
  int shift_ = 0;
  fx::Rounding rounding_;
  std::vector<int64_t> table_;
};

// alpha = 1 - exp(-exp(raw) * delta) over the raw densities where it moves
// from below half an output step to above one minus that (delta: sample
// spacing in scene units).
ActivationLut make_alpha_lut(double delta, int in_frac_bits, int address_bits, int out_bits, fx::Rounding rounding);
// rgb = sigmoid(raw) over the raw values where it moves from half an output
// step to one minus that.
ActivationLut make_sigmoid_lut(int in_frac_bits, int address_bits, int out_bits, fx::Rounding rounding);

}  // namespace edrnr::chip
