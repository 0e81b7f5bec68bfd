// Highway kernels of the block features, compiled once per SIMD target
// (hwy/foreach_target.h) and picked at run time (HWY_DYNAMIC_DISPATCH).
#include "train/feature_kernels.h"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "train/feature_kernels.cpp"
#include <hwy/foreach_target.h>  // before highway.h
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace edrnr::train {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// Full vectors over the row, then the tail channels one at a time (a
// one-lane vector does the same IEEE operation as the scalar form).
template <class Body>
HWY_INLINE void for_each_chunk(size_t F, Body body) {
  const hn::ScalableTag<float> d;
  const hn::CappedTag<float, 1> d1;
  const size_t n = hn::Lanes(d);
  size_t k = 0;
  for (; k + n <= F; k += n) body(d, k);
  for (; k < F; ++k) body(d1, k);
}

void BlendRows(const float* const rows[8], const float* w, size_t F, float* out) {
  for_each_chunk(F, [&](auto d, size_t k) {
    auto acc = hn::Zero(d);
    for (int c = 0; c < 8; ++c) acc = hn::Add(acc, hn::Mul(hn::Set(d, w[c]), hn::LoadU(d, rows[c] + k)));
    hn::StoreU(acc, d, out + k);
  });
}

void BlendRowsFakeQuant(const float* const rows[8], const float* w, size_t F, const float* scale,
                        const float* inv_scale, const float* zero_point, float* out) {
  for_each_chunk(F, [&](auto d, size_t k) {
    // Int4Channel::quantize and dequantize, operation by operation: the
    // clamp keeps a NaN (no comparison holds), the 1.5 * 2^23 trick rounds
    // half to even, a code not above 0 (a NaN too) is 0, and the code is an
    // integer, so it needs no conversion.
    const auto lo = hn::Set(d, -64.f), hi = hn::Set(d, 64.f), big = hn::Set(d, 12582912.f);
    const auto zero = hn::Zero(d), top = hn::Set(d, 15.f);
    const auto inv = hn::LoadU(d, inv_scale + k), zp = hn::LoadU(d, zero_point + k), sc = hn::LoadU(d, scale + k);
    auto acc = hn::Zero(d);
    for (int c = 0; c < 8; ++c) {
      const auto p = hn::Mul(hn::LoadU(d, rows[c] + k), inv);
      const auto t = hn::IfThenElse(hn::Lt(p, lo), lo, hn::IfThenElse(hn::Lt(hi, p), hi, p));
      const auto v = hn::Add(hn::Sub(hn::Add(t, big), big), zp);
      const auto code = hn::IfThenElse(hn::Ge(v, top), top, hn::IfThenElse(hn::Gt(v, zero), v, zero));
      acc = hn::Add(acc, hn::Mul(hn::Set(d, w[c]), hn::Mul(hn::Sub(code, zp), sc)));
    }
    hn::StoreU(acc, d, out + k);
  });
}

uint32_t ScatterRows(float* const grad[8], const float* w, const float* g, size_t F) {
  uint32_t touched = 0;
  for (int c = 0; c < 8; ++c) {
    bool was_zero = true, now_zero = true;
    float* row = grad[c];
    for_each_chunk(F, [&](auto d, size_t k) {
      const auto before = hn::LoadU(d, row + k);
      const auto after = hn::Add(before, hn::Mul(hn::Set(d, w[c]), hn::LoadU(d, g + k)));
      hn::StoreU(after, d, row + k);
      was_zero = was_zero && hn::AllTrue(d, hn::Eq(before, hn::Zero(d)));
      now_zero = now_zero && hn::AllTrue(d, hn::Eq(after, hn::Zero(d)));
    });
    if (was_zero && !now_zero) touched |= 1u << c;
  }
  return touched;
}

void AdamRows(float* p, float* m, float* v, float* g, const int32_t* list, size_t n, size_t F, const AdamStep& s) {
  for (size_t i = 0; i < n; ++i) {
    if (i + 4 < n) {
      const size_t f = size_t(list[i + 4]) * F;
      for (size_t k = 0; k < F; k += 16) {
        __builtin_prefetch(p + f + k, 1);
        __builtin_prefetch(m + f + k, 1);
        __builtin_prefetch(v + f + k, 1);
        __builtin_prefetch(g + f + k, 1);
      }
    }
    const size_t row = size_t(list[i]) * F;
    for_each_chunk(F, [&](auto d, size_t k) {
      // AdamStep::update, operation by operation.
      const size_t at = row + k;
      const auto G = hn::LoadU(d, g + at);
      const auto M = hn::Add(hn::Mul(hn::Set(d, s.beta1), hn::LoadU(d, m + at)), hn::Mul(hn::Set(d, 1.f - s.beta1), G));
      const auto V = hn::Add(hn::Mul(hn::Set(d, s.beta2), hn::LoadU(d, v + at)),
                             hn::Mul(hn::Set(d, 1.f - s.beta2), hn::Mul(G, G)));
      const auto num = hn::Mul(hn::Set(d, s.lr), hn::Mul(M, hn::Set(d, s.c1)));
      const auto den = hn::Add(hn::Sqrt(hn::Mul(V, hn::Set(d, s.c2))), hn::Set(d, s.eps));
      hn::StoreU(hn::Sub(hn::LoadU(d, p + at), hn::Div(num, den)), d, p + at);
      hn::StoreU(M, d, m + at);
      hn::StoreU(V, d, v + at);
      hn::StoreU(hn::Zero(d), d, g + at);
    });
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace edrnr::train
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace edrnr::train {

HWY_EXPORT(BlendRows);
HWY_EXPORT(BlendRowsFakeQuant);
HWY_EXPORT(ScatterRows);
HWY_EXPORT(AdamRows);

void feature_blend_rows(const float* const rows[8], const float w[8], size_t F, float* out) {
  HWY_DYNAMIC_DISPATCH(BlendRows)(rows, w, F, out);
}

void feature_blend_rows_fake_quant(const float* const rows[8], const float w[8], size_t F, const float* scale,
                                   const float* inv_scale, const float* zero_point, float* out) {
  HWY_DYNAMIC_DISPATCH(BlendRowsFakeQuant)(rows, w, F, scale, inv_scale, zero_point, out);
}

uint32_t feature_scatter_rows(float* const grad[8], const float w[8], const float* g, size_t F) {
  return HWY_DYNAMIC_DISPATCH(ScatterRows)(grad, w, g, F);
}

void feature_adam_rows(float* p, float* m, float* v, float* g, const int32_t* list, size_t n, size_t F,
                       const AdamStep& step) {
  HWY_DYNAMIC_DISPATCH(AdamRows)(p, m, v, g, list, n, F, step);
}

}  // namespace edrnr::train
#endif
