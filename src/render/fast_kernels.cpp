// Highway kernels of the fast renderer; compiled once per SIMD target
// (hwy/foreach_target.h) and picked at run time (HWY_DYNAMIC_DISPATCH).
#include "render/fast_kernels.h"

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstring>
#include <limits>
#include <vector>

#include "model/mlp.h"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/fast_kernels.cpp"
// clang-format off
#include <hwy/foreach_target.h>  // before highway.h
#include <hwy/highway.h>
#include <hwy/cache_control.h>
#include <hwy/contrib/math/math-inl.h>
#include "render/fast_layers-inl.h"  // Dense, the byte form, Requantize (per target)
#include "render/fast_fused-inl.h"   // the default MLP shape's chunk in registers (per target)
// clang-format on

HWY_BEFORE_NAMESPACE();
namespace edrnr {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<float>;
using VF = hn::Vec<DF>;
using Clock = std::chrono::steady_clock;

// Block vertices of the 8 corners of a micro voxel, relative to corner
// (0, 0, 0), in the reference's corner order (x fastest).
constexpr uint32_t kCornerVertex[8] = {0, 1, 5, 6, 25, 26, 30, 31};

// Per-chunk scratch: activations of one vector of samples, row r of a buffer
// at [r * N, r * N + N).
struct Scratch {
  alignas(64) float a[kFastMaxWidth * kCap];
  alignas(64) float b[kFastMaxWidth * kCap];
  alignas(64) float cin[kFastMaxWidth * kCap];
  alignas(64) float split[kFastMaxWidth * kCap];
  alignas(64) float rgb[3 * kCap];
  alignas(64) uint32_t words[16 * kCap];
  // Two-word vertices: per pair of corners (x neighbours), each sample's 4
  // consecutive words (corner a group 0, 1, corner b group 0, 1).
  alignas(64) uint32_t pairs[4 * 4 * kCap];
  alignas(64) float fx[kCap], fy[kCap], fz[kCap];
  alignas(64) float out[5 * kCap];
  alignas(64) uint32_t vertex[kCap];
  // The sample's ray slot in dir_q is slot_base + slot[l]. A new slot
  // starts at each change of ray along the batch, so the lanes of a vector
  // span fewer slots than there are lanes.
  alignas(64) int32_t slot[kCap];
  int32_t slot_base = 0;
  // The direction part of the colour net's first layer per ray of a
  // segment (Int8: in accumulator units): output o of slot j at
  // dir_q[o * kDirRow + j].
  alignas(64) float dir_q[kFastMaxWidth * kDirRow];
  // Int8 byte form: a layer's inputs plus 128, 4 rows per word (xq2: the
  // next layer's, written by the layer before it).
  alignas(64) int32_t xq[(kFastMaxWidth / 4) * kCap];
  alignas(64) int32_t xq2[(kFastMaxWidth / 4) * kCap];
};

// The low 4 bits of each lane of u (mask: 15 in every lane) as a float. On
// AVX-512 a lane permutation of the table 0, 1, ..., 15, which reads only
// those bits; elsewhere a mask and a conversion. The same values.
template <class DT, class VU>
HWY_INLINE hn::Vec<DT> CodeValue(DT d, VU u, VU mask) {
#if HWY_TARGET == HWY_AVX3 || HWY_TARGET == HWY_AVX3_DL
  hn::Vec<DT> r = hn::Zero(d);
  if constexpr (sizeof(r.raw) == 64) {
    const __m512 table = _mm512_setr_ps(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    r.raw = _mm512_permutexvar_ps(u.raw, table);
    return r;
  } else if constexpr (sizeof(r.raw) == 32) {
    const __m256 lo = _mm256_setr_ps(0, 1, 2, 3, 4, 5, 6, 7), hi = _mm256_setr_ps(8, 9, 10, 11, 12, 13, 14, 15);
    r.raw = _mm256_permutex2var_ps(lo, u.raw, hi);
    return r;
  }
#endif
  return hn::ConvertTo(d, hn::BitCast(hn::RebindToSigned<DT>(), hn::And(u, mask)));
}

// The two-word vertices of InterpolateQ4 on AVX-512: for the corner pair p
// (words `offset` on from a sample's corner (0, 0, 0)), each sample's 4
// words (a0, a1, b0, b1: corner a's two words, then b's) read with one
// 16-byte load into a 128-bit block of a register (register q holds samples
// q, q + 4, q + 8, q + 12), then transposed within the blocks, so that
// vector a0 holds word a0 of samples 0 .. N - 1 in order: the rows
// LoadInterleaved4 of the copies makes, without the copies (whose 16-byte
// stores a 64-byte load cannot forward). Rows to words (N lanes each):
// a0 -> 2 p, b0 -> 2 p + 1, a1 -> 8 + 2 p, b1 -> 9 + 2 p.
template <class DT>
constexpr bool PairWordsInRegisters(DT d) {
#if HWY_TARGET == HWY_AVX3 || HWY_TARGET == HWY_AVX3_DL
  return hn::MaxLanes(d) == 16 || hn::MaxLanes(d) == 8;
#elif HWY_TARGET == HWY_AVX2
  return hn::MaxLanes(d) == 8;
#else
  (void)d;
  return false;
#endif
}
template <class DT>
HWY_INLINE void PairWords(DT d, const uint32_t* q4, const uint32_t* vertex, uint32_t offset, int p, size_t N,
                          uint32_t* words) {
#if HWY_TARGET == HWY_AVX3 || HWY_TARGET == HWY_AVX3_DL || HWY_TARGET == HWY_AVX2
  auto at = [&](size_t l) {
    return _mm_loadu_si128(reinterpret_cast<const __m128i*>(q4 + size_t(vertex[l]) * 2 + offset));
  };
  uint32_t* a0 = words + size_t(2 * p) * N;
  uint32_t* b0 = words + size_t(2 * p + 1) * N;
  uint32_t* a1 = words + size_t(8 + 2 * p) * N;
  uint32_t* b1 = words + size_t(9 + 2 * p) * N;
#if HWY_TARGET != HWY_AVX2
  if constexpr (hn::MaxLanes(d) == 16) {
    __m512i z[4];
    for (size_t q = 0; q < 4; ++q) {
      z[q] = _mm512_castsi128_si512(at(q));
      z[q] = _mm512_inserti32x4(z[q], at(q + 4), 1);
      z[q] = _mm512_inserti32x4(z[q], at(q + 8), 2);
      z[q] = _mm512_inserti32x4(z[q], at(q + 12), 3);
    }
    const __m512i t0 = _mm512_unpacklo_epi32(z[0], z[1]), t1 = _mm512_unpackhi_epi32(z[0], z[1]);
    const __m512i t2 = _mm512_unpacklo_epi32(z[2], z[3]), t3 = _mm512_unpackhi_epi32(z[2], z[3]);
    _mm512_store_si512(a0, _mm512_unpacklo_epi64(t0, t2));
    _mm512_store_si512(a1, _mm512_unpackhi_epi64(t0, t2));
    _mm512_store_si512(b0, _mm512_unpacklo_epi64(t1, t3));
    _mm512_store_si512(b1, _mm512_unpackhi_epi64(t1, t3));
  } else
#endif
      if constexpr (hn::MaxLanes(d) == 8) {
    __m256i z[4];
    for (size_t q = 0; q < 4; ++q) z[q] = _mm256_inserti128_si256(_mm256_castsi128_si256(at(q)), at(q + 4), 1);
    const __m256i t0 = _mm256_unpacklo_epi32(z[0], z[1]), t1 = _mm256_unpackhi_epi32(z[0], z[1]);
    const __m256i t2 = _mm256_unpacklo_epi32(z[2], z[3]), t3 = _mm256_unpackhi_epi32(z[2], z[3]);
    _mm256_store_si256(reinterpret_cast<__m256i*>(a0), _mm256_unpacklo_epi64(t0, t2));
    _mm256_store_si256(reinterpret_cast<__m256i*>(a1), _mm256_unpackhi_epi64(t0, t2));
    _mm256_store_si256(reinterpret_cast<__m256i*>(b0), _mm256_unpacklo_epi64(t1, t3));
    _mm256_store_si256(reinterpret_cast<__m256i*>(b1), _mm256_unpackhi_epi64(t1, t3));
  }
#else
  (void)d, (void)q4, (void)vertex, (void)offset, (void)p, (void)N, (void)words;
#endif
}

// Features of the chunk's samples from INT4 codes, 8 channels per 32-bit
// word (F a multiple of 8), into rows of X: float values (Float) or the
// density net's INT8 inputs (Int8, feature_in: per-channel multipliers).
// Int8 with xq: those inputs in the byte form instead (PackBytes' words).
template <bool kInt8, class DT>
void InterpolateQ4(DT d, size_t N, const FastModel& fm, Scratch& s, const float* feature_in, float* X,
                   int32_t* xq = nullptr) {
  const hn::RebindToUnsigned<DT> du;
  const hn::RebindToSigned<DT> di;
  const hn::Vec<DT> one = hn::Set(d, 1.f);
  const hn::Vec<DT> fx = hn::Load(d, s.fx), fy = hn::Load(d, s.fy), fz = hn::Load(d, s.fz);
  const hn::Vec<DT> wx[2] = {hn::Sub(one, fx), fx}, wy[2] = {hn::Sub(one, fy), fy}, wz[2] = {hn::Sub(one, fz), fz};
  hn::Vec<DT> w[8];
  for (int j = 0; j < 8; ++j) w[j] = hn::Mul(hn::Mul(wx[j & 1], wy[(j >> 1) & 1]), wz[j >> 2]);
  // The codes as 32-bit words (8 channels each): F / 8 words per vertex,
  // gathered per corner (the feature array starts on an allocation boundary).
  const uint32_t* q4 = reinterpret_cast<const uint32_t*>(fm.model->features_q4.data());
  const int F = fm.feature_channels;
  const int32_t vertex_words = F / 8;
  const auto vertex = hn::Mul(hn::BitCast(di, hn::Load(du, s.vertex)), hn::Set(di, vertex_words));
  const auto mask = hn::Set(du, 15u);
  // Two words per vertex (16 channels): corners j and j + 1 (j even) are
  // neighbours along x, so their 4 words are consecutive: copied per sample
  // and de-interleaved, which is cheaper than 16 gathers.
  const bool pairs = vertex_words == 2;
  if (pairs && PairWordsInRegisters(d)) {
    for (int p = 0; p < 4; ++p) PairWords(d, q4, s.vertex, kCornerVertex[2 * p] * 2, p, N, s.words);
  } else if (pairs) {
    for (size_t l = 0; l < N; ++l) {
      const uint32_t* v = q4 + size_t(s.vertex[l]) * 2;
      for (int p = 0; p < 4; ++p)
        std::memcpy(s.pairs + (size_t(p) * N + l) * 4, v + size_t(kCornerVertex[2 * p]) * 2, 4 * sizeof(uint32_t));
    }
    for (int p = 0; p < 4; ++p) {
      hn::Vec<decltype(du)> a0, a1, b0, b1;
      hn::LoadInterleaved4(du, s.pairs + size_t(p) * N * 4, a0, a1, b0, b1);
      hn::Store(a0, du, s.words + size_t(2 * p) * N);
      hn::Store(b0, du, s.words + size_t(2 * p + 1) * N);
      hn::Store(a1, du, s.words + size_t(8 + 2 * p) * N);
      hn::Store(b1, du, s.words + size_t(8 + 2 * p + 1) * N);
    }
  }
  for (int g = 0; g < F / 8; ++g) {
    const uint32_t* words = s.words + (pairs ? size_t(g) * 8 * N : 0);
    if (!pairs) {
      for (int j = 0; j < 8; ++j) {
        const auto idx = hn::Add(vertex, hn::Set(di, int32_t(kCornerVertex[j]) * vertex_words + g));
        hn::Store(hn::GatherIndex(du, q4, idx), du, s.words + size_t(j) * N);
      }
    }
    const int c0 = 8 * g;
    hn::Vec<DT> acc[8];
    hn::Vec<DT> zp[8], scale[8];
    for (int k = 0; k < 8; ++k) {
      acc[k] = hn::Zero(d);
      zp[k] = hn::Set(d, fm.feature_zero_point[size_t(c0 + k)]);
      scale[k] = hn::Set(d, fm.feature_scale[size_t(c0 + k)]);
    }
    for (int j = 0; j < 8; ++j) {
      const auto word = hn::Load(du, words + size_t(j) * N);
      for (int k = 0; k < 8; ++k) {
        const hn::Vec<DT> code = CodeValue(d, k == 0 ? word : hn::ShiftRightSame(word, 4 * k), mask);
        acc[k] = hn::MulAdd(w[j], code, acc[k]);
      }
    }
    if (kInt8 && xq) {
      // Clamped, then rounded (the bounds are integers: the same values),
      // plus kByteOffset, 4 channels per word.
      for (int h = 0; h < 2; ++h) {
        auto word = hn::Zero(di);
        for (int b = 0; b < 4; ++b) {
          const int k = 4 * h + b;
          hn::Vec<DT> v = hn::Mul(hn::Sub(acc[k], zp[k]), hn::Set(d, feature_in[c0 + k]));
          v = hn::Min(hn::Max(v, hn::Set(d, -128.f)), hn::Set(d, 127.f));
          word = hn::Or(word, ByteAt(RoundToInt(d, v), b));
        }
        hn::Store(word, di, xq + size_t(c0 / 4 + h) * N);
      }
      continue;
    }
    for (int k = 0; k < 8; ++k) {
      hn::Vec<DT> v = acc[k];
      if (kInt8) {
        v = hn::Round(hn::Mul(hn::Sub(v, zp[k]), hn::Set(d, feature_in[c0 + k])));
        v = hn::Min(hn::Max(v, hn::Set(d, -128.f)), hn::Set(d, 127.f));
      } else {  // the weights sum to 1: (sum of w code - zero point) * scale
        v = hn::Mul(hn::Sub(v, zp[k]), scale[k]);
      }
      hn::Store(v, d, X + size_t(c0 + k) * N);
    }
  }
}

// Features of the chunk's samples one value at a time, in the reference's
// order (float features, or INT4 codes when F is not a multiple of 8).
void InterpolateScalar(size_t N, const FastModel& fm, const Scratch& s, float* X) {
  const SceneModel& m = *fm.model;
  const int F = fm.feature_channels;
  const bool q4 = fm.form.quantized_features;
  for (size_t l = 0; l < N; ++l) {
    const float wx[2] = {1.f - s.fx[l], s.fx[l]}, wy[2] = {1.f - s.fy[l], s.fy[l]}, wz[2] = {1.f - s.fz[l], s.fz[l]};
    for (int c = 0; c < F; ++c) X[size_t(c) * N + l] = 0.f;
    for (int j = 0; j < 8; ++j) {
      const float w = wx[j & 1] * wy[(j >> 1) & 1] * wz[j >> 2];
      const size_t base = (size_t(s.vertex[l]) + kCornerVertex[j]) * size_t(F);
      for (int c = 0; c < F; ++c) {
        float v;
        if (q4) {
          const size_t idx = base + size_t(c);
          const uint8_t byte = m.features_q4[idx >> 1];
          const int q = (idx & 1) ? (byte >> 4) : (byte & 15);
          v = float(q - int(m.feature_quant.zero_point[size_t(c)])) * m.feature_quant.scale[size_t(c)];
        } else {
          v = m.features_f32[base + size_t(c)];
        }
        X[size_t(c) * N + l] += w * v;
      }
    }
  }
}

// The chip's arithmetic in the byte form (RunNet<true> with q): each
// layer's inputs packed 4 to a word (PackBytes), and a hidden layer whose
// outputs are all the next layer's byte-form inputs writes them packed
// (DenseBytesHidden) instead of as rows of floats to be packed again. xq,
// xq_next: scratch for the packed inputs (in_packed: xq holds the first
// layer's already, and `in` is not read). The results are RunNet's.
template <class DT>
void RunNetBytes(DT d, size_t N, const std::vector<FastLayer>& net, const float* p, const int32_t* q, const float* in,
                 float* a, float* last, int split, const float* dir_q, const int32_t* slots, int32_t* xq,
                 int32_t* xq_next, bool in_packed) {
  const hn::RebindToSigned<DT> di;
  const auto lanes = hn::IndicesFromVec(d, split >= 0 ? hn::Load(di, slots) : hn::Zero(di));
  const float* x = in;
  bool packed = in_packed;  // the layer's inputs are in xq already
  for (size_t l = 0; l < net.size(); ++l) {
    const FastLayer& L = net[l];
    const bool hidden = l + 1 < net.size();
    if (!packed) PackBytes(d, N, x, L.q_in, xq);
    const float* dir = l == 0 && split >= 0 ? dir_q : nullptr;
    // A first layer's inputs are signed; later ones are ReLU outputs.
    const bool first = l == 0;
    if (hidden && L.out % 4 == 0 && net[l + 1].q_in == L.out) {
      if (first)
        DenseBytesHidden<true>(d, N, xq, L, q, p + L.m, dir, lanes, xq_next);
      else
        DenseBytesHidden<false>(d, N, xq, L, q, p + L.m, dir, lanes, xq_next);
      std::swap(xq, xq_next);
      packed = true;
      continue;
    }
    float* y = hidden ? a : last;  // x is packed already: a may be overwritten
    Epilogue e;
    e.mult = p + L.m;
    e.lo = hidden ? 0.f : -32768.f;
    e.hi = hidden ? 127.f : 32767.f;
    if (dir) {
      DenseBytes<true>(d, N, xq, L, q, y, Epilogue());
      AddDirectionTerms(d, N, y, L.out, dir, lanes, e);
    } else if (first) {
      DenseBytes<true>(d, N, xq, L, q, y, e);
    } else {
      DenseBytes<false>(d, N, xq, L, q, y, e);
    }
    x = y;
    packed = false;
  }
}

// A net's layers from `in` into `last` (rows of the last layer's output),
// hidden layers through a and b. Int8 with split >= 0: the first layer's
// products of the inputs from split on (the direction) are not summed here but
// read from dir_q (DirectionParts) at each sample's slot. Int8 with q: the
// byte form (RunNetBytes, scratch xq and xq_next; in_packed: the inputs
// are in xq already).
template <bool kInt8, class DT>
void RunNet(DT d, size_t N, const std::vector<FastLayer>& net, const float* p, const int32_t* q, const float* in,
            float* a, float* b, float* last, int split, const float* dir_q, const int32_t* slots, int32_t* xq,
            int32_t* xq_next, bool in_packed = false) {
  if constexpr (kInt8 && kHaveDotBytes) {
    if (q) {
      RunNetBytes(d, N, net, p, q, in, a, last, split, dir_q, slots, xq, xq_next, in_packed);
      return;
    }
  }
  // split >= 0: dir_q points at the chunk's first slot, slots holds the
  // lanes' slots relative to it (each below the lane count).
  const float* x = in;
  for (size_t l = 0; l < net.size(); ++l) {
    const FastLayer& L = net[l];
    const bool hidden = l + 1 < net.size();
    float* y = !hidden ? last : (x == a ? b : a);
    // Int8: ReLU and the next layer's INT8 input (hidden), or raw outputs
    // in 1/256 steps (last); float: ReLU (hidden).
    Epilogue e;
    if (kInt8) {
      e.mult = p + L.m;
      e.lo = hidden ? 0.f : -32768.f;
      e.hi = hidden ? 127.f : 32767.f;
    } else {
      e.relu = hidden;
    }
    if (l == 0 && split >= 0) {
      // The inputs before `split` here; those from it on (the direction)
      // were summed per ray (DirectionParts): added by the sample's slot,
      // then the epilogue.
      Dense(d, N, x, L.in, 0, split, p + L.w, p + L.b, L.out, y);
      const hn::RebindToSigned<DT> di;
      const auto lanes = hn::IndicesFromVec(d, hn::Load(di, slots));
      AddDirectionTerms(d, N, y, L.out, dir_q, lanes, e);
    } else {
      Dense(d, N, x, L.in, 0, L.in, p + L.w, p + L.b, L.out, y, e);
    }
    x = y;
  }
}

// Rows [G, G + D) of X: direction value k of ray rays[l] in lane l (floats,
// or with int32 lanes the byte form's packed words).
template <class DT>
void GatherDirections(DT d, size_t N, const hn::TFromD<DT>* dir, size_t ray_stride, const uint32_t* rays, int G, int D,
                      hn::TFromD<DT>* X) {
  const hn::RebindToSigned<DT> di;
  const auto ray = hn::BitCast(di, hn::Load(hn::RebindToUnsigned<DT>(), rays));
  // Consecutive rays (the common case: neighbouring pixels): plain loads.
  const bool run = hn::AllTrue(di, hn::Eq(ray, hn::Add(hn::Set(di, int32_t(rays[0])), hn::Iota(di, 0))));
  for (int k = 0; k < D; ++k) {
    const hn::TFromD<DT>* row = dir + size_t(k) * ray_stride;
    hn::Store(run ? hn::LoadU(d, row + rays[0]) : hn::GatherIndex(d, row, ray), d, X + size_t(G + k) * N);
  }
}

// dir_q for `count` rays (slots 0..count-1, ray of slot j: rays[j]): the
// colour net's first-layer products of the direction inputs, summed in input
// order; Int8: brought to accumulator units with the multiplier dir_in and
// rounded (as the chip adds them to the other products).
template <bool kInt8, class DT>
void DirectionParts(DT d, size_t N, const FastModel& fm, const float* p, const int32_t* q, const float* dir,
                    size_t ray_stride, const uint32_t* rays, size_t count, Scratch& s) {
  const FastLayer& L = fm.color.front();
  const int G = fm.geo_width, D = fm.dir_dims;
  const hn::Vec<DT> m = hn::Set(d, kInt8 ? p[fm.dir_in] : 1.f);
  alignas(64) uint32_t lane_rays[kCap];
  for (size_t j0 = 0; j0 < count; j0 += N) {
    for (size_t l = 0; l < N; ++l) lane_rays[l] = rays[std::min(j0 + l, count - 1)];
    if (kInt8 && kHaveDotBytes && q) {
      // The byte form: the rays' packed direction bytes (the rows after the
      // D values: fast_direction_rows) read as words, 4 inputs per product.
      const int words = (D + 3) / 4;
      GatherDirections(hn::RebindToSigned<DT>(), N, reinterpret_cast<const int32_t*>(dir + size_t(D) * ray_stride),
                       ray_stride, lane_rays, 0, words, s.xq);
      DirectionBytes(d, N, s.xq, words, q + L.dwq, q + L.dbq, L.out, p[fm.dir_in], s.dir_q + j0);
      continue;
    }
    GatherDirections(d, N, dir, ray_stride, lane_rays, G, D, s.cin);
    Dense(d, N, s.cin, L.in, G, L.in, p + L.w, nullptr, L.out, s.split);
    for (int o = 0; o < L.out; ++o) {
      const hn::Vec<DT> v = hn::Load(d, s.split + size_t(o) * N);
      hn::Store(kInt8 ? hn::Round(hn::Mul(v, m)) : v, d, s.dir_q + size_t(o) * kDirRow + j0);
    }
  }
}

template <bool kInt8, class DT>
void EvalChunk(DT d, size_t N, const FastModel& fm, const float* p, const int32_t* q, const float* dir,
               size_t ray_stride, float delta, bool fused, const FastActivationTables* tables, Scratch& s,
               FastKernelSeconds* seconds) {
  Clock::time_point t0;
  if (seconds) t0 = Clock::now();
  const int F = fm.feature_channels, G = fm.geo_width, D = fm.dir_dims;
  // Int8 in the byte form: the nets' first inputs are packed as they are made.
  const bool bytes = kInt8 && kHaveDotBytes && q != nullptr;
  bool features_packed = false;
  if (fm.form.quantized_features && F % 8 == 0 && fm.model->features_q4.size() < (size_t(1) << 31)) {
    InterpolateQ4<kInt8>(d, N, fm, s, p + fm.feature_in, s.a, bytes ? s.xq : nullptr);
    features_packed = bytes;
  } else {
    InterpolateScalar(N, fm, s, s.a);
    if (kInt8) Requantize(d, N, s.a, F, p + fm.feature_in, true, -128.f, 127.f);
  }
  Clock::time_point t1;
  if (seconds) {
    t1 = Clock::now();
    seconds->interpolation += std::chrono::duration<double>(t1 - t0).count();
  }
  if (fused) {
    if (kInt8)
      FusedNets(d, N, fm, p, q, s.xq, s.dir_q + s.slot_base, s.slot, delta, tables ? tables->alpha.data() : nullptr,
                tables ? tables->sigmoid.data() : nullptr, s.out);
    else
      FusedNetsFloat(d, N, fm, p, s.a, s.dir_q + s.slot_base, s.slot, delta, s.out);
    if (seconds) seconds->mlp += std::chrono::duration<double>(Clock::now() - t1).count();
    return;
  }

  // Density net: its G outputs land in the first rows of the colour input.
  RunNet<kInt8>(d, N, fm.density, p, q, s.a, s.a, s.b, s.cin, -1, nullptr, nullptr, s.xq, s.xq2, features_packed);
  hn::Vec<DT> raw = hn::Load(d, s.cin);
  if (kInt8) {
    raw = hn::Mul(raw, hn::Set(d, 1.f / 256.f));
    if (bytes)  // the colour net's first inputs, packed
      PackBytesScaled(d, N, s.cin, G, p[fm.geo_in], s.xq);
    else
      Requantize(d, N, s.cin, G, p + fm.geo_in, false, -128.f, 127.f);
  }
  const hn::Vec<DT> sigma = hn::Exp(d, hn::Min(hn::Max(raw, hn::Set(d, kRawSigmaMin)), hn::Set(d, kRawSigmaMax)));
  const hn::Vec<DT> tau = hn::Mul(sigma, hn::Set(d, delta));
  const hn::Vec<DT> alpha = hn::Neg(hn::Expm1(d, hn::Neg(tau)));
  const hn::Vec<DT> trans = kInt8 ? hn::Sub(hn::Set(d, 1.f), alpha) : hn::Exp(d, hn::Neg(tau));
  hn::Store(alpha, d, s.out);
  hn::Store(trans, d, s.out + N);
  // The direction inputs' part of the colour net is in dir_q.
  RunNet<kInt8>(d, N, fm.color, p, q, s.cin, s.a, s.b, s.rgb, D > 0 ? G : -1, s.dir_q + s.slot_base, s.slot, s.xq,
                s.xq2, bytes);
  for (int c = 0; c < 3; ++c) {
    hn::Vec<DT> v = hn::Load(d, s.rgb + size_t(c) * N);
    if (kInt8) v = hn::Mul(v, hn::Set(d, 1.f / 256.f));
    hn::Store(Sigmoid(d, v), d, s.out + size_t(2 + c) * N);
  }
  if (seconds) seconds->mlp += std::chrono::duration<double>(Clock::now() - t1).count();
}

// One chunk of a batch: its samples [0, valid) (b: the batch from the
// chunk's first sample on) in the lanes of d (the tail repeats the last
// sample; Int8: slots[l] is lane l's slot in s.dir_q), their outputs to out.
template <bool kInt8, class DT>
void RunChunk(DT d, const FastModel& fm, const float* p, const int32_t* q, bool fused,
              const FastActivationTables* tables, const FastBatch& b, size_t valid, const int32_t* slots,
              const float* dir, size_t ray_stride, float delta, Scratch& s, FastSampleOut* out,
              FastKernelSeconds* seconds) {
  const size_t N = hn::Lanes(d);
  const hn::RebindToSigned<DT> di;
  const hn::RebindToUnsigned<DT> du;
  alignas(64) int32_t slot[kCap];
  if (valid == N) {  // whole vectors of the fields
    hn::Store(hn::LoadU(d, b.fx), d, s.fx);
    hn::Store(hn::LoadU(d, b.fy), d, s.fy);
    hn::Store(hn::LoadU(d, b.fz), d, s.fz);
    hn::Store(hn::LoadU(du, b.vertex), du, s.vertex);
    hn::Store(hn::LoadU(di, slots), di, slot);
  } else {  // the tail repeats the last sample
    for (size_t l = 0; l < N; ++l) {
      const size_t i = std::min(l, valid - 1);
      s.fx[l] = b.fx[i];
      s.fy[l] = b.fy[i];
      s.fz[l] = b.fz[i];
      s.vertex[l] = b.vertex[i];
      slot[l] = slots[i];
    }
  }
  s.slot_base = slot[0];
  hn::Store(hn::Sub(hn::Load(di, slot), hn::Set(di, s.slot_base)), di, s.slot);
  EvalChunk<kInt8>(d, N, fm, p, q, dir, ray_stride, delta, fused, tables, s, seconds);
  for (size_t l = 0; l < valid; ++l) {
    FastSampleOut& o = out[b.order[l]];
    o.alpha = s.out[l];
    o.trans = s.out[N + l];
    for (int c = 0; c < 3; ++c) o.rgb[c] = s.out[size_t(2 + c) * N + l];
  }
}

void EvalBatch(const FastModel& fm, uint32_t mlp, const FastBatch& batch, size_t n, const float* dir, size_t ray_stride,
               float delta, FastSampleOut* out, FastKernelSeconds* seconds, const FastActivationTables* given) {
  const DF d;
  const hn::Half<DF> dh;
  const size_t N = hn::Lanes(d);
  Scratch s;
  const float* p = fm.mlp(mlp);
  const bool int8 = fm.arithmetic == FastArithmetic::Int8;
  const int32_t* q = int8 && !fm.quads.empty() ? fm.mlp_quads(mlp) : nullptr;
  const bool fused = FusedShape(fm, q);  // the default MLP shape: FusedNets
  // Tables made for another spacing (or for the float path) are not read.
  const FastActivationTables* tables =
      int8 && given && given->delta == delta && given->alpha.size() == 65536 ? given : nullptr;
  // Int8: per segment, the rays met (a new slot at each change of ray: a
  // ray's samples are consecutive) and their direction parts.
  alignas(64) uint32_t seg_rays[kSegment];
  alignas(64) int32_t seg_slot[kSegment + kCap];
  size_t seg_begin = 0, seg_end = 0;
  // INT4 features read in whole words (InterpolateQ4) are prefetched.
  const int F = fm.feature_channels;
  const uint8_t* q4 = fm.form.quantized_features && F % 8 == 0 ? fm.model->features_q4.data() : nullptr;
  const size_t vertex_bytes = size_t(F) / 2;
  for (size_t i0 = 0; i0 < n; i0 += N) {
    const size_t valid = std::min(N, n - i0);
    if (fm.dir_dims > 0 && i0 >= seg_end) {
      seg_begin = i0;
      seg_end = std::min(n, i0 + kSegment);  // kSegment is a multiple of N: chunks do not cross segments
      // Without a branch per sample: each sample writes its ray at the next
      // slot, which it takes only if the ray changed (rays are tile indices,
      // never UINT32_MAX).
      size_t slots = 0;
      uint32_t last = UINT32_MAX;
      for (size_t i = i0; i < seg_end; ++i) {
        const uint32_t ray = batch.ray[i];
        seg_rays[slots] = ray;
        slots += ray != last;
        last = ray;
        seg_slot[i - i0] = int32_t(slots - 1);
      }
      if (int8)
        DirectionParts<true>(d, N, fm, p, q, dir, ray_stride, seg_rays, slots, s);
      else
        DirectionParts<false>(d, N, fm, p, q, dir, ray_stride, seg_rays, slots, s);
    }
    // The next chunk's feature words (mostly in L3: the features are larger
    // than L2) are fetched while this chunk runs: per sample the four runs
    // of x-neighbour corners (InterpolateQ4).
    if (q4 != nullptr) {
      const size_t next_end = std::min(n, i0 + 2 * N);
      for (size_t i = i0 + N; i < next_end; ++i) {
        const uint8_t* v = q4 + size_t(batch.vertex[i]) * vertex_bytes;
        for (int j = 0; j < 8; j += 2) hwy::Prefetch(v + kCornerVertex[j] * vertex_bytes);
      }
    }
    // A batch's last chunk, when it fills at most half the lanes, runs in
    // half-width vectors: the lanes are independent, so the results are the
    // same, for half the work on padding lanes. (Quarter-width vectors for
    // the shortest tails were slower.)
    const int32_t* slots = seg_slot + (i0 - seg_begin);
    FastBatch b = batch;  // from the chunk's first sample on
    b.ray += i0;
    b.vertex += i0;
    b.fx += i0;
    b.fy += i0;
    b.fz += i0;
    b.order += i0;
    if (N >= 8 && valid <= hn::Lanes(dh)) {
      if (int8)
        RunChunk<true>(dh, fm, p, q, fused, tables, b, valid, slots, dir, ray_stride, delta, s, out, seconds);
      else
        RunChunk<false>(dh, fm, p, q, fused, tables, b, valid, slots, dir, ray_stride, delta, s, out, seconds);
    } else if (int8) {
      RunChunk<true>(d, fm, p, q, fused, tables, b, valid, slots, dir, ray_stride, delta, s, out, seconds);
    } else {
      RunChunk<false>(d, fm, p, q, fused, tables, b, valid, slots, dir, ray_stride, delta, s, out, seconds);
    }
  }
}

void EncodeDirections(const FastModel& fm, const float* dx, const float* dy, const float* dz, size_t n, float* out,
                      size_t ray_stride) {
  const DF d;
  const size_t N = hn::Lanes(d);
  const bool int8 = fm.arithmetic == FastArithmetic::Int8;
  for (size_t r = 0; r < n; r += N) {
    const VF v[3] = {hn::LoadU(d, dx + r), hn::LoadU(d, dy + r), hn::LoadU(d, dz + r)};
    int row = 0;
    auto put = [&](VF x) {
      if (int8) x = hn::Min(hn::Max(hn::Round(hn::Mul(x, hn::Set(d, 127.f))), hn::Set(d, -127.f)), hn::Set(d, 127.f));
      hn::StoreU(x, d, out + size_t(row++) * ray_stride + r);
    };
    for (int a = 0; a < 3; ++a) put(v[a]);
    float freq = 1.f;
    for (int k = 0; k < fm.dir_frequencies; ++k) {
      const VF f = hn::Set(d, freq);
      for (int a = 0; a < 3; ++a) put(hn::Sin(d, hn::Mul(f, v[a])));
      for (int a = 0; a < 3; ++a) put(hn::Cos(d, hn::Mul(f, v[a])));
      freq *= 2.f;
    }
    if (int8 && !fm.quads.empty()) {
      // The byte form's rows (fast_direction_rows): codes plus kByteOffset
      // as bytes, input 4 j + k in byte k of row D + j.
      const hn::RebindToSigned<DF> di;
      const int D = fm.dir_dims;
      for (int j = 0; 4 * j < D; ++j) {
        auto u = hn::Zero(di);
        for (int k = 0; k < 4 && 4 * j + k < D; ++k) {
          const auto code = hn::ConvertTo(di, hn::LoadU(d, out + size_t(4 * j + k) * ray_stride + r));
          u = hn::Or(u, ByteAt(code, k));
        }
        hn::StoreU(u, di, reinterpret_cast<int32_t*>(out + size_t(D + j) * ray_stride + r));
      }
    }
  }
}

void ActivationTables(float delta, float* alpha, float* sigmoid) {
  const DF d;
  const size_t N = hn::Lanes(d);
  for (size_t i = 0; i < 65536; i += N) {                                   // 65536 is a multiple of every lane count
    const VF raw_q = hn::Add(hn::Iota(d, float(i)), hn::Set(d, -32768.f));  // exact integers
    hn::StoreU(AlphaOfRaw(d, raw_q, delta), d, alpha + i);
    hn::StoreU(ColourOfRaw(d, raw_q), d, sigmoid + i);
  }
}

int64_t Target() { return HWY_TARGET; }

int32_t ByteFormOffset() { return kHaveDotBytes ? kByteOffset : -1; }

bool FusedModel(const FastModel& fm) { return FusedShape(fm, fm.quads.empty() ? nullptr : fm.quads.data()); }

}  // namespace HWY_NAMESPACE
}  // namespace edrnr
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace edrnr {

HWY_EXPORT(EvalBatch);
HWY_EXPORT(ActivationTables);
HWY_EXPORT(EncodeDirections);
HWY_EXPORT(Target);
HWY_EXPORT(ByteFormOffset);
HWY_EXPORT(FusedModel);

void fast_eval_batch(const FastModel& fm, uint32_t mlp, const FastBatch& batch, size_t n, const float* dir,
                     size_t ray_stride, float delta, FastSampleOut* out, FastKernelSeconds* seconds,
                     const FastActivationTables* tables) {
  HWY_DYNAMIC_DISPATCH(EvalBatch)(fm, mlp, batch, n, dir, ray_stride, delta, out, seconds, tables);
}

FastActivationTables fast_activation_tables(const FastModel& fm, float delta) {
  FastActivationTables t;
  if (fm.arithmetic != FastArithmetic::Int8) return t;
  t.delta = delta;
  t.alpha.resize(65536);
  t.sigmoid.resize(65536);
  HWY_DYNAMIC_DISPATCH(ActivationTables)(delta, t.alpha.data(), t.sigmoid.data());
  return t;
}

void fast_eval_batch(const FastModel& fm, uint32_t mlp, const FastSample* samples, const uint32_t* order, size_t n,
                     const float* dir, size_t ray_stride, float delta, FastSampleOut* out, FastKernelSeconds* seconds,
                     const FastActivationTables* tables) {
  std::vector<uint32_t> ray(n), vertex(n);
  std::vector<float> fx(n), fy(n), fz(n);
  for (size_t i = 0; i < n; ++i) {
    const FastSample& r = samples[order[i]];
    ray[i] = r.ray;
    vertex[i] = r.vertex;
    fx[i] = r.fx;
    fy[i] = r.fy;
    fz[i] = r.fz;
  }
  const FastBatch batch{ray.data(), vertex.data(), fx.data(), fy.data(), fz.data(), order};
  fast_eval_batch(fm, mlp, batch, n, dir, ray_stride, delta, out, seconds, tables);
}

void fast_encode_directions(const FastModel& fm, const float* dx, const float* dy, const float* dz, size_t n,
                            float* out, size_t ray_stride) {
  HWY_DYNAMIC_DISPATCH(EncodeDirections)(fm, dx, dy, dz, n, out, ray_stride);
}

const char* fast_simd_target() { return hwy::TargetName(HWY_DYNAMIC_DISPATCH(Target)()); }

int fast_byte_form_offset() { return HWY_DYNAMIC_DISPATCH(ByteFormOffset)(); }

bool fast_fused_shape(const FastModel& fm) { return HWY_DYNAMIC_DISPATCH(FusedModel)(fm); }

}  // namespace edrnr
#endif
