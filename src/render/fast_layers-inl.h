// Highway kernels of the fast renderer's MLP layers (render/fast_kernels.cpp
// includes this once per SIMD target): the dense layers in float lanes
// (Dense), their INT8 byte form on AVX-512 VNNI and AVX2 (DenseBytes and the
// packing of inputs and outputs, FastModel::quads), requantization and
// the colour net's per-ray direction terms. Per-target include guard, as
// Highway's -inl.h headers have it.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>

#include "model/mlp.h"
#include "render/fast_model.h"

#if defined(EDRNR_RENDER_FAST_LAYERS_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef EDRNR_RENDER_FAST_LAYERS_INL_H_
#undef EDRNR_RENDER_FAST_LAYERS_INL_H_
#else
#define EDRNR_RENDER_FAST_LAYERS_INL_H_
#endif

#include <hwy/contrib/math/math-inl.h>
#include <hwy/highway.h>

#include "render/fast_convert-inl.h"  // ToInt32 (per target)

HWY_BEFORE_NAMESPACE();
namespace edrnr {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// 1 / (1 + exp(-x)). Highway's Exp is defined up to 104 (beyond, its
// result is not infinity), so -x is kept within +-87, where exp(-x) is
// finite; beyond that the sigmoid is 0 or 1 to within 2^-125.
template <class DT>
hn::Vec<DT> Sigmoid(DT d, hn::Vec<DT> x) {
  const hn::Vec<DT> one = hn::Set(d, 1.f), limit = hn::Set(d, 87.f);
  const hn::Vec<DT> e = hn::Exp(d, hn::Min(hn::Max(hn::Neg(x), hn::Neg(limit)), limit));
  return hn::Div(one, hn::Add(one, e));
}

// The optical depth tau = sigma delta of a raw density output (sigma =
// exp(clamp(raw)), model/mlp.h) and the opacity 1 - exp(-tau).
template <class DT>
HWY_INLINE hn::Vec<DT> OpticalDepth(DT d, hn::Vec<DT> raw, float delta) {
  const hn::Vec<DT> sigma = hn::Exp(d, hn::Min(hn::Max(raw, hn::Set(d, kRawSigmaMin)), hn::Set(d, kRawSigmaMax)));
  return hn::Mul(sigma, hn::Set(d, delta));
}
template <class DT>
HWY_INLINE hn::Vec<DT> AlphaOfDepth(DT d, hn::Vec<DT> tau) {
  return hn::Neg(hn::Expm1(d, hn::Neg(tau)));
}

// The INT8 path's activations of raw outputs (integers in 1/256 steps):
// alpha of the raw density for sample spacing delta, and the colour.
template <class DT>
HWY_INLINE hn::Vec<DT> AlphaOfRaw(DT d, hn::Vec<DT> raw_q, float delta) {
  return AlphaOfDepth(d, OpticalDepth(d, hn::Mul(raw_q, hn::Set(d, 1.f / 256.f)), delta));
}
template <class DT>
HWY_INLINE hn::Vec<DT> ColourOfRaw(DT d, hn::Vec<DT> raw_q) {
  return Sigmoid(d, hn::Mul(raw_q, hn::Set(d, 1.f / 256.f)));
}

// Room for the widest vector of any target.
constexpr size_t kCap = HWY_MAX_BYTES / sizeof(float);
// Int8: samples are run in segments of at most this many, whose rays' direction
// parts are computed once per ray (slot) before the samples' chunks.
constexpr size_t kSegment = 256;
constexpr size_t kDirRow = kSegment + kCap;  // a row of dir_q: a vector load from any slot stays inside

// What a layer does to its sums before they are stored: nothing (mult null,
// relu false), ReLU (float), or clamp(round(sum * mult[row]), lo, hi) (Int8:
// the next layer's INT8 input, or raw outputs in 1/256 steps).
struct Epilogue {
  const float* mult = nullptr;
  float lo = 0.f, hi = 0.f;
  bool relu = false;
};

// ACC rows [o, o + NB) = epilogue((B ? bias : 0) + W[o.., i0..i1) X[i0..i1)),
// one fused multiply-add at a time in input order (the Int8 path's products
// and sums are exact integers; the float path's round differently from the
// reference's multiply then add, far below its 50 dB bound).
template <int NB, class DT>
HWY_INLINE void DenseBlock(DT d, size_t N, const float* X, int in, int i0, int i1, const float* W, const float* B,
                           int o, float* ACC, const Epilogue& e) {
  hn::Vec<DT> acc[NB];
  for (int k = 0; k < NB; ++k) acc[k] = B ? hn::Set(d, B[o + k]) : hn::Zero(d);
  for (int i = i0; i < i1; ++i) {
    const hn::Vec<DT> x = hn::Load(d, X + size_t(i) * N);
    for (int k = 0; k < NB; ++k) {
      const hn::Vec<DT> w = hn::Set(d, W[size_t(o + k) * size_t(in) + size_t(i)]);
      acc[k] = hn::MulAdd(w, x, acc[k]);
    }
  }
  for (int k = 0; k < NB; ++k) {
    hn::Vec<DT> v = acc[k];
    if (e.mult) {
      v = hn::Round(hn::Mul(v, hn::Set(d, e.mult[o + k])));
      v = hn::Min(hn::Max(v, hn::Set(d, e.lo)), hn::Set(d, e.hi));
    } else if (e.relu) {
      v = hn::Max(v, hn::Zero(d));
    }
    hn::Store(v, d, ACC + size_t(o + k) * N);
  }
}

template <class DT>
void Dense(DT d, size_t N, const float* X, int in, int i0, int i1, const float* W, const float* B, int out, float* ACC,
           const Epilogue& e = Epilogue()) {
  int o = 0;
  for (; o + 8 <= out; o += 8) DenseBlock<8>(d, N, X, in, i0, i1, W, B, o, ACC, e);
  if (o + 4 <= out) {
    DenseBlock<4>(d, N, X, in, i0, i1, W, B, o, ACC, e);
    o += 4;
  }
  if (o + 2 <= out) {
    DenseBlock<2>(d, N, X, in, i0, i1, W, B, o, ACC, e);
    o += 2;
  }
  if (o < out) DenseBlock<1>(d, N, X, in, i0, i1, W, B, o, ACC, e);
}

// round(v) as int32 lanes, v already within the int32 range (to nearest
// even, as hn::Round).
template <class DT>
HWY_INLINE hn::Vec<hn::RebindToSigned<DT>> RoundToInt(DT, hn::Vec<DT> v) {
  return ToInt32<false>(hn::RebindToSigned<DT>(), v);
}

#if HWY_TARGET == HWY_AVX3_DL || HWY_TARGET == HWY_AVX2
constexpr bool kHaveDotBytes = true;
#else
constexpr bool kHaveDotBytes = false;
#endif
#if HWY_TARGET == HWY_AVX3_DL
// VPDPBUSD multiplies unsigned bytes by signed ones: a layer's inputs are
// packed plus 128 (and the bias words take 128 times the weights back out).
constexpr int32_t kByteOffset = 128;
#else
// AVX2 multiplies with VPMADDUBSW, whose 16-bit pair sums must not
// saturate: the inputs are packed as signed bytes, and a signed input's
// sign moves to the weight (VPSIGNB), |x| <= 128 against |w| <= 127
// (FastModel::byte_offset 0 packs no weight -128), or an input known to be
// in [0, 127] meets the weight as it is: at most 2 * 128 * 127 per pair.
constexpr int32_t kByteOffset = 0;
#endif

// Byte k of a byte-form word: the integer v (in [-128, 127]) plus
// kByteOffset, masked to its byte (a negative v's sign bits must not reach
// the bytes above when kByteOffset is 0).
template <class VI>
HWY_INLINE VI ByteAt(VI v, int k) {
  const hn::DFromV<VI> di;
  VI u = hn::Add(v, hn::Set(di, kByteOffset));
  if constexpr (kByteOffset == 0) u = hn::And(u, hn::Set(di, 255));
  return hn::ShiftLeftSame(u, 8 * k);
}

#if HWY_TARGET == HWY_AVX3_DL || HWY_TARGET == HWY_AVX2
// One word of a layer's byte-form inputs as DotBytes takes it: u, the
// packed bytes, and on AVX2 a, their absolute values (kSigned) or u.
template <class V>
struct ByteInputs {
  V u, a;
};
template <bool kSigned, class V>
HWY_INLINE ByteInputs<V> PrepareBytes(V u) {
  ByteInputs<V> x{u, u};
#if HWY_TARGET == HWY_AVX2
  if constexpr (kSigned) {
    if constexpr (sizeof(u.raw) == 32)
      x.a.raw = _mm256_abs_epi8(u.raw);
    else
      x.a.raw = _mm_abs_epi8(u.raw);
  }
#endif
  return x;
}

// acc plus, per 32-bit lane, the 4 products of the input bytes and the
// signed bytes of the word *w, broadcast to every lane: on AVX-512 VNNI one
// VPDPBUSD with a broadcast memory operand; on AVX2 VPSIGNB (kSigned),
// VPMADDUBSW, VPMADDWD by ones and VPADDD, the same exact sums.
template <bool kSigned, class V>
HWY_INLINE V DotBytes(V acc, const ByteInputs<V>& x, const int32_t* w) {
  auto r = acc.raw;
#if HWY_TARGET == HWY_AVX3_DL
  if constexpr (sizeof(r) == 64)
    asm("vpdpbusd %2%{1to16%}, %1, %0" : "+v"(r) : "v"(x.u.raw), "m"(*w));
  else
    asm("vpdpbusd %2%{1to8%}, %1, %0" : "+v"(r) : "v"(x.u.raw), "m"(*w));
#else
  if constexpr (sizeof(r) == 32) {
    __m256i wb = _mm256_set1_epi32(*w);
    if constexpr (kSigned) wb = _mm256_sign_epi8(wb, x.u.raw);
    r = _mm256_add_epi32(r, _mm256_madd_epi16(_mm256_maddubs_epi16(x.a.raw, wb), _mm256_set1_epi16(1)));
  } else {
    __m128i wb = _mm_set1_epi32(*w);
    if constexpr (kSigned) wb = _mm_sign_epi8(wb, x.u.raw);
    r = _mm_add_epi32(r, _mm_madd_epi16(_mm_maddubs_epi16(x.a.raw, wb), _mm_set1_epi16(1)));
  }
#endif
  acc.raw = r;
  return acc;
}

// Four sums acc[0..3] of outputs o..o + 3 of a hidden layer as one word of
// the next layer's byte form: clamp(round(mult (sum + dir)), 0, 127) plus
// kByteOffset, output o + b in byte b. dir (null: none): the colour net's
// direction terms, output r's of the lanes' slots at dir[r * kDirRow]
// picked by `lanes`. (The bounds are integers, so clamping before or after
// rounding is the same.)
template <class DT, class VI, class Idx>
HWY_INLINE VI HiddenWord(DT d, const VI* acc, int o, const float* mult, const float* dir, Idx lanes) {
  const hn::RebindToSigned<DT> di;
  const hn::Vec<DT> lo = hn::Zero(d), hi = hn::Set(d, 127.f);
  // The offset of every byte (the values are below 128).
  VI word = hn::Set(di, kByteOffset == 128 ? int32_t(0x80808080u) : 0);
  for (int b = 0; b < 4; ++b) {
    hn::Vec<DT> v = hn::ConvertTo(d, acc[b]);
    if (dir) v = hn::Add(v, hn::TableLookupLanes(hn::LoadU(d, dir + size_t(o + b) * kDirRow), lanes));
    v = hn::Min(hn::Max(hn::Mul(v, hn::Set(d, mult[o + b])), lo), hi);
    word = hn::Or(word, hn::ShiftLeftSame(RoundToInt(d, v), 8 * b));
  }
  return word;
}

// The sums bias + W X of outputs [o, o + NB) in the byte form: the inputs in
// xq (4 per word, plus kByteOffset), the weight words wq, the bias words bq
// (which take the offset back out). kSigned: inputs may be negative (a net's
// first layer, the direction); otherwise they are in [0, 127]. Every sum is
// an exact integer, as in Dense.
template <int NB, bool kSigned, class DI>
HWY_INLINE void ByteSums(DI di, size_t N, const int32_t* xq, int words, const int32_t* wq, const int32_t* bq, int o,
                         hn::Vec<DI>* acc) {
  for (int k = 0; k < NB; ++k) acc[k] = hn::Set(di, bq[o + k]);
  for (int j = 0; j < words; ++j) {
    const ByteInputs<hn::Vec<DI>> x = PrepareBytes<kSigned>(hn::Load(di, xq + size_t(j) * N));
    for (int k = 0; k < NB; ++k) acc[k] = DotBytes<kSigned>(acc[k], x, wq + size_t(o + k) * size_t(words) + size_t(j));
  }
}

// DenseBlock in the byte form: ACC rows [o, o + NB) = epilogue(bias + W X),
// row r at ACC + r * stride (N when 0): the results of DenseBlock<NB>.
template <int NB, bool kSigned, class DT>
HWY_INLINE void DenseBytesBlock(DT d, size_t N, const int32_t* xq, int words, const int32_t* wq, const int32_t* bq,
                                int o, float* ACC, const Epilogue& e, size_t stride = 0) {
  if (stride == 0) stride = N;
  const hn::RebindToSigned<DT> di;
  hn::Vec<decltype(di)> acc[NB];
  ByteSums<NB, kSigned>(di, N, xq, words, wq, bq, o, acc);
  for (int k = 0; k < NB; ++k) {
    hn::Vec<DT> v = hn::ConvertTo(d, acc[k]);
    if (e.mult) {
      v = hn::Round(hn::Mul(v, hn::Set(d, e.mult[o + k])));
      v = hn::Min(hn::Max(v, hn::Set(d, e.lo)), hn::Set(d, e.hi));
    }
    hn::Store(v, d, ACC + size_t(o + k) * stride);
  }
}

// A hidden layer's outputs [o, o + NB) (NB a multiple of 4) straight into
// the next layer's byte form: clamp(round(mult (sum + dir)), 0, 127) plus
// kByteOffset, 4 outputs per word of xq_out. dir (null: none): the colour net's
// direction terms, output r's of the lanes' slots at dir[r * kDirRow]
// picked by `lanes`. The values are those of DenseBytesBlock's epilogue (the
// bounds are integers, so clamping before or after rounding is the same)
// and of the next layer's packing (DenseBytes).
template <int NB, bool kSigned, class DT, class Idx>
HWY_INLINE void DenseBytesToBytes(DT d, size_t N, const int32_t* xq, int words, const int32_t* wq, const int32_t* bq,
                                  int o, const float* mult, const float* dir, Idx lanes, int32_t* xq_out) {
  static_assert(NB % 4 == 0, "whole words");
  const hn::RebindToSigned<DT> di;
  hn::Vec<decltype(di)> acc[NB];
  ByteSums<NB, kSigned>(di, N, xq, words, wq, bq, o, acc);
  for (int g = 0; g < NB; g += 4)
    hn::Store(HiddenWord(d, acc + g, o + g, mult, dir, lanes), di, xq_out + size_t(o + g) / 4 * N);
}

// The byte form of input rows [0, rows) of X (integers in [-128, 127]): 4
// per word, plus kByteOffset: ceil(rows / 4) rows of N words.
template <class DT>
void PackBytes(DT d, size_t N, const float* X, int rows, int32_t* xq) {
  const hn::RebindToSigned<DT> di;
  for (int j = 0; 4 * j < rows; ++j) {
    auto u = hn::Zero(di);
    for (int k = 0; k < 4 && 4 * j + k < rows; ++k)
      u = hn::Or(u, ByteAt(hn::ConvertTo(di, hn::Load(d, X + size_t(4 * j + k) * N)), k));
    hn::Store(u, di, xq + size_t(j) * N);
  }
}

// One word of the byte form from count <= 4 values v: clamp(round(v m),
// -128, 127) in byte k (ByteAt).
template <class DT>
HWY_INLINE hn::Vec<hn::RebindToSigned<DT>> ScaledWord(DT d, const hn::Vec<DT>* v, int count, float m) {
  const hn::Vec<DT> mv = hn::Set(d, m), lo = hn::Set(d, -128.f), hi = hn::Set(d, 127.f);
  auto u = hn::Zero(hn::RebindToSigned<DT>());
  for (int k = 0; k < count; ++k) u = hn::Or(u, ByteAt(RoundToInt(d, hn::Min(hn::Max(hn::Mul(v[k], mv), lo), hi)), k));
  return u;
}

// PackBytes of the rows clamp(round(X * m), -128, 127) (Requantize's
// values, which are not stored), rows [0, rows).
template <class DT>
void PackBytesScaled(DT d, size_t N, const float* X, int rows, float m, int32_t* xq) {
  const hn::RebindToSigned<DT> di;
  for (int j = 0; 4 * j < rows; ++j) {
    const int count = std::min(4, rows - 4 * j);
    hn::Vec<DT> v[4];
    for (int k = 0; k < count; ++k) v[k] = hn::Load(d, X + size_t(4 * j + k) * N);
    hn::Store(ScaledWord(d, v, count, m), di, xq + size_t(j) * N);
  }
}

// Dense over inputs [0, L.q_in), already in the byte form in xq (q:
// the MLP's words), into rows of ACC. kSigned as in ByteSums.
template <bool kSigned, class DT>
void DenseBytes(DT d, size_t N, const int32_t* xq, const FastLayer& L, const int32_t* q, float* ACC,
                const Epilogue& e) {
  const int words = (L.q_in + 3) / 4;
  const int32_t* wq = q + L.wq;
  const int32_t* bq = q + L.bq;
  int o = 0;
  for (; o + 8 <= L.out; o += 8) DenseBytesBlock<8, kSigned>(d, N, xq, words, wq, bq, o, ACC, e);
  if (o + 4 <= L.out) {
    DenseBytesBlock<4, kSigned>(d, N, xq, words, wq, bq, o, ACC, e);
    o += 4;
  }
  for (; o < L.out; ++o) DenseBytesBlock<1, kSigned>(d, N, xq, words, wq, bq, o, ACC, e);
}

// A hidden layer (L.out a multiple of 4) from the byte form in xq to the
// next layer's byte form in xq_out (DenseBytesToBytes), with the direction
// terms dir picked by lanes when dir is not null. kSigned as in ByteSums.
template <bool kSigned, class DT, class Idx>
void DenseBytesHidden(DT d, size_t N, const int32_t* xq, const FastLayer& L, const int32_t* q, const float* mult,
                      const float* dir, Idx lanes, int32_t* xq_out) {
  const int words = (L.q_in + 3) / 4;
  const int32_t* wq = q + L.wq;
  const int32_t* bq = q + L.bq;
  int o = 0;
  for (; o + 8 <= L.out; o += 8) DenseBytesToBytes<8, kSigned>(d, N, xq, words, wq, bq, o, mult, dir, lanes, xq_out);
  for (; o < L.out; o += 4) DenseBytesToBytes<4, kSigned>(d, N, xq, words, wq, bq, o, mult, dir, lanes, xq_out);
}

// DirectionParts' sums in the byte form: output o of the vector's slots at
// dir_q[o * kDirRow] = round(m * (bq[o] + W_o . X)) from the packed
// direction bytes xq (words rows of N lanes) and the weight words wq (out
// outputs). The sums are exact integers, as in the float form
// (Dense), so the results are the same.
template <class DT>
void DirectionBytes(DT d, size_t N, const int32_t* xq, int words, const int32_t* wq, const int32_t* bq, int out,
                    float m, float* dir_q) {
  float mult[kFastMaxWidth];
  std::fill(mult, mult + out, m);
  Epilogue e;  // rounded, not clamped
  e.mult = mult;
  e.lo = -std::numeric_limits<float>::infinity();
  e.hi = std::numeric_limits<float>::infinity();
  int o = 0;
  for (; o + 4 <= out; o += 4) DenseBytesBlock<4, true>(d, N, xq, words, wq, bq, o, dir_q, e, kDirRow);
  for (; o < out; ++o) DenseBytesBlock<1, true>(d, N, xq, words, wq, bq, o, dir_q, e, kDirRow);
}
#else
template <class DT>
void PackBytes(DT, size_t, const float*, int, int32_t*) {}
template <class DT>
void PackBytesScaled(DT, size_t, const float*, int, float, int32_t*) {}
template <bool kSigned, class DT>
void DenseBytes(DT, size_t, const int32_t*, const FastLayer&, const int32_t*, float*, const Epilogue&) {}
template <bool kSigned, class DT, class Idx>
void DenseBytesHidden(DT, size_t, const int32_t*, const FastLayer&, const int32_t*, const float*, const float*, Idx,
                      int32_t*) {}
template <class DT>
void DirectionBytes(DT, size_t, const int32_t*, int, const int32_t*, const int32_t*, int, float, float*) {}
#endif
// rows[r] = clamp(round(rows[r] * mult[r or 0]), lo, hi) for r < count.
template <class DT>
void Requantize(DT d, size_t N, float* rows, int count, const float* mult, bool per_row, float lo, float hi) {
  for (int r = 0; r < count; ++r) {
    const hn::Vec<DT> m = hn::Set(d, mult[per_row ? r : 0]);
    float* p = rows + size_t(r) * N;
    const hn::Vec<DT> v = hn::Round(hn::Mul(hn::Load(d, p), m));
    hn::Store(hn::Min(hn::Max(v, hn::Set(d, lo)), hn::Set(d, hi)), d, p);
  }
}

// Rows [0, out) of y (a layer's sums without the direction inputs) plus
// the direction terms of the lanes' slots (output o's at dir[o * kDirRow],
// picked by lanes), then the epilogue e (mult, lo, hi; or ReLU), in place.
template <class DT, class Idx>
HWY_INLINE void AddDirectionTerms(DT d, size_t N, float* y, int out, const float* dir, Idx lanes, const Epilogue& e) {
  for (int o = 0; o < out; ++o) {
    float* r = y + size_t(o) * N;
    const hn::Vec<DT> t = hn::TableLookupLanes(hn::LoadU(d, dir + size_t(o) * kDirRow), lanes);
    hn::Vec<DT> v = hn::Add(hn::Load(d, r), t);
    if (e.mult) {
      v = hn::Round(hn::Mul(v, hn::Set(d, e.mult[o])));
      v = hn::Min(hn::Max(v, hn::Set(d, e.lo)), hn::Set(d, e.hi));
    } else if (e.relu) {
      v = hn::Max(v, hn::Zero(d));
    }
    hn::Store(v, d, r);
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace edrnr
HWY_AFTER_NAMESPACE();

#endif  // EDRNR_RENDER_FAST_LAYERS_INL_H_
