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

using DF = hn::CappedTag<float, FastMarcher::State::kMaxChunk>;  // at most 16 candidates per test: a 32-bit mask
using DI = hn::RebindToSigned<DF>;
using DU = hn::RebindToUnsigned<DF>;

// Micro voxels per coarse voxel edge.
constexpr int kCvMicro = kMicroPerFine * kFinePerCoarse;

// Chunks start below this candidate index: k + lane fits int32 lanes, and
// float(k) of an int32 equals float(k) of the int64 (both round to nearest).
constexpr int64_t kVectorKLimit = int64_t(1) << 30;

// What the march reads of the model, the same for all marchers of a render.
struct Grid {
  const uint32_t* words;  // FastSkipGrid::fine_words
  const uint8_t* reach;   // FastSkipGrid::reach
  const int32_t* fine_to_block;
  const int32_t* coarse_to_mlp;
  int micro_res, fine_res, coarse_res;
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
// its micro voxel is occupied. The samples' lanes, points, voxels and fine
// voxels go to st.found_* in order (found_next reset to 0).
uint32_t TestCandidates(FastMarcher::State& st, const Grid& g, int64_t k, int count) {
  const DF df;
  const DI di;
  const DU du;
  const MicroRay& r = st.ray;
  st.found_next = 0;
  if (k + int64_t(hn::Lanes(df)) >= kVectorKLimit) {  // far along a ray: one candidate at a time
    uint32_t bits = 0;
    int n = 0;
    for (int i = 0; i < count; ++i) {
      Vec3i v;
      const Vec3f p = r.point(k + i);
      if (VoxelOf(p, g, v) && Occupied(v, g)) {
        bits |= uint32_t(1) << i;
        st.found_lane[n] = i;
        st.found_f[0][n] = p.x - float(v.x);
        st.found_f[1][n] = p.y - float(v.y);
        st.found_f[2][n] = p.z - float(v.z);
        st.found_v[0][n] = v.x;
        st.found_v[1][n] = v.y;
        st.found_v[2][n] = v.z;
        st.found_fine[n] = int32_t(FineIndex(v, g.fine_res));
        st.found_vertex[n] = (v.x & 3) + kBlockVertsPerAxis * ((v.y & 3) + kBlockVertsPerAxis * (v.z & 3));
        st.found_coarse[n] = int32_t(linear_index(v.x / kCvMicro, v.y / kCvMicro, v.z / kCvMicro, g.coarse_res));
        ++n;
      }
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
  if (bits == 0) return bits;
  // What the renderer's records take: the position in the micro voxel (the
  // scalar p - float(v)), the block vertex and the coarse voxel.
  const auto fx = hn::Sub(px, hn::ConvertTo(df, vx));
  const auto fy = hn::Sub(py, hn::ConvertTo(df, vy));
  const auto fz = hn::Sub(pz, hn::ConvertTo(df, vz));
  const auto five = hn::Set(di, kBlockVertsPerAxis);
  const auto vertex =
      hn::Add(hn::And(vx, three), hn::Mul(five, hn::Add(hn::And(vy, three), hn::Mul(five, hn::And(vz, three)))));
  static_assert(kCvMicro == 32, "coarse voxels of 32 micro voxels");
  const auto cr = hn::Set(di, g.coarse_res);
  const auto coarse =
      hn::Add(hn::ShiftRight<5>(vx), hn::Mul(cr, hn::Add(hn::ShiftRight<5>(vy), hn::Mul(cr, hn::ShiftRight<5>(vz)))));
  // The samples' lanes packed to the front, in order: one compress per
  // vector where AVX-512 has it as an instruction, lane by lane elsewhere
  // (other targets emulate it at far greater cost).
#if HWY_TARGET == HWY_AVX3 || HWY_TARGET == HWY_AVX3_DL
  {
    const auto m = hn::RebindMask(di, samples);
    const auto mf = hn::RebindMask(df, samples);
    hn::StoreU(hn::Compress(lane, m), di, st.found_lane);
    hn::StoreU(hn::Compress(fx, mf), df, st.found_f[0]);
    hn::StoreU(hn::Compress(fy, mf), df, st.found_f[1]);
    hn::StoreU(hn::Compress(fz, mf), df, st.found_f[2]);
    hn::StoreU(hn::Compress(vx, m), di, st.found_v[0]);
    hn::StoreU(hn::Compress(vy, m), di, st.found_v[1]);
    hn::StoreU(hn::Compress(vz, m), di, st.found_v[2]);
    hn::StoreU(hn::Compress(fine, m), di, st.found_fine);
    hn::StoreU(hn::Compress(vertex, m), di, st.found_vertex);
    hn::StoreU(hn::Compress(coarse, m), di, st.found_coarse);
  }
#else
  {
    constexpr int kM = FastMarcher::State::kMaxChunk;
    alignas(64) float lf[3][kM];
    alignas(64) int32_t lv[6][kM];
    hn::Store(fx, df, lf[0]);
    hn::Store(fy, df, lf[1]);
    hn::Store(fz, df, lf[2]);
    hn::Store(vx, di, lv[0]);
    hn::Store(vy, di, lv[1]);
    hn::Store(vz, di, lv[2]);
    hn::Store(fine, di, lv[3]);
    hn::Store(vertex, di, lv[4]);
    hn::Store(coarse, di, lv[5]);
    int n = 0;
    for (uint32_t b = bits; b != 0; b &= b - 1, ++n) {
      const int i = std::countr_zero(b);
      st.found_lane[n] = i;
      for (int a = 0; a < 3; ++a) {
        st.found_f[a][n] = lf[a][i];
        st.found_v[a][n] = lv[a][i];
      }
      st.found_fine[n] = lv[3][i];
      st.found_vertex[n] = lv[4][i];
      st.found_coarse[n] = lv[5][i];
    }
  }
#endif
  return bits;
}

// The box skip_box jumps from micro voxel v, whose fine voxel has reach e:
// the fine voxel's micro voxels widened by e.
HWY_INLINE Vec3i ReachLo(const Vec3i& v, int e) {
  return Vec3i{4 * (v.x >> 2) - e, 4 * (v.y >> 2) - e, 4 * (v.z >> 2) - e};
}

// Where a marcher's samples go: MarchSamples and their blocks, or the
// renderer's records (with the ray's index) and the count of samples that
// have no MLP or block.
struct Out {
  MarchSample* samples = nullptr;
  int32_t* blocks = nullptr;
  FastSample* records = nullptr;
  uint32_t ray = 0;
  int written = 0;  // records written
  uint64_t* missing = nullptr;
};

// Hands out up to `room` of a marcher's pending samples, in order; returns
// how many.
template <bool kRecords>
HWY_INLINE int Emit(FastMarcher::State& st, const Grid& g, Out& out, int room) {
  int n = 0;
  while (st.pending != 0 && n < room) {
    st.pending &= st.pending - 1;
    const int j = st.found_next++;
    ++n;
    st.block = g.fine_to_block[st.found_fine[j]];
    const Vec3i v{st.found_v[0][j], st.found_v[1][j], st.found_v[2][j]};
    if (kRecords) {
      const int32_t mlp = g.coarse_to_mlp[st.found_coarse[j]];
      if (mlp < 0 || st.block < 0) {
        ++*out.missing;
        continue;
      }
      FastSample& r = out.records[out.written++];
      r.ray = out.ray;
      r.mlp = uint32_t(mlp);
      r.vertex = uint32_t(size_t(st.block) * kBlockVerts + size_t(st.found_vertex[j]));
      r.fx = st.found_f[0][j];
      r.fy = st.found_f[1][j];
      r.fz = st.found_f[2][j];
    } else {
      MarchSample& s = out.samples[out.written];
      s.k = st.chunk_k + st.found_lane[j];
      // v + (p - v) is p: the difference of a float in [v, v + 1] and v >= 0 is exact.
      s.p_micro = Vec3f{float(v.x) + st.found_f[0][j], float(v.y) + st.found_f[1][j], float(v.z) + st.found_f[2][j]};
      s.voxel = v;
      out.blocks[out.written++] = st.block;
    }
  }
  return n;
}

// Tests the vector of candidates from st.k on (st.k <= st.k_end): they
// become the pending samples, and the next chunk is tested at once if any
// of them is a sample.
HWY_INLINE void TestChunk(FastMarcher::State& st, const Grid& g) {
  const int64_t k = st.k;
  const int count = int(std::min<int64_t>(int64_t(hn::Lanes(DF())), st.k_end - k + 1));
  st.pending = TestCandidates(st, g, k, count);
  st.dense = st.pending != 0;
  st.chunk_k = k;
  st.k = k + count;
  st.checks += uint64_t(count);
}

// One unit of a marcher's work when nothing is pending: skip an empty cube of
// fine voxels, or test the next vector of candidates. False once the march
// has ended.
HWY_INLINE bool Advance(FastMarcher::State& st, const Grid& g) {
  if (st.k > st.k_end) return false;
  const int64_t k = st.k;
  if (st.dense) {  // near occupied micro voxels: the next chunk is likely to hold samples too
    TestChunk(st, g);
    return true;
  }
  Vec3i v;
  if (!VoxelOf(st.ray.point(k), g, v)) {
    st.k = k + 1;
    return true;
  }
  ++st.checks;
  const int e = g.reach[FineIndex(v, g.fine_res)];
  if (e >= kFastJumpReach) {  // the fine voxel widened by e micro voxels is empty
    st.k = st.skip_box(k, ReachLo(v, e), 4 + 2 * e);
    return true;
  }
  TestChunk(st, g);
  return true;
}

// The march of fast_march_group (out[i].samples, blocks) or fast_march_records
// (out[i].records); counts[i]: the samples (records) written.
template <bool kRecords>
void MarchOut(FastMarcher* const* marchers, int n, int limit, Out* out, int* counts, bool* ended) {
  if (n <= 0) return;
  const FastMarcher::State& s0 = marchers[0]->state();
  Grid g;
  g.words = s0.skip->fine_words.data();
  g.reach = s0.skip->reach.data();
  g.fine_to_block = s0.model->fine_to_block.data();
  g.coarse_to_mlp = s0.model->coarse_to_mlp.data();
  g.micro_res = s0.model->micro_res;
  g.fine_res = s0.skip->res;
  g.coarse_res = s0.model->coarse_res();
  g.hi = float(g.micro_res);
  // The marchers' iterations interleaved: their dependency chains (point,
  // voxel, lookup, jump) are independent, so the CPU overlaps them.
  int active = 0;
  bool done[kFastMarchGroup];
  int handed[kFastMarchGroup];  // samples handed out (records written, or left out as missing)
  for (int i = 0; i < n; ++i) {
    handed[i] = 0;
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
      handed[i] += Emit<kRecords>(st, g, out[i], limit - handed[i]);
      if (handed[i] == limit) {
        done[i] = true;
        ended[i] = st.pending == 0 && st.k > st.k_end;
        --active;
      }
    }
  }
  for (int i = 0; i < n; ++i) counts[i] = out[i].written;
}

void MarchGroup(FastMarcher* const* marchers, int n, int limit, MarchSample* samples, int32_t* blocks, int* counts,
                bool* ended) {
  Out out[kFastMarchGroup];
  for (int i = 0; i < n; ++i) {
    out[i].samples = samples + size_t(i) * size_t(limit);
    out[i].blocks = blocks + size_t(i) * size_t(limit);
  }
  MarchOut<false>(marchers, n, limit, out, counts, ended);
}

void MarchRecords(FastMarcher* const* marchers, const uint32_t* rays, int n, int limit, FastSample* records,
                  int* counts, bool* ended, uint64_t* missing) {
  Out out[kFastMarchGroup];
  for (int i = 0; i < n; ++i) {
    out[i].records = records + size_t(i) * size_t(limit);
    out[i].ray = rays[i];
    out[i].missing = missing;
  }
  MarchOut<true>(marchers, n, limit, out, counts, ended);
}

// std::max and std::min of doubles, lane by lane with their exact semantics
// (the first operand unless the comparison says otherwise).
template <class V>
HWY_INLINE V StdMax(V a, V b) {
  return hn::IfThenElse(hn::Lt(a, b), b, a);
}
template <class V>
HWY_INLINE V StdMin(V a, V b) {
  return hn::IfThenElse(hn::Lt(b, a), b, a);
}

// What SetupRays does in lanes after the set-up, for one marcher: the
// march's steps (Advance) up to a candidate whose reach is below kFastJumpReach,
// whose vector test is then left to the march without a second lookup
// (dense).
void Approach(FastMarcher::State& st, const Grid& g) {
  while (st.k <= st.k_end) {
    Vec3i v;
    if (!VoxelOf(st.ray.point(st.k), g, v)) {
      ++st.k;
      continue;
    }
    const int e = g.reach[FineIndex(v, g.fine_res)];
    ++st.checks;
    if (e < kFastJumpReach) {
      st.dense = true;
      return;
    }
    st.k = st.skip_box(st.k, ReachLo(v, e), 4 + 2 * e);
  }
}

// A mask of 32-bit lanes as the mask of the 64-bit lanes of the same count.
template <class DD, class DI32, class M>
HWY_INLINE auto WidenMask(DD dd, DI32 di32, M m) {
  const hn::RebindToSigned<DD> di64;
  return hn::MaskFromVec(hn::BitCast(dd, hn::PromoteTo(di64, hn::VecFromMask(di32, m))));
}

void SetupRays(const SceneModel& model, const FastSkipGrid& skip, const Camera& cam, float delta, const Box3d& aabb,
               int x0, int y0, int tw, int n, FastMarcher* marchers, float* dx, float* dy, float* dz, bool* hit_aabb) {
  using DD = hn::ScalableTag<double>;
  using VD = hn::Vec<DD>;
  const DD dd;
  const hn::Rebind<float, DD> dfh;
  const hn::Rebind<int32_t, DD> di32;
  using VF = hn::Vec<decltype(dfh)>;
  using VI = hn::Vec<decltype(di32)>;
  const int32_t* reach = reinterpret_cast<const int32_t*>(skip.reach.data());  // 32-bit reads at byte offsets
  const float grid_hi = float(model.micro_res);
  Grid grid;
  grid.words = skip.fine_words.data();
  grid.reach = skip.reach.data();
  grid.fine_to_block = model.fine_to_block.data();
  grid.coarse_to_mlp = model.coarse_to_mlp.data();
  grid.micro_res = model.micro_res;
  grid.fine_res = skip.res;
  grid.coarse_res = model.coarse_res();
  grid.hi = grid_hi;
  constexpr size_t kMax = HWY_MAX_BYTES / sizeof(double);
  const size_t L = hn::Lanes(dd);
  // Per camera and model: the ray origin, its micro-unit form and the
  // micro scale (make_micro_ray's operations), the boxes relative to it.
  const Vec3d o = cam.origin();
  const MicroRay m0 = make_micro_ray(model, Ray{o, Vec3d{0, 0, 1}}, delta);
  const Vec3d size = model.scene_box.size().cast<double>();
  const double R = double(model.micro_res);
  const double mscale[3] = {R / size.x, R / size.y, R / size.z};
  const double ddelta = double(delta);
  double rlo[3], rhi[3], alo[3], ahi[3];
  for (int a = 0; a < 3; ++a) {
    rlo[a] = skip.region.lo[a] - o[a];
    rhi[a] = skip.region.hi[a] - o[a];
    alo[a] = aabb.lo[a] - o[a];
    ahi[a] = aabb.hi[a] - o[a];
  }
  const VD one = hn::Set(dd, 1.0), zero = hn::Zero(dd);
  const VD c2w_z[3] = {hn::Set(dd, cam.c2w[2] * -1.0), hn::Set(dd, cam.c2w[6] * -1.0), hn::Set(dd, cam.c2w[10] * -1.0)};
  const VD half = hn::Set(dd, 0.5), vdelta = hn::Set(dd, ddelta);
  double om[3];  // the micro origin as doubles
  for (int a = 0; a < 3; ++a) om[a] = double(m0.origin[a]);
  alignas(64) double u[kMax], v[kMax], dir[3][kMax], exit[3][kMax], scale[3][kMax], offset[3][kMax], kk[3][kMax];
  alignas(64) double aabb_far[kMax], flags[5][kMax];
  alignas(64) float dm[3][kMax];
  for (int r0 = 0; r0 < n; r0 += int(L)) {
    for (size_t l = 0; l < L; ++l) {
      const int r = std::min(r0 + int(l), n - 1);
      u[l] = double(x0 + r % tw) + 0.5;
      v[l] = double(y0 + r / tw) + 0.5;
    }
    // Camera::ray_at: the camera-space direction, rotated, normalized.
    const VD cx = hn::Div(hn::Sub(hn::Load(dd, u), hn::Set(dd, cam.cx)), hn::Set(dd, cam.fx));
    const VD cy = hn::Div(hn::Neg(hn::Sub(hn::Load(dd, v), hn::Set(dd, cam.cy))), hn::Set(dd, cam.fy));
    VD d[3];
    for (int a = 0; a < 3; ++a)
      d[a] = hn::Add(hn::Add(hn::Mul(hn::Set(dd, cam.c2w[4 * a]), cx), hn::Mul(hn::Set(dd, cam.c2w[4 * a + 1]), cy)),
                     c2w_z[a]);
    const VD len = hn::Sqrt(hn::Add(hn::Add(hn::Mul(d[0], d[0]), hn::Mul(d[1], d[1])), hn::Mul(d[2], d[2])));
    // Lanes that set_up handles: a zero or tiny component (intersect_box's
    // special case, or a micro component that rounds to 0).
    auto special = hn::FirstN(dd, 0);
    VD tn = hn::Set(dd, -INFINITY), tf = hn::Set(dd, INFINITY);
    VD an = tn, af = tf;
    VD dmd[3];
    VF fdir[3];
    for (int a = 0; a < 3; ++a) {
      d[a] = hn::Div(d[a], len);
      hn::Store(d[a], dd, dir[a]);
      // make_micro_ray: the direction in micro units, rounded to float.
      const auto f = hn::DemoteTo(dfh, hn::Mul(d[a], hn::Set(dd, mscale[a])));
      hn::Store(f, dfh, dm[a]);
      fdir[a] = f;
      dmd[a] = hn::PromoteTo(dd, f);
      special = hn::Or(special, hn::Or(hn::Lt(hn::Abs(d[a]), hn::Set(dd, 0x1p-500)), hn::Eq(dmd[a], zero)));
      // intersect_box with the region and with the AABB.
      const VD ia = hn::Div(one, d[a]);
      VD t0 = hn::Mul(hn::Set(dd, rlo[a]), ia), t1 = hn::Mul(hn::Set(dd, rhi[a]), ia);
      auto swap = hn::Gt(t0, t1);
      tn = StdMax(tn, hn::IfThenElse(swap, t1, t0));
      tf = StdMin(tf, hn::IfThenElse(swap, t0, t1));
      t0 = hn::Mul(hn::Set(dd, alo[a]), ia);
      t1 = hn::Mul(hn::Set(dd, ahi[a]), ia);
      swap = hn::Gt(t0, t1);
      an = StdMax(an, hn::IfThenElse(swap, t1, t0));
      af = StdMin(af, hn::IfThenElse(swap, t0, t1));
    }
    // FastMarcher::set_up from its box test on, for lanes whose candidate
    // indices stay below 2^51 (where floor and ceil in doubles equal the
    // int64 arithmetic there); the others take set_up.
    const auto valid = hn::And(hn::And(hn::Le(tn, tf), hn::Ge(tf, zero)), hn::And(hn::IsFinite(tf), hn::IsFinite(tn)));
    const VD first = StdMin(hn::Sub(hn::Div(StdMax(tn, zero), vdelta), half), hn::Set(dd, 4e18));
    const VD last = StdMin(hn::Sub(hn::Div(tf, vdelta), half), hn::Set(dd, 4e18));
    special = hn::Or(special, hn::AndNot(hn::Lt(last, hn::Set(dd, 0x1p51)), valid));
    const VD k = StdMax(zero, hn::Sub(hn::Floor(first), one));
    const VD k_end = hn::Add(hn::Ceil(last), one);
    const VD t_max = hn::Mul(hn::Add(k_end, hn::Set(dd, 1.5)), vdelta);
    VD max_coord = hn::Set(dd, R);
    for (int a = 0; a < 3; ++a)
      max_coord = StdMax(max_coord, hn::Add(hn::Set(dd, std::abs(om[a])), hn::Mul(hn::Abs(dmd[a]), t_max)));
    const VD margin = hn::Mul(max_coord, hn::Set(dd, 1.0 / 524288.0));
    VD ex_v[3], sc_v[3], of_v[3];
    for (int a = 0; a < 3; ++a) {
      const auto up = hn::Gt(dmd[a], zero);
      sc_v[a] = hn::Div(one, hn::Mul(dmd[a], vdelta));
      ex_v[a] = hn::IfThenElseZero(up, one);
      const VD m = hn::IfThenElse(up, hn::Neg(margin), margin);
      of_v[a] = hn::Sub(hn::Mul(hn::Sub(m, hn::Set(dd, om[a])), sc_v[a]), half);
      hn::Store(ex_v[a], dd, exit[a]);
      hn::Store(sc_v[a], dd, scale[a]);
      hn::Store(of_v[a], dd, offset[a]);
    }
    // The march's first steps, in the lanes (Advance): from a fine voxel
    // whose reach is kFastJumpReach or more a jump past the empty box around it
    // (FastMarcher::State::skip_box), past a candidate outside the grid one
    // step, until a candidate with a shorter reach or the end. That
    // candidate's vector test is left to the march, marked dense so that it
    // does not look the reach up again.
    VD kv = k, checks = zero;
    auto dense = hn::FirstN(dd, 0);
    // Whether the march has candidates, before the steps (the AABB count's condition).
    const auto has_candidates = hn::And(valid, hn::Le(k, k_end));
    auto active = hn::AndNot(special, has_candidates);
    while (!hn::AllFalse(dd, active)) {
      const VF kf = hn::DemoteTo(dfh, kv);  // kv is an integer below 2^51: float(int64) rounds the same
      const VF t = hn::Mul(hn::Add(kf, hn::Set(dfh, 0.5f)), hn::Set(dfh, delta));
      VI vox[3];
      auto inside_f = hn::FirstN(dfh, hn::Lanes(dfh));
      for (int a = 0; a < 3; ++a) {
        const VF p = hn::Add(hn::Set(dfh, m0.origin[a]), hn::Mul(fdir[a], t));
        inside_f = hn::And(inside_f, hn::And(hn::Ge(p, hn::Zero(dfh)), hn::Le(p, hn::Set(dfh, grid_hi))));
        vox[a] = hn::Min(hn::ConvertTo(di32, p), hn::Set(di32, model.micro_res - 1));
      }
      const auto inside_i = hn::RebindMask(di32, inside_f);
      const VI fr = hn::Set(di32, skip.res);
      const VI fine = hn::Add(hn::ShiftRight<2>(vox[0]),
                              hn::Mul(fr, hn::Add(hn::ShiftRight<2>(vox[1]), hn::Mul(fr, hn::ShiftRight<2>(vox[2])))));
      const VI e = hn::And(hn::GatherOffset(di32, reach, hn::IfThenElseZero(inside_i, fine)), hn::Set(di32, 0xFF));
      const auto far_i = hn::And(inside_i, hn::Gt(e, hn::Set(di32, kFastJumpReach - 1)));
      // skip_box(k, lo, size): lo = 4 (v >> 2) - e per axis, size = 4 + 2 e.
      const VD size_d = hn::PromoteTo(dd, hn::Add(hn::Add(e, e), hn::Set(di32, 4)));
      VD xs[3];
      for (int a = 0; a < 3; ++a) {
        const VI lo = hn::Sub(hn::ShiftLeft<2>(hn::ShiftRight<2>(vox[a])), e);
        xs[a] = hn::Add(hn::Mul(hn::Add(hn::PromoteTo(dd, lo), hn::Mul(size_d, ex_v[a])), sc_v[a]), of_v[a]);
      }
      const VD xm = StdMin(xs[0], StdMin(xs[1], xs[2]));
      const VD floor_x = hn::Floor(StdMax(xm, hn::Set(dd, -4e18)));
      const VD jump =
          hn::IfThenElse(hn::Lt(xm, k_end), StdMax(hn::Add(kv, one), hn::Add(floor_x, one)), hn::Add(k_end, one));
      const auto inside = WidenMask(dd, di32, inside_i);
      const auto far = hn::And(active, WidenMask(dd, di32, far_i));
      const auto outside = hn::AndNot(inside, active);
      kv = hn::IfThenElse(far, jump, hn::IfThenElse(outside, hn::Add(kv, one), kv));
      const auto stop = hn::AndNot(far, hn::And(active, inside));
      checks = hn::Add(checks, hn::IfThenElseZero(hn::Or(far, stop), one));
      dense = hn::Or(dense, stop);
      active = hn::And(hn::Or(far, outside), hn::Le(kv, k_end));
    }
    hn::Store(checks, dd, kk[2]);
    hn::Store(hn::IfThenElseZero(dense, one), dd, flags[4]);
    hn::Store(kv, dd, kk[0]);
    hn::Store(k_end, dd, kk[1]);
    hn::Store(af, dd, aabb_far);
    hn::Store(hn::IfThenElseZero(valid, one), dd, flags[0]);
    hn::Store(hn::IfThenElseZero(has_candidates, one), dd, flags[3]);
    hn::Store(hn::IfThenElseZero(hn::Le(an, af), one), dd, flags[1]);
    hn::Store(hn::IfThenElseZero(special, one), dd, flags[2]);
    const int valid_lanes = std::min(int(L), n - r0);
    for (int l = 0; l < valid_lanes; ++l) {
      const int r = r0 + l;
      FastMarcher& fm = marchers[r];
      if (flags[2][l] != 0) {
        const Ray ray = cam.pixel_ray(x0 + r % tw, y0 + r / tw);
        fm.set_up(model, skip, ray, make_micro_ray(model, ray, delta));
        const bool had_candidates = !fm.empty();
        Approach(fm.state(), grid);
        dx[r] = float(ray.dir.x);
        dy[r] = float(ray.dir.y);
        dz[r] = float(ray.dir.z);
        double t_near, t_far;
        hit_aabb[r] = had_candidates && intersect_box(ray.origin, ray.dir, aabb, t_near, t_far) && t_far >= 0;
        continue;
      }
      MicroRay mr = m0;
      mr.dir = Vec3f{dm[0][l], dm[1][l], dm[2][l]};
      if (flags[0][l] != 0) {
        const double e[3] = {exit[0][l], exit[1][l], exit[2][l]};
        const double sc[3] = {scale[0][l], scale[1][l], scale[2][l]};
        const double of[3] = {offset[0][l], offset[1][l], offset[2][l]};
        fm.assign(model, skip, mr, int64_t(kk[0][l]), int64_t(kk[1][l]), e, sc, of);
        fm.state().checks = uint64_t(kk[2][l]);
        fm.state().dense = flags[4][l] != 0;
      } else {
        const double z[3] = {0, 0, 0};
        fm.assign(model, skip, mr, 0, -1, z, z, z);
      }
      dx[r] = float(dir[0][l]);
      dy[r] = float(dir[1][l]);
      dz[r] = float(dir[2][l]);
      hit_aabb[r] = flags[3][l] != 0 && flags[1][l] != 0 && aabb_far[l] >= 0;
    }
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace edrnr
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace edrnr {

HWY_EXPORT(MarchGroup);
HWY_EXPORT(MarchRecords);
HWY_EXPORT(SetupRays);

void fast_setup_rays(const SceneModel& model, const FastSkipGrid& skip, const Camera& camera, float delta,
                     const Box3d& aabb, int x0, int y0, int tw, int n, FastMarcher* marchers, float* dx, float* dy,
                     float* dz, bool* hit_aabb) {
  HWY_DYNAMIC_DISPATCH(SetupRays)(model, skip, camera, delta, aabb, x0, y0, tw, n, marchers, dx, dy, dz, hit_aabb);
}

void fast_march_group(FastMarcher* const* marchers, int n, int limit, MarchSample* samples, int32_t* blocks,
                      int* counts, bool* ended) {
  HWY_DYNAMIC_DISPATCH(MarchGroup)(marchers, n, limit, samples, blocks, counts, ended);
}

void fast_march_records(FastMarcher* const* marchers, const uint32_t* rays, int n, int limit, FastSample* records,
                        int* counts, bool* ended, uint64_t* missing) {
  HWY_DYNAMIC_DISPATCH(MarchRecords)(marchers, rays, n, limit, records, counts, ended, missing);
}

}  // namespace edrnr
#endif
