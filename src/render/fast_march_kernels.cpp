// Highway kernel of the fast renderer's march (render/fast_march.h; the ray
// set-up's is in fast_setup_kernels.cpp); compiled once per SIMD target
// (hwy/foreach_target.h) and picked at run time (HWY_DYNAMIC_DISPATCH).
#include <algorithm>
#include <array>
#include <bit>
#include <cstring>

#include "render/fast_march.h"
#include "render/fast_march_grid.h"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/fast_march_kernels.cpp"
// clang-format off
#include <hwy/foreach_target.h>  // before highway.h
#include <hwy/highway.h>
#include "render/fast_convert-inl.h"  // ToInt32 (per target)
// clang-format on

HWY_BEFORE_NAMESPACE();
namespace edrnr {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;
using fast_march_detail::FineIndex;
using fast_march_detail::Grid;
using fast_march_detail::ReachLo;
using fast_march_detail::VoxelOf;

using DF = hn::CappedTag<float, FastMarcher::State::kMaxChunk>;  // at most 16 candidates per test: a 32-bit mask
using DI = hn::RebindToSigned<DF>;
using DU = hn::RebindToUnsigned<DF>;

constexpr int kCell = FastSkipGrid::kCellWords;

// Chunks start below this candidate index: k + lane fits int32 lanes, and
// float(k) of an int32 equals float(k) of the int64 (both round to nearest).
constexpr int64_t kVectorKLimit = int64_t(1) << 30;

// Whether micro voxel v is occupied, from the fine voxels' masks.
HWY_INLINE bool Occupied(const Vec3i& v, const Grid& g) {
  const size_t word = kCell * FineIndex(v, g.fine_res) + size_t((v.z >> 1) & 1);
  const int bit = (v.x & 3) + 4 * (v.y & 3) + 16 * (v.z & 1);
  return (g.words[word] >> bit) & 1u;
}

#if HWY_TARGET == HWY_AVX2
// For each 8-bit mask, the indices of its set bits in order, 4 bits each
// (lane i's source in nibble i): a compress of 8 lanes as one permutation.
constexpr std::array<uint32_t, 256> CompressTable() {
  std::array<uint32_t, 256> t{};
  for (uint32_t m = 0; m < 256; ++m) {
    int n = 0;
    for (uint32_t i = 0; i < 8; ++i)
      if ((m >> i) & 1) t[m] |= i << (4 * n++);
  }
  return t;
}
constexpr std::array<uint32_t, 256> kCompressTable = CompressTable();
#endif

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
        st.found_f[0][n] = p.x - float(v.x);
        st.found_f[1][n] = p.y - float(v.y);
        st.found_f[2][n] = p.z - float(v.z);
        st.found_fine[n] = int32_t(FineIndex(v, g.fine_res));
        st.found_vertex[n] = (v.x & 3) + kBlockVertsPerAxis * ((v.y & 3) + kBlockVertsPerAxis * (v.z & 3));
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
  // Truncated without Highway's fix-up of out-of-range lanes: the lanes
  // that matter lie in the grid, the others are masked below.
  const auto vx = hn::Min(ToInt32<true>(di, px), top);
  const auto vy = hn::Min(ToInt32<true>(di, py), top);
  const auto vz = hn::Min(ToInt32<true>(di, pz), top);
  const auto fr = hn::Set(di, g.fine_res);
  const auto fine =
      hn::Add(hn::ShiftRight<2>(vx), hn::Mul(fr, hn::Add(hn::ShiftRight<2>(vy), hn::Mul(fr, hn::ShiftRight<2>(vz)))));
  const auto one = hn::Set(di, 1), three = hn::Set(di, 3);
  const auto word = hn::IfThenElseZero(inside, hn::Add(hn::ShiftLeft<2>(fine), hn::And(hn::ShiftRight<1>(vz), one)));
  static_assert(kCell == 4, "4 words per fine voxel");
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
  // scalar p - float(v)) and the block vertex (the block and the MLP come
  // with the fine voxel's cell).
  const auto fx = hn::Sub(px, hn::ConvertTo(df, vx));
  const auto fy = hn::Sub(py, hn::ConvertTo(df, vy));
  const auto fz = hn::Sub(pz, hn::ConvertTo(df, vz));
  const auto five = hn::Set(di, kBlockVertsPerAxis);
  const auto vertex =
      hn::Add(hn::And(vx, three), hn::Mul(five, hn::Add(hn::And(vy, three), hn::Mul(five, hn::And(vz, three)))));
  // The samples' lanes packed to the front, in order: one compress per
  // vector where AVX-512 has it as an instruction, one permutation from a
  // table on AVX2, lane by lane elsewhere (other targets emulate it at far
  // greater cost).
#if HWY_TARGET == HWY_AVX3 || HWY_TARGET == HWY_AVX3_DL
  {
    const auto m = hn::RebindMask(di, samples);
    const auto mf = hn::RebindMask(df, samples);
    hn::StoreU(hn::Compress(fx, mf), df, st.found_f[0]);
    hn::StoreU(hn::Compress(fy, mf), df, st.found_f[1]);
    hn::StoreU(hn::Compress(fz, mf), df, st.found_f[2]);
    hn::StoreU(hn::Compress(fine, m), di, st.found_fine);
    hn::StoreU(hn::Compress(vertex, m), di, st.found_vertex);
  }
#elif HWY_TARGET == HWY_AVX2
  {
    static_assert(hn::MaxLanes(DF()) == 8, "8 lanes on AVX2");
    const __m256i idx = _mm256_srlv_epi32(_mm256_set1_epi32(int32_t(kCompressTable[bits])),
                                          _mm256_setr_epi32(0, 4, 8, 12, 16, 20, 24, 28));
    _mm256_storeu_ps(st.found_f[0], _mm256_permutevar8x32_ps(fx.raw, idx));
    _mm256_storeu_ps(st.found_f[1], _mm256_permutevar8x32_ps(fy.raw, idx));
    _mm256_storeu_ps(st.found_f[2], _mm256_permutevar8x32_ps(fz.raw, idx));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(st.found_fine), _mm256_permutevar8x32_epi32(fine.raw, idx));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(st.found_vertex), _mm256_permutevar8x32_epi32(vertex.raw, idx));
  }
#else
  {
    constexpr int kM = FastMarcher::State::kMaxChunk;
    alignas(64) float lf[3][kM];
    alignas(64) int32_t lv[2][kM];
    hn::Store(fx, df, lf[0]);
    hn::Store(fy, df, lf[1]);
    hn::Store(fz, df, lf[2]);
    hn::Store(fine, di, lv[0]);
    hn::Store(vertex, di, lv[1]);
    int n = 0;
    for (uint32_t b = bits; b != 0; b &= b - 1, ++n) {
      const int i = std::countr_zero(b);
      for (int a = 0; a < 3; ++a) st.found_f[a][n] = lf[a][i];
      st.found_fine[n] = lv[0][i];
      st.found_vertex[n] = lv[1][i];
    }
  }
#endif
  return bits;
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
  // The marcher's cursor and the output count in locals: the records'
  // stores could alias the state's words, which would otherwise be
  // stored and read again for every sample.
  uint32_t pending = st.pending;
  int j = st.found_next;
  int32_t block = st.block;
  int written = out.written;
  int n = 0;
  while (pending != 0 && n < room) {
    const int lane = std::countr_zero(pending);  // the pending samples are handed out in order
    pending &= pending - 1;
    ++n;
    const uint32_t* cell = g.words + kCell * size_t(st.found_fine[j]);  // read by the vector test
    block = int32_t(cell[FastSkipGrid::kCellBlock]);
    if constexpr (kRecords) {
      const int32_t mlp = int32_t(cell[FastSkipGrid::kCellMlp]);
      if (mlp < 0 || block < 0) {
        ++*out.missing;
        ++j;
        continue;
      }
      FastSample& r = out.records[written++];
      r.ray = out.ray;
      r.mlp = uint32_t(mlp);
      r.vertex = uint32_t(size_t(block) * kBlockVerts + size_t(st.found_vertex[j]));
      r.fx = st.found_f[0][j];
      r.fy = st.found_f[1][j];
      r.fz = st.found_f[2][j];
    } else {
      // The micro voxel from the candidate's point again (the same float
      // operations as the vector test, which found the point in the grid).
      MarchSample& s = out.samples[written];
      s.k = st.chunk_k + lane;
      Vec3i v;
      VoxelOf(st.ray.point(s.k), g, v);
      // v + (p - v) is p: the difference of a float in [v, v + 1] and v >= 0 is exact.
      s.p_micro = Vec3f{float(v.x) + st.found_f[0][j], float(v.y) + st.found_f[1][j], float(v.z) + st.found_f[2][j]};
      s.voxel = v;
      out.blocks[written++] = block;
    }
    ++j;
  }
  st.pending = pending;
  st.found_next = j;
  st.block = block;
  out.written = written;
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
  g.micro_res = s0.skip->micro_res;
  g.fine_res = s0.skip->res;
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

}  // namespace HWY_NAMESPACE
}  // namespace edrnr
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace edrnr {

HWY_EXPORT(MarchGroup);
HWY_EXPORT(MarchRecords);

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
