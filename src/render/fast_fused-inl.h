// The fast renderer's chunk for the default MLP shape (density 16-16-8,
// colour 8 + D -> 16 -> 3: model/mlp.h's defaults, every bundled model's),
// float path and INT8 path (in the byte form, fast_layers-inl.h), with every
// size known when it is compiled: each layer's inputs and outputs stay in registers, and
// there is no loop over layers, blocks or words at run time. The same
// operations in the same order as the general path (RunNet, RunNetBytes
// and EvalChunk), so the same bits. Included once per SIMD target by
// render/fast_kernels.cpp, after fast_layers-inl.h.
#include <cstddef>
#include <cstdint>

#include "render/fast_model.h"

#if defined(EDRNR_RENDER_FAST_FUSED_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef EDRNR_RENDER_FAST_FUSED_INL_H_
#undef EDRNR_RENDER_FAST_FUSED_INL_H_
#else
#define EDRNR_RENDER_FAST_FUSED_INL_H_
#endif

#include <hwy/contrib/math/math-inl.h>
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace edrnr {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// The shape the fused chunk is compiled for.
constexpr int kFusedF = 16;  // features: the density net's inputs
constexpr int kFusedH = 16;  // the density net's hidden width
constexpr int kFusedG = 8;   // the density net's outputs (raw density first)
constexpr int kFusedC = 16;  // the colour net's hidden width

// Whether fm's MLPs have the shape above.
inline bool FusedArch(const FastModel& fm) {
  if (fm.feature_channels != kFusedF || fm.geo_width != kFusedG || fm.dir_dims <= 0) return false;
  if (fm.density.size() != 2 || fm.color.size() != 2) return false;
  const FastLayer &d0 = fm.density[0], &d1 = fm.density[1], &c0 = fm.color[0], &c1 = fm.color[1];
  return d0.in == kFusedF && d0.out == kFusedH && d1.in == kFusedH && d1.out == kFusedG &&
         c0.in == kFusedG + fm.dir_dims && c0.out == kFusedC && c1.in == kFusedC && c1.out == 3;
}

// Whether the fused chunk can run fm (with its byte form q, null when it has
// none): the float path (FusedNetsFloat), or the INT8 path with byte
// products (FusedNets), for the shape above.
inline bool FusedShape(const FastModel& fm, const int32_t* q) {
  if (!fm.fused || !FusedArch(fm)) return false;
  if (fm.arithmetic == FastArithmetic::Float) return true;
  if (!kHaveDotBytes || q == nullptr) return false;
  const FastLayer &d0 = fm.density[0], &d1 = fm.density[1], &c0 = fm.color[0], &c1 = fm.color[1];
  return d0.q_in == kFusedF && d1.q_in == kFusedH && c0.q_in == kFusedG && c1.q_in == kFusedC;
}

// Outputs of a float layer summed together (FusedDense).
constexpr int kFusedFloatBlock = HWY_TARGET == HWY_AVX2 ? 4 : 8;

// OUT outputs (a multiple of NB) of a float layer with IN inputs (row
// stride `in` of W; inputs x[0, IN) in registers): bias + W x, one fused
// multiply-add at a time in input order (DenseBlock), into y.
template <int OUT, int IN, int NB, class DT>
HWY_INLINE void FusedDense(DT d, const hn::Vec<DT>* x, const float* W, int in, const float* B, hn::Vec<DT>* y) {
  static_assert(OUT % NB == 0, "whole blocks");
  for (int o = 0; o < OUT; o += NB) {
    hn::Vec<DT> acc[NB];
    for (int k = 0; k < NB; ++k) acc[k] = hn::Set(d, B[o + k]);
    for (int i = 0; i < IN; ++i)
      for (int k = 0; k < NB; ++k) acc[k] = hn::MulAdd(hn::Set(d, W[(o + k) * in + i]), x[i], acc[k]);
    for (int k = 0; k < NB; ++k) y[o + k] = acc[k];
  }
}

// The float path's nets and activations (EvalChunk after the
// interpolation): the features in rows of X (kFusedF rows of N lanes), the
// colour net's direction terms at dir_q picked by the lane slots `slot`;
// out rows 0..4: alpha, exp(-sigma delta), r, g, b.
template <class DT>
HWY_INLINE void FusedNetsFloat(DT d, size_t N, const FastModel& fm, const float* p, const float* X, const float* dir_q,
                               const int32_t* slot, float delta, float* out) {
  using VF = hn::Vec<DT>;
  const hn::RebindToSigned<DT> di;
  const FastLayer &d0 = fm.density[0], &d1 = fm.density[1], &c0 = fm.color[0], &c1 = fm.color[1];
  const auto lanes = hn::IndicesFromVec(d, hn::Load(di, slot));
  const VF zero = hn::Zero(d);
  VF x[kFusedF];
  for (int i = 0; i < kFusedF; ++i) x[i] = hn::Load(d, X + size_t(i) * N);
  VF h[kFusedH];
  FusedDense<kFusedH, kFusedF, kFusedFloatBlock>(d, x, p + d0.w, kFusedF, p + d0.b, h);
  for (int k = 0; k < kFusedH; ++k) h[k] = hn::Max(h[k], zero);
  VF geo[kFusedG];
  FusedDense<kFusedG, kFusedH, kFusedFloatBlock>(d, h, p + d1.w, kFusedH, p + d1.b, geo);

  const VF tau = OpticalDepth(d, geo[0], delta);
  hn::Store(AlphaOfDepth(d, tau), d, out);
  hn::Store(hn::Exp(d, hn::Neg(tau)), d, out + N);

  // The colour net's first layer over the density outputs, then each
  // lane's direction terms (AddDirectionTerms) and ReLU.
  VF c[kFusedC];
  FusedDense<kFusedC, kFusedG, kFusedFloatBlock>(d, geo, p + c0.w, c0.in, p + c0.b, c);
  for (int k = 0; k < kFusedC; ++k)
    c[k] = hn::Max(hn::Add(c[k], hn::TableLookupLanes(hn::LoadU(d, dir_q + size_t(k) * kDirRow), lanes)), zero);
  VF rgb[3];
  FusedDense<3, kFusedC, 3>(d, c, p + c1.w, kFusedC, p + c1.b, rgb);
  for (int k = 0; k < 3; ++k) hn::Store(Sigmoid(d, rgb[k]), d, out + size_t(2 + k) * N);
}

// A table of 65536 values (FastActivationTables) at raw_q + 32768.
template <class DT>
HWY_INLINE hn::Vec<DT> FromTable(DT d, const float* table, hn::Vec<DT> raw_q) {
  const hn::RebindToSigned<DT> di;
  return hn::GatherIndex(d, table, hn::Add(hn::ConvertTo(di, raw_q), hn::Set(di, 32768)));
}

#if HWY_TARGET == HWY_AVX3_DL || HWY_TARGET == HWY_AVX2
// Outputs summed together: 4 keeps AVX2's 16 registers from spilling (1.6 %
// less time on lego than 8); AVX-512 has 32.
constexpr int kFusedBlock = HWY_TARGET == HWY_AVX2 ? 4 : 8;
// acc[k] = bias + the byte products of outputs o + k (k < NB) with the
// WORDS input words x (ByteSums with the inputs in registers).
template <int NB, int WORDS, bool kSigned, class VI>
HWY_INLINE void FusedSums(const ByteInputs<VI>* x, const int32_t* wq, const int32_t* bq, int o, VI* acc) {
  const hn::DFromV<VI> di;
  for (int k = 0; k < NB; ++k) acc[k] = hn::Set(di, bq[o + k]);
  for (int j = 0; j < WORDS; ++j)
    for (int k = 0; k < NB; ++k) acc[k] = DotBytes<kSigned>(acc[k], x[j], wq + (o + k) * WORDS + j);
}

// A hidden layer of OUT outputs (a multiple of 4) from WORDS input words to
// OUT / 4 words of the next layer's byte form (DenseBytesToBytes): with
// dir, the colour net's direction terms of the lanes' slots added first.
template <int OUT, int WORDS, bool kSigned, class DT, class Idx>
HWY_INLINE void FusedHidden(DT d, const ByteInputs<hn::Vec<hn::RebindToSigned<DT>>>* x, const int32_t* wq,
                            const int32_t* bq, const float* mult, const float* dir, Idx lanes,
                            hn::Vec<hn::RebindToSigned<DT>>* y) {
  static_assert(OUT % kFusedBlock == 0, "whole blocks of outputs");
  const hn::RebindToSigned<DT> di;
  for (int o = 0; o < OUT; o += kFusedBlock) {
    hn::Vec<decltype(di)> acc[kFusedBlock];
    FusedSums<kFusedBlock, WORDS, kSigned>(x, wq, bq, o, acc);
    for (int g = 0; g < kFusedBlock; g += 4) y[(o + g) / 4] = HiddenWord(d, acc + g, o + g, mult, dir, lanes);
  }
}

// A net's last layer of OUT outputs: raw outputs in 1/256 steps,
// clamp(round(mult * sum), -32768, 32767) (DenseBytesBlock's epilogue).
template <int OUT, int WORDS, class DT>
HWY_INLINE void FusedLast(DT d, const ByteInputs<hn::Vec<hn::RebindToSigned<DT>>>* x, const int32_t* wq,
                          const int32_t* bq, const float* mult, hn::Vec<DT>* y) {
  hn::Vec<hn::RebindToSigned<DT>> acc[OUT];
  FusedSums<OUT, WORDS, false>(x, wq, bq, 0, acc);
  for (int k = 0; k < OUT; ++k) {
    const hn::Vec<DT> v = hn::Round(hn::Mul(hn::ConvertTo(d, acc[k]), hn::Set(d, mult[k])));
    y[k] = hn::Min(hn::Max(v, hn::Set(d, -32768.f)), hn::Set(d, 32767.f));
  }
}

// The chunk's nets and activations (EvalChunk after the interpolation):
// the density net's inputs in xq (kFusedF / 4 words of N lanes), the
// direction terms at dir_q picked by the lane slots `slot` (relative to
// dir_q); out rows 0..4 of N lanes: alpha, 1 - alpha, r, g, b.
// alpha_table and sigmoid_table (FastActivationTables for delta, or null):
// the activations read from them.
template <class DT>
HWY_INLINE void FusedNets(DT d, size_t N, const FastModel& fm, const float* p, const int32_t* q, const int32_t* xq,
                          const float* dir_q, const int32_t* slot, float delta, const float* alpha_table,
                          const float* sigmoid_table, float* out) {
  const hn::RebindToSigned<DT> di;
  using VI = hn::Vec<decltype(di)>;
  using VF = hn::Vec<DT>;
  const FastLayer &d0 = fm.density[0], &d1 = fm.density[1], &c0 = fm.color[0], &c1 = fm.color[1];
  const auto lanes = hn::IndicesFromVec(d, hn::Load(di, slot));

  // Density net: features (signed) -> hidden (in [0, 127]) -> raw outputs.
  ByteInputs<VI> x[kFusedF / 4];
  for (int j = 0; j < kFusedF / 4; ++j) x[j] = PrepareBytes<true>(hn::Load(di, xq + size_t(j) * N));
  VI h[kFusedH / 4];
  FusedHidden<kFusedH, kFusedF / 4, true>(d, x, q + d0.wq, q + d0.bq, p + d0.m, nullptr, lanes, h);
  ByteInputs<VI> hx[kFusedH / 4];
  for (int j = 0; j < kFusedH / 4; ++j) hx[j] = PrepareBytes<false>(h[j]);
  VF geo[kFusedG];
  FusedLast<kFusedG, kFusedH / 4>(d, hx, q + d1.wq, q + d1.bq, p + d1.m, geo);

  // Opacity from the raw density (1/256 steps).
  const VF alpha = alpha_table ? FromTable(d, alpha_table, geo[0]) : AlphaOfRaw(d, geo[0], delta);
  hn::Store(alpha, d, out);
  hn::Store(hn::Sub(hn::Set(d, 1.f), alpha), d, out + N);

  // Colour net: the density outputs requantized to its INT8 inputs
  // (PackBytesScaled), plus the direction terms -> hidden -> raw colour.
  ByteInputs<VI> cx[kFusedG / 4];
  for (int j = 0; j < kFusedG / 4; ++j) cx[j] = PrepareBytes<true>(ScaledWord(d, geo + 4 * j, 4, p[fm.geo_in]));
  VI c[kFusedC / 4];
  FusedHidden<kFusedC, kFusedG / 4, true>(d, cx, q + c0.wq, q + c0.bq, p + c0.m, dir_q, lanes, c);
  ByteInputs<VI> chx[kFusedC / 4];
  for (int j = 0; j < kFusedC / 4; ++j) chx[j] = PrepareBytes<false>(c[j]);
  VF rgb[3];
  FusedLast<3, kFusedC / 4>(d, chx, q + c1.wq, q + c1.bq, p + c1.m, rgb);
  for (int k = 0; k < 3; ++k)
    hn::Store(sigmoid_table ? FromTable(d, sigmoid_table, rgb[k]) : ColourOfRaw(d, rgb[k]), d, out + size_t(2 + k) * N);
}
#else
template <class DT>
HWY_INLINE void FusedNets(DT, size_t, const FastModel&, const float*, const int32_t*, const int32_t*, const float*,
                          const int32_t*, float, const float*, const float*, float*) {}
#endif

}  // namespace HWY_NAMESPACE
}  // namespace edrnr
HWY_AFTER_NAMESPACE();

#endif  // EDRNR_RENDER_FAST_FUSED_INL_H_
