// Highway kernel of the fast renderer's march (render/fast_march.h); compiled
// once per SIMD target (hwy/foreach_target.h) and picked at run time
// (HWY_DYNAMIC_DISPATCH).
#include <algorithm>
#include <bit>
#include <cstring>

#include "render/fast_march.h"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/fast_march_kernels.cpp"
// clang-format off
#include <hwy/foreach_target.h>  // before highway.h
#include <hwy/highway.h>
// clang-format on

HWY_BEFORE_NAMESPACE();
namespace edrnr {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::CappedTag<float, 16>;  // at most 16 candidates per test: the lanes fit a 32-bit mask
using DI = hn::RebindToSigned<DF>;
using DU = hn::RebindToUnsigned<DF>;

// Chunks start below this candidate index: k + lane fits int32 lanes, and
// float(k) of an int32 equals float(k) of the int64 (both round to nearest).
constexpr int64_t kVectorKLimit = int64_t(1) << 30;

// What the march reads of the model, the same for all marchers of a render.
struct Grid {
  const uint32_t* words;  // FastSkipGrid::fine_words
  const uint8_t* distance;
  const int32_t* fine_to_block;
  int micro_res, fine_res;
  float hi;  // micro_res as a float: the largest coordinate inside the grid
};

// micro_voxel_of (model/mlp.h) without a floor call: for the non-negative
// coordinates it accepts, truncation is floor.
HWY_INLINE bool VoxelOf(const Vec3f& p, const Grid& g, Vec3i& v) {
  if (!(p.x >= 0.f && p.x <= g.hi && p.y >= 0.f && p.y <= g.hi && p.z >= 0.f && p.z <= g.hi)) return false;
  v.x = std::min(int(p.x), g.micro_res - 1);
  v.y = std::min(int(p.y), g.micro_res - 1);
  v.z = std::min(int(p.z), g.micro_res - 1);
  return true;
}

HWY_INLINE size_t FineIndex(const Vec3i& v, int fine_res) {
  return size_t(v.x >> 2) + size_t(fine_res) * (size_t(v.y >> 2) + size_t(fine_res) * size_t(v.z >> 2));
}

// Whether micro voxel v is occupied, from the fine voxels' masks.
HWY_INLINE bool Occupied(const Vec3i& v, const Grid& g) {
  const size_t word = 2 * FineIndex(v, g.fine_res) + size_t((v.z >> 1) & 1);
  const int bit = (v.x & 3) + 4 * (v.y & 3) + 16 * (v.z & 1);
  return (g.words[word] >> bit) & 1u;
}

// Bit i set iff candidate k + i (i < count <= Lanes) is a sample: its point
// p_k (the reference's float operations, lane by lane) lies in the grid and
// its micro voxel is occupied.
uint32_t TestCandidates(const FastMarcher::State& st, const Grid& g, int64_t k, int count) {
  const DF df;
  const DI di;
  const DU du;
  const MicroRay& r = st.ray;
  if (k + int64_t(hn::Lanes(df)) >= kVectorKLimit) {  // far along a ray: one candidate at a time
    uint32_t bits = 0;
    for (int i = 0; i < count; ++i) {
      Vec3i v;
      if (VoxelOf(r.point(k + i), g, v) && Occupied(v, g)) bits |= uint32_t(1) << i;
    }
    return bits;
  }
  const auto lane = hn::Iota(di, 0);
  const auto t = hn::Mul(hn::Add(hn::ConvertTo(df, hn::Add(lane, hn::Set(di, int32_t(k)))), hn::Set(df, 0.5f)),
                         hn::Set(df, r.delta));
  // o + d t, a multiply then an add (no contraction: -ffp-contract=off), as MicroRay::point.
  const auto px = hn::Add(hn::Set(df, r.origin.x), hn::Mul(hn::Set(df, r.dir.x), t));
  const auto py = hn::Add(hn::Set(df, r.origin.y), hn::Mul(hn::Set(df, r.dir.y), t));
  const auto pz = hn::Add(hn::Set(df, r.origin.z), hn::Mul(hn::Set(df, r.dir.z), t));
  const auto zero = hn::Zero(df), hi = hn::Set(df, g.hi);
  const auto inside_f =
      hn::And(hn::And(hn::And(hn::Ge(px, zero), hn::Le(px, hi)), hn::And(hn::Ge(py, zero), hn::Le(py, hi))),
              hn::And(hn::Ge(pz, zero), hn::Le(pz, hi)));
  const auto inside = hn::And(hn::RebindMask(di, inside_f), hn::Lt(lane, hn::Set(di, count)));
  const auto top = hn::Set(di, g.micro_res - 1);
  const auto vx = hn::Min(hn::ConvertTo(di, px), top);
  const auto vy = hn::Min(hn::ConvertTo(di, py), top);
  const auto vz = hn::Min(hn::ConvertTo(di, pz), top);
  const auto fr = hn::Set(di, g.fine_res);
  const auto fine =
      hn::Add(hn::ShiftRight<2>(vx), hn::Mul(fr, hn::Add(hn::ShiftRight<2>(vy), hn::Mul(fr, hn::ShiftRight<2>(vz)))));
  const auto one = hn::Set(di, 1), three = hn::Set(di, 3);
  const auto word = hn::IfThenElseZero(inside, hn::Add(hn::Add(fine, fine), hn::And(hn::ShiftRight<1>(vz), one)));
  const auto bit =
      hn::Add(hn::Add(hn::And(vx, three), hn::ShiftLeft<2>(hn::And(vy, three))), hn::ShiftLeft<4>(hn::And(vz, one)));
  const auto w = hn::GatherIndex(du, g.words, word);
  const auto hit = hn::Ne(hn::And(hn::Shr(w, hn::BitCast(du, bit)), hn::Set(du, 1u)), hn::Zero(du));
  const auto samples = hn::And(hn::RebindMask(du, inside), hit);
  uint8_t bytes[8] = {0};
  hn::StoreMaskBits(du, samples, bytes);
  uint32_t bits;
  std::memcpy(&bits, bytes, sizeof(bits));
  return bits;
}

// Fine voxels at this distance or nearer to an occupied one are not jumped
// past: the candidates from there on are tested a vector at a time (a jump
// from them would pass a fine voxel or two, about as many candidates).
constexpr int kChunkBelow = 2;

// Hands out up to `room` of a marcher's pending samples, in order; returns
// how many.
HWY_INLINE int Emit(FastMarcher::State& st, const Grid& g, MarchSample* out, int32_t* blocks, int room) {
  int n = 0;
  while (st.pending != 0 && n < room) {
    const int i = std::countr_zero(st.pending);
    st.pending &= st.pending - 1;
    MarchSample& s = out[n];
    s.k = st.chunk_k + i;
    s.p_micro = st.ray.point(s.k);
    VoxelOf(s.p_micro, g, s.voxel);  // inside: TestCandidates found it occupied
    st.block = g.fine_to_block[FineIndex(s.voxel, g.fine_res)];
    blocks[n++] = st.block;
  }
  return n;
}

// One unit of a marcher's work when nothing is pending: skip an empty cube of
// fine voxels, or test the next vector of candidates. False once the march
// has ended.
HWY_INLINE bool Advance(FastMarcher::State& st, const Grid& g) {
  if (st.k > st.k_end) return false;
  const int64_t k = st.k;
  Vec3i v;
  if (!VoxelOf(st.ray.point(k), g, v)) {
    st.k = k + 1;
    return true;
  }
  ++st.checks;
  const int r = g.distance[FineIndex(v, g.fine_res)];
  if (r > kChunkBelow) {  // the cube of fine voxels within r - 1 is empty
    const Vec3i lo{4 * ((v.x >> 2) - r + 1), 4 * ((v.y >> 2) - r + 1), 4 * ((v.z >> 2) - r + 1)};
    st.k = st.skip_box(k, lo, 4 * (2 * r - 1));
    return true;
  }
  const int count = int(std::min<int64_t>(int64_t(hn::Lanes(DF())), st.k_end - k + 1));
  st.pending = TestCandidates(st, g, k, count);
  st.chunk_k = k;
  st.k = k + count;
  st.checks += uint64_t(count);
  return true;
}

void MarchGroup(FastMarcher* const* marchers, int n, int limit, MarchSample* samples, int32_t* blocks, int* counts,
                bool* ended) {
  if (n <= 0) return;
  const FastMarcher::State& s0 = marchers[0]->state();
  Grid g;
  g.words = s0.skip->fine_words.data();
  g.distance = s0.skip->distance.data();
  g.fine_to_block = s0.model->fine_to_block.data();
  g.micro_res = s0.model->micro_res;
  g.fine_res = s0.skip->res;
  g.hi = float(g.micro_res);
  // The marchers' iterations interleaved: their dependency chains (point,
  // voxel, lookup, jump) are independent, so the CPU overlaps them.
  int active = 0;
  bool done[kFastMarchGroup];
  for (int i = 0; i < n; ++i) {
    counts[i] = 0;
    ended[i] = false;
    done[i] = limit <= 0;
    active += !done[i];
  }
  while (active > 0) {
    for (int i = 0; i < n; ++i) {
      if (done[i]) continue;
      FastMarcher::State& st = marchers[i]->state();
      if (st.pending == 0 && !Advance(st, g)) {
        ended[i] = done[i] = true;
        --active;
        continue;
      }
      if (st.pending == 0) continue;
      const size_t at = size_t(i) * size_t(limit) + size_t(counts[i]);
      counts[i] += Emit(st, g, samples + at, blocks + at, limit - counts[i]);
      if (counts[i] == limit) {
        done[i] = true;
        ended[i] = st.pending == 0 && st.k > st.k_end;
        --active;
      }
    }
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace edrnr
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace edrnr {

HWY_EXPORT(MarchGroup);

void fast_march_group(FastMarcher* const* marchers, int n, int limit, MarchSample* samples, int32_t* blocks,
                      int* counts, bool* ended) {
  HWY_DYNAMIC_DISPATCH(MarchGroup)(marchers, n, limit, samples, blocks, counts, ended);
}

}  // namespace edrnr
#endif
