// Highway kernels of the training MLP's layers (train/mlp_layer_kernels.h),
// compiled once per SIMD target (hwy/foreach_target.h) and picked at run time
// (HWY_DYNAMIC_DISPATCH). Every lane does the same IEEE operations in the same
// order on every target (products and sums, never fused: the build has
// -ffp-contract=off), and the sums across lanes follow one fixed tree, so the
// results are the same bits whichever target runs.
#include "train/mlp_layer_kernels.h"

#include <algorithm>
#include <cmath>

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "train/mlp_layer_kernels.cpp"
#include <hwy/foreach_target.h>  // before highway.h
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace edrnr::train {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<float>;
constexpr size_t kN = hn::MaxLanes(DF());
static_assert(kLanes % kN == 0 && kLanes / kN <= 32, "a chunk is a whole number of vectors");
constexpr int kVecs = int(kLanes / kN);

void LayerForward(const float* W, const float* b, int in, int out, const float* x, float* y, bool relu) {
  const DF d;
  const auto zero = hn::Zero(d);
  for (int o = 0; o < out; ++o) {
    const float* w = W + size_t(o) * in;
    hn::Vec<DF> a[kVecs];
    for (int v = 0; v < kVecs; ++v) a[v] = hn::Set(d, b[o]);
    for (int i = 0; i < in; ++i) {
      const auto wi = hn::Set(d, w[i]);
      const float* xi = x + size_t(i) * kLanes;
      for (int v = 0; v < kVecs; ++v) a[v] = hn::Add(a[v], hn::Mul(wi, hn::LoadU(d, xi + kN * v)));
    }
    for (int v = 0; v < kVecs; ++v) {
      if (relu) a[v] = hn::IfThenElse(hn::Gt(a[v], zero), a[v], zero);
      hn::StoreU(a[v], d, y + size_t(o) * kLanes + kN * v);
    }
  }
}

void LayerInputGrad(const float* W, int in, int out, const float* dy, const float* mask, float* dx) {
  const DF d;
  const auto zero = hn::Zero(d);
  for (int i = 0; i < in; ++i) {
    hn::Vec<DF> a[kVecs];
    for (int v = 0; v < kVecs; ++v) a[v] = zero;
    for (int o = 0; o < out; ++o) {
      const auto wi = hn::Set(d, W[size_t(o) * in + i]);
      const float* g = dy + size_t(o) * kLanes;
      for (int v = 0; v < kVecs; ++v) a[v] = hn::Add(a[v], hn::Mul(wi, hn::LoadU(d, g + kN * v)));
    }
    for (int v = 0; v < kVecs; ++v) {
      if (mask) a[v] = hn::IfThenElse(hn::Gt(hn::LoadU(d, mask + size_t(i) * kLanes + kN * v), zero), a[v], zero);
      hn::StoreU(a[v], d, dx + size_t(i) * kLanes + kN * v);
    }
  }
}

// The sum of a chunk's 32 lanes p[0..31], in the one fixed order every target
// gives: the four runs of 8 lanes added lane by lane, first to last (r[j] =
// ((p[j] + p[8 + j]) + p[16 + j]) + p[24 + j]), then r by the tree
// ((r0 + r4) + (r2 + r6)) + ((r1 + r5) + (r3 + r7)).
template <class D>
HWY_INLINE float SumChunk(D d, const hn::Vec<D>* p) {
  constexpr size_t N = hn::MaxLanes(D());
#if HWY_TARGET == HWY_SCALAR  // lane by lane
  float l[kLanes];
  for (int v = 0; v < kVecs; ++v) hn::StoreU(p[v], d, l + N * v);
  float r[8];
  for (int j = 0; j < 8; ++j) r[j] = ((l[j] + l[8 + j]) + l[16 + j]) + l[24 + j];
  return ((r[0] + r[4]) + (r[2] + r[6])) + ((r[1] + r[5]) + (r[3] + r[7]));
#else
  const hn::FixedTag<float, 4> d4;
  hn::Vec<decltype(d4)> lo, hi;  // r[0..3] and r[4..7]
  if constexpr (N == 4) {
    lo = p[0];
    hi = p[1];
    for (int v = 2; v < kVecs; v += 2) {
      lo = hn::Add(lo, p[v]);
      hi = hn::Add(hi, p[v + 1]);
    }
  } else if constexpr (N == 8) {
    auto r = p[0];
    for (int v = 1; v < kVecs; ++v) r = hn::Add(r, p[v]);
    const hn::Half<D> dq;
    lo = hn::LowerHalf(dq, r);
    hi = hn::UpperHalf(dq, r);
  } else {  // 16 lanes: two runs of 8 in each vector
    const hn::Half<D> dh;
    auto r = hn::Add(hn::LowerHalf(dh, p[0]), hn::UpperHalf(dh, p[0]));
    for (int v = 1; v < kVecs; ++v) r = hn::Add(hn::Add(r, hn::LowerHalf(dh, p[v])), hn::UpperHalf(dh, p[v]));
    const hn::Half<hn::Half<D> > dq;
    lo = hn::LowerHalf(dq, r);
    hi = hn::UpperHalf(dq, r);
  }
  const auto a = hn::Add(lo, hi);                             // r0+r4, r1+r5, r2+r6, r3+r7
  const auto s = hn::Add(a, hn::ConcatUpperUpper(d4, a, a));  // lanes 0, 1: (r0+r4)+(r2+r6), (r1+r5)+(r3+r7)
  return hn::GetLane(s) + hn::ExtractLane(s, 1);
#endif
}

void LayerParamGrad(const float* x, const float* dy, int in, int out, float* gW, float* gb) {
  const DF d;
  for (int o = 0; o < out; ++o) {
    const float* g = dy + size_t(o) * kLanes;
    hn::Vec<DF> dv[kVecs], p[kVecs];
    for (int v = 0; v < kVecs; ++v) dv[v] = hn::LoadU(d, g + kN * v);
    gb[o] += SumChunk(d, dv);
    for (int i = 0; i < in; ++i) {
      const float* xi = x + size_t(i) * kLanes;
      for (int v = 0; v < kVecs; ++v) p[v] = hn::Mul(dv[v], hn::LoadU(d, xi + kN * v));
      gW[size_t(o) * in + i] += SumChunk(d, p);
    }
  }
}

void QuantizeRows(float* block, int rows, float step, float lo, float hi) {
  const DF d;
  const auto inv = hn::Set(d, 1.f / step), half = hn::Set(d, 0.5f), s = hn::Set(d, step);
  const auto vlo = hn::Set(d, lo), vhi = hn::Set(d, hi);
  for (size_t i = 0; i < size_t(rows) * kLanes; i += kN) {
    const auto t = hn::Floor(hn::Add(hn::Mul(hn::LoadU(d, block + i), inv), half));
    // std::clamp(t, lo, hi): t < lo ? lo : (hi < t ? hi : t), so a NaN stays.
    const auto c = hn::IfThenElse(hn::Lt(t, vlo), vlo, hn::IfThenElse(hn::Lt(vhi, t), vhi, t));
    hn::StoreU(hn::Mul(c, s), d, block + i);
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace edrnr::train
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace edrnr::train {

HWY_EXPORT(LayerForward);
HWY_EXPORT(LayerInputGrad);
HWY_EXPORT(LayerParamGrad);
HWY_EXPORT(QuantizeRows);

void mlp_layer_forward(const float* W, const float* b, int in, int out, const float* x, float* y, bool relu) {
  HWY_DYNAMIC_DISPATCH(LayerForward)(W, b, in, out, x, y, relu);
}

void mlp_layer_param_grad(const float* x, const float* dy, int in, int out, float* gW, float* gb) {
  HWY_DYNAMIC_DISPATCH(LayerParamGrad)(x, dy, in, out, gW, gb);
}

void mlp_layer_input_grad(const float* W, int in, int out, const float* dy, const float* mask, float* dx) {
  HWY_DYNAMIC_DISPATCH(LayerInputGrad)(W, in, out, dy, mask, dx);
}

void quantize_block(float* block, int rows, float step, float lo, float hi) {
  HWY_DYNAMIC_DISPATCH(QuantizeRows)(block, rows, step, lo, hi);
}

}  // namespace edrnr::train
#endif
