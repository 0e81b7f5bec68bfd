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
#include "render/fast_interp-inl.h"  // the chunk's scratch and the trilinear interpolation (per target)
// clang-format on

HWY_BEFORE_NAMESPACE();
namespace edrnr {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<float>;
using VF = hn::Vec<DF>;
using Clock = std::chrono::steady_clock;

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
  const hn::Vec<DT> raw = hn::Load(d, s.cin);
  if (kInt8) {
    const hn::Vec<DT> alpha = AlphaOfRaw(d, raw, delta);
    hn::Store(alpha, d, s.out);
    hn::Store(hn::Sub(hn::Set(d, 1.f), alpha), d, s.out + N);
    if (bytes)  // the colour net's first inputs, packed
      PackBytesScaled(d, N, s.cin, G, p[fm.geo_in], s.xq);
    else
      Requantize(d, N, s.cin, G, p + fm.geo_in, false, -128.f, 127.f);
  } else {
    const hn::Vec<DT> tau = OpticalDepth(d, raw, delta);
    hn::Store(AlphaOfDepth(d, tau), d, s.out);
    hn::Store(hn::Exp(d, hn::Neg(tau)), d, s.out + N);
  }
  // The direction inputs' part of the colour net is in dir_q.
  RunNet<kInt8>(d, N, fm.color, p, q, s.cin, s.a, s.b, s.rgb, D > 0 ? G : -1, s.dir_q + s.slot_base, s.slot, s.xq,
                s.xq2, bytes);
  for (int c = 0; c < 3; ++c) {
    const hn::Vec<DT> v = hn::Load(d, s.rgb + size_t(c) * N);
    hn::Store(kInt8 ? ColourOfRaw(d, v) : Sigmoid(d, v), d, s.out + size_t(2 + c) * N);
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
