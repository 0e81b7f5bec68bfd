// det_sin_cos (activation_lut.h): the same range reduction and Taylor series
// as det_sin / det_cos, several arguments at a time in double lanes. Every
// operation is one IEEE operation per lane (no fused multiply-add: the build
// has -ffp-contract=off and the kernel calls Mul, Div, Sub separately), so
// each lane gives the scalar functions' bits.
#include <algorithm>

#include "chip/activation_lut.h"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "chip/det_trig_kernel.cpp"
#include <hwy/foreach_target.h>  // before highway.h
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace edrnr::chip {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// Lanes of x (|x| < 2^20, checked by the caller): n = floor(x 2/pi + 1/2),
// r = (x - n pio2_hi) - n pio2_lo, then sin(r) and cos(r) by the series.
// Every array holds `count` rounded up to whole vectors (the tail padded).
void SinCosSmall(const double* HWY_RESTRICT x, size_t count, double inv_pio2, double pio2_hi, double pio2_lo,
                 double* HWY_RESTRICT n_out, double* HWY_RESTRICT sin_r, double* HWY_RESTRICT cos_r) {
  const hn::ScalableTag<double> d;
  const size_t lanes = hn::Lanes(d);
  const auto one = hn::Set(d, 1.0);
  for (size_t i = 0; i < count; i += lanes) {
    const auto xv = hn::LoadU(d, x + i);
    const auto n = hn::Floor(hn::Add(hn::Mul(xv, hn::Set(d, inv_pio2)), hn::Set(d, 0.5)));
    const auto r = hn::Sub(hn::Sub(xv, hn::Mul(n, hn::Set(d, pio2_hi))), hn::Mul(n, hn::Set(d, pio2_lo)));
    const auto r2 = hn::Mul(r, r);
    auto s = one, c = one;
    // The two series interleaved: sin over i = 23, 21, ..., 3; cos over 22, 20, ..., 2.
    for (int k = 23; k >= 3; k -= 2) {
      s = hn::Sub(one, hn::Div(hn::Mul(s, r2), hn::Set(d, double(k * (k - 1)))));
      c = hn::Sub(one, hn::Div(hn::Mul(c, r2), hn::Set(d, double((k - 1) * (k - 2)))));
    }
    hn::StoreU(n, d, n_out + i);
    hn::StoreU(hn::Mul(r, s), d, sin_r + i);
    hn::StoreU(c, d, cos_r + i);
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace edrnr::chip
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
#include <cmath>

#include "core/error.h"

namespace edrnr::chip {
HWY_EXPORT(SinCosSmall);

void det_sin_cos(const double* x, size_t count, double* sin_out, double* cos_out) {
  constexpr size_t kChunk = 64;  // a multiple of every target's lane count
  alignas(64) double xs[kChunk], n[kChunk], sr[kChunk], cr[kChunk];
  for (size_t base = 0; base < count; base += kChunk) {
    const size_t m = std::min(kChunk, count - base);
    for (size_t i = 0; i < m; ++i) {
      xs[i] = x[base + i];
      if (!(std::fabs(xs[i]) < 1048576.0)) fail("det_sin_cos: argument {} outside the supported range", xs[i]);
    }
    // The tail of the last vector, as wide as the widest target's.
    constexpr size_t kLanesMax = std::min<size_t>(kChunk, HWY_MAX_BYTES / sizeof(double));
    std::fill(xs + m, xs + std::min(kChunk, (m + kLanesMax - 1) / kLanesMax * kLanesMax), 0.0);
    HWY_DYNAMIC_DISPATCH(SinCosSmall)
    (xs, m, det_trig_constants::kInvPio2, det_trig_constants::kPio2Hi, det_trig_constants::kPio2Lo, n, sr, cr);
    for (size_t i = 0; i < m; ++i) {
      const double s = sr[i], c = cr[i];
      switch (int(int64_t(n[i]) & 3)) {
        case 0:
          sin_out[base + i] = s, cos_out[base + i] = c;
          break;
        case 1:
          sin_out[base + i] = c, cos_out[base + i] = -s;
          break;
        case 2:
          sin_out[base + i] = -s, cos_out[base + i] = -c;
          break;
        default:
          sin_out[base + i] = -c, cos_out[base + i] = s;
          break;
      }
    }
  }
}

}  // namespace edrnr::chip
#endif  // HWY_ONCE
