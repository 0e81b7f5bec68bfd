// Highway kernels of the fast renderer; compiled once per SIMD target
// (hwy/foreach_target.h) and picked at run time (HWY_DYNAMIC_DISPATCH).
#include "render/fast_kernels.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <vector>

#include "model/mlp.h"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/fast_kernels.cpp"
// clang-format off
#include <hwy/foreach_target.h>  // before highway.h
#include <hwy/highway.h>
#include <hwy/contrib/math/math-inl.h>
// clang-format on

HWY_BEFORE_NAMESPACE();
namespace edrnr {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<float>;
using VF = hn::Vec<DF>;
using Clock = std::chrono::steady_clock;

// Room for the widest vector of any target.
constexpr size_t kCap = HWY_MAX_BYTES / sizeof(float);
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
  alignas(64) uint32_t words[8 * kCap];
  alignas(64) float fx[kCap], fy[kCap], fz[kCap];
  alignas(64) float out[5 * kCap];
  uint32_t vertex[kCap];
  uint32_t ray[kCap];
};

// ACC rows [o, o + NB) = (B ? bias : 0) + W[o.., i0..i1) X[i0..i1), one
// product at a time in input order. kFma: fused multiply-add (the Int8 path,
// whose products and sums are exact integers); otherwise multiply then add,
// the reference's rounding.
template <int NB, bool kFma>
HWY_INLINE void DenseBlock(DF d, size_t N, const float* X, int in, int i0, int i1, const float* W, const float* B,
                           int o, float* ACC) {
  VF acc[NB];
  for (int k = 0; k < NB; ++k) acc[k] = B ? hn::Set(d, B[o + k]) : hn::Zero(d);
  for (int i = i0; i < i1; ++i) {
    const VF x = hn::Load(d, X + size_t(i) * N);
    for (int k = 0; k < NB; ++k) {
      const VF w = hn::Set(d, W[size_t(o + k) * size_t(in) + size_t(i)]);
      acc[k] = kFma ? hn::MulAdd(w, x, acc[k]) : hn::Add(acc[k], hn::Mul(w, x));
    }
  }
  for (int k = 0; k < NB; ++k) hn::Store(acc[k], d, ACC + size_t(o + k) * N);
}

template <bool kFma>
void Dense(DF d, size_t N, const float* X, int in, int i0, int i1, const float* W, const float* B, int out,
           float* ACC) {
  int o = 0;
  for (; o + 8 <= out; o += 8) DenseBlock<8, kFma>(d, N, X, in, i0, i1, W, B, o, ACC);
  if (o + 4 <= out) {
    DenseBlock<4, kFma>(d, N, X, in, i0, i1, W, B, o, ACC);
    o += 4;
  }
  if (o + 2 <= out) {
    DenseBlock<2, kFma>(d, N, X, in, i0, i1, W, B, o, ACC);
    o += 2;
  }
  if (o < out) DenseBlock<1, kFma>(d, N, X, in, i0, i1, W, B, o, ACC);
}

// Features of the chunk's samples from INT4 codes, 8 channels per 32-bit
// word (F a multiple of 8), into rows of X: float values (Float) or the
// density net's INT8 inputs (Int8, feature_in: per-channel multipliers).
template <bool kInt8>
void InterpolateQ4(DF d, size_t N, const FastModel& fm, Scratch& s, const float* feature_in, float* X) {
  const hn::RebindToUnsigned<DF> du;
  const hn::RebindToSigned<DF> di;
  const VF one = hn::Set(d, 1.f);
  const VF fx = hn::Load(d, s.fx), fy = hn::Load(d, s.fy), fz = hn::Load(d, s.fz);
  const VF wx[2] = {hn::Sub(one, fx), fx}, wy[2] = {hn::Sub(one, fy), fy}, wz[2] = {hn::Sub(one, fz), fz};
  VF w[8];
  for (int j = 0; j < 8; ++j) w[j] = hn::Mul(hn::Mul(wx[j & 1], wy[(j >> 1) & 1]), wz[j >> 2]);
  const uint8_t* q4 = fm.model->features_q4.data();
  const int F = fm.feature_channels;
  const size_t vertex_bytes = size_t(F) / 2;
  const auto mask = hn::Set(du, 15u);
  for (int g = 0; g < F / 8; ++g) {
    for (size_t l = 0; l < N; ++l)
      for (int j = 0; j < 8; ++j)
        std::memcpy(&s.words[size_t(j) * N + l], q4 + (size_t(s.vertex[l]) + kCornerVertex[j]) * vertex_bytes + 4 * g,
                    4);
    const int c0 = 8 * g;
    VF acc[8];
    VF zp[8], scale[8];
    for (int k = 0; k < 8; ++k) {
      acc[k] = hn::Zero(d);
      zp[k] = hn::Set(d, fm.feature_zero_point[size_t(c0 + k)]);
      scale[k] = hn::Set(d, fm.feature_scale[size_t(c0 + k)]);
    }
    for (int j = 0; j < 8; ++j) {
      const auto word = hn::Load(du, s.words + size_t(j) * N);
      for (int k = 0; k < 8; ++k) {
        const VF code = hn::ConvertTo(d, hn::BitCast(di, hn::And(hn::ShiftRightSame(word, 4 * k), mask)));
        if (kInt8) {
          acc[k] = hn::MulAdd(w[j], code, acc[k]);
        } else {  // the reference: (code - zero point) * scale, weighted, added in corner order
          acc[k] = hn::Add(acc[k], hn::Mul(w[j], hn::Mul(hn::Sub(code, zp[k]), scale[k])));
        }
      }
    }
    for (int k = 0; k < 8; ++k) {
      VF v = acc[k];
      if (kInt8) {
        v = hn::Round(hn::Mul(hn::Sub(v, zp[k]), hn::Set(d, feature_in[c0 + k])));
        v = hn::Min(hn::Max(v, hn::Set(d, -128.f)), hn::Set(d, 127.f));
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

// rows[r] = clamp(round(rows[r] * mult[r or 0]), lo, hi) for r < count.
void Requantize(DF d, size_t N, float* rows, int count, const float* mult, bool per_row, float lo, float hi) {
  for (int r = 0; r < count; ++r) {
    const VF m = hn::Set(d, mult[per_row ? r : 0]);
    float* p = rows + size_t(r) * N;
    const VF v = hn::Round(hn::Mul(hn::Load(d, p), m));
    hn::Store(hn::Min(hn::Max(v, hn::Set(d, lo)), hn::Set(d, hi)), d, p);
  }
}

// A net's layers from `in` into `last` (rows of the last layer's output),
// hidden layers through a and b. Int8 with split >= 0: the inputs from split
// on (the direction) are summed apart in `part` and brought to accumulator
// units with the multiplier dir_in before the bias and the other products.
template <bool kInt8>
void RunNet(DF d, size_t N, const std::vector<FastLayer>& net, const float* p, const float* in, float* a, float* b,
            float* last, int split, float dir_in, float* part) {
  const float* x = in;
  for (size_t l = 0; l < net.size(); ++l) {
    const FastLayer& L = net[l];
    const bool hidden = l + 1 < net.size();
    float* y = !hidden ? last : (x == a ? b : a);
    if (kInt8 && l == 0 && split >= 0) {
      Dense<true>(d, N, x, L.in, 0, split, p + L.w, p + L.b, L.out, y);
      Dense<true>(d, N, x, L.in, split, L.in, p + L.w, nullptr, L.out, part);
      const VF m = hn::Set(d, dir_in);
      for (int o = 0; o < L.out; ++o) {
        float* r = y + size_t(o) * N;
        const VF q = hn::Round(hn::Mul(hn::Load(d, part + size_t(o) * N), m));
        hn::Store(hn::Add(hn::Load(d, r), q), d, r);
      }
    } else {
      Dense<kInt8>(d, N, x, L.in, 0, L.in, p + L.w, p + L.b, L.out, y);
    }
    if (kInt8) {
      if (hidden)
        Requantize(d, N, y, L.out, p + L.m, true, 0.f, 127.f);  // ReLU, then the next layer's INT8 input
      else
        Requantize(d, N, y, L.out, p + L.m, true, -32768.f, 32767.f);  // raw outputs, 1/256 steps
    } else if (hidden) {
      for (int o = 0; o < L.out; ++o) {
        float* r = y + size_t(o) * N;
        hn::Store(hn::Max(hn::Load(d, r), hn::Zero(d)), d, r);
      }
    }
    x = y;
  }
}

VF Sigmoid(DF d, VF x) {
  const VF one = hn::Set(d, 1.f);
  return hn::Div(one, hn::Add(one, hn::Exp(d, hn::Neg(x))));
}

template <bool kInt8>
void EvalChunk(DF d, size_t N, const FastModel& fm, const float* p, const float* dir, size_t ray_stride, float delta,
               Scratch& s, FastKernelSeconds* seconds) {
  Clock::time_point t0;
  if (seconds) t0 = Clock::now();
  const int F = fm.feature_channels, G = fm.geo_width, D = fm.dir_dims;
  if (fm.form.quantized_features && F % 8 == 0) {
    InterpolateQ4<kInt8>(d, N, fm, s, p + fm.feature_in, s.a);
  } else {
    InterpolateScalar(N, fm, s, s.a);
    if (kInt8) Requantize(d, N, s.a, F, p + fm.feature_in, true, -128.f, 127.f);
  }
  Clock::time_point t1;
  if (seconds) {
    t1 = Clock::now();
    seconds->interpolation += std::chrono::duration<double>(t1 - t0).count();
  }

  // Density net: its G outputs land in the first rows of the colour input.
  RunNet<kInt8>(d, N, fm.density, p, s.a, s.a, s.b, s.cin, -1, 0.f, nullptr);
  VF raw = hn::Load(d, s.cin);
  if (kInt8) {
    raw = hn::Mul(raw, hn::Set(d, 1.f / 256.f));
    Requantize(d, N, s.cin, G, p + fm.geo_in, false, -128.f, 127.f);
  }
  const VF sigma = hn::Exp(d, hn::Min(hn::Max(raw, hn::Set(d, kRawSigmaMin)), hn::Set(d, kRawSigmaMax)));
  const VF tau = hn::Mul(sigma, hn::Set(d, delta));
  const VF alpha = hn::Neg(hn::Expm1(d, hn::Neg(tau)));
  const VF trans = kInt8 ? hn::Sub(hn::Set(d, 1.f), alpha) : hn::Exp(d, hn::Neg(tau));
  hn::Store(alpha, d, s.out);
  hn::Store(trans, d, s.out + N);
  // The rays' direction inputs after the density outputs.
  for (int k = 0; k < D; ++k) {
    const float* row = dir + size_t(k) * ray_stride;
    float* dst = s.cin + size_t(G + k) * N;
    for (size_t l = 0; l < N; ++l) dst[l] = row[s.ray[l]];
  }
  RunNet<kInt8>(d, N, fm.color, p, s.cin, s.a, s.b, s.rgb, kInt8 ? G : -1, kInt8 ? p[fm.dir_in] : 0.f, s.split);
  for (int c = 0; c < 3; ++c) {
    VF v = hn::Load(d, s.rgb + size_t(c) * N);
    if (kInt8) v = hn::Mul(v, hn::Set(d, 1.f / 256.f));
    hn::Store(Sigmoid(d, v), d, s.out + size_t(2 + c) * N);
  }
  if (seconds) seconds->mlp += std::chrono::duration<double>(Clock::now() - t1).count();
}

void EvalBatch(const FastModel& fm, uint32_t mlp, const FastSample* samples, const uint32_t* order, size_t n,
               const float* dir, size_t ray_stride, float delta, FastSampleOut* out, FastKernelSeconds* seconds) {
  const DF d;
  const size_t N = hn::Lanes(d);
  Scratch s;
  const float* p = fm.mlp(mlp);
  const bool int8 = fm.arithmetic == FastArithmetic::Int8;
  for (size_t i0 = 0; i0 < n; i0 += N) {
    const size_t valid = std::min(N, n - i0);
    for (size_t l = 0; l < N; ++l) {
      const FastSample& x = samples[order[i0 + std::min(l, valid - 1)]];  // the tail repeats the last sample
      s.fx[l] = x.fx;
      s.fy[l] = x.fy;
      s.fz[l] = x.fz;
      s.vertex[l] = x.vertex;
      s.ray[l] = x.ray;
    }
    if (int8)
      EvalChunk<true>(d, N, fm, p, dir, ray_stride, delta, s, seconds);
    else
      EvalChunk<false>(d, N, fm, p, dir, ray_stride, delta, s, seconds);
    for (size_t l = 0; l < valid; ++l) {
      FastSampleOut& o = out[order[i0 + l]];
      o.alpha = s.out[l];
      o.trans = s.out[N + l];
      for (int c = 0; c < 3; ++c) o.rgb[c] = s.out[size_t(2 + c) * N + l];
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
  }
}

int64_t Target() { return HWY_TARGET; }

}  // namespace HWY_NAMESPACE
}  // namespace edrnr
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace edrnr {

HWY_EXPORT(EvalBatch);
HWY_EXPORT(EncodeDirections);
HWY_EXPORT(Target);

void fast_eval_batch(const FastModel& fm, uint32_t mlp, const FastSample* samples, const uint32_t* order, size_t n,
                     const float* dir, size_t ray_stride, float delta, FastSampleOut* out, FastKernelSeconds* seconds) {
  HWY_DYNAMIC_DISPATCH(EvalBatch)(fm, mlp, samples, order, n, dir, ray_stride, delta, out, seconds);
}

void fast_encode_directions(const FastModel& fm, const float* dx, const float* dy, const float* dz, size_t n,
                            float* out, size_t ray_stride) {
  HWY_DYNAMIC_DISPATCH(EncodeDirections)(fm, dx, dy, dz, n, out, ray_stride);
}

const char* fast_simd_target() { return hwy::TargetName(HWY_DYNAMIC_DISPATCH(Target)()); }

}  // namespace edrnr
#endif
