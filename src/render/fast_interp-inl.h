// The fast renderer's trilinear interpolation of a chunk's features from
// the model's fine-voxel blocks (INT4 codes read in place, or floats), and
// the per-chunk scratch the batch kernel works in. Included once per SIMD
// target by render/fast_kernels.cpp, after fast_layers-inl.h.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "render/fast_model.h"

#if defined(EDRNR_RENDER_FAST_INTERP_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef EDRNR_RENDER_FAST_INTERP_INL_H_
#undef EDRNR_RENDER_FAST_INTERP_INL_H_
#else
#define EDRNR_RENDER_FAST_INTERP_INL_H_
#endif

#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace edrnr {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

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

// The two-word vertices of InterpolateQ4 on AVX-512 and on AVX2 (8 lanes):
// for the corner pair p (words `offset` on from a sample's corner (0, 0,
// 0)), each sample's 4 words (a0, a1, b0, b1: corner a's two words, then
// b's) read with one 16-byte load into a 128-bit block of a register
// (register q holds samples q, q + 4, q + 8, q + 12), then transposed
// within the blocks, so that vector a0 holds word a0 of samples 0 .. N - 1
// in order: the rows LoadInterleaved4 of the copies makes, without the
// copies (whose 16-byte stores a wider load cannot forward). Rows to words (N lanes each):
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
inline void InterpolateScalar(size_t N, const FastModel& fm, const Scratch& s, float* X) {
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

}  // namespace HWY_NAMESPACE
}  // namespace edrnr
HWY_AFTER_NAMESPACE();

#endif  // EDRNR_RENDER_FAST_INTERP_INL_H_
