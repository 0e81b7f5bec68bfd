// Highway kernels of the training-time occupancy grid and its refresh
// (train/occupancy_kernels.h), compiled once per SIMD target
// (hwy/foreach_target.h) and picked at run time (HWY_DYNAMIC_DISPATCH).
#include "train/occupancy_kernels.h"

#include <algorithm>
#include <cstring>

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "train/occupancy_kernels.cpp"
#include <hwy/foreach_target.h>  // before highway.h
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace edrnr::train {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<float>;
constexpr size_t kN = hn::MaxLanes(DF());
static_assert(kLanes % kN == 0 && 64 % kN == 0, "a chunk and a word are whole vectors");

void SumNonnegative(const float* d, size_t n, double* sum, size_t* count) {
  constexpr size_t kParts = 8;  // the contract's partial sums
  const hn::ScalableTag<double> dd;
  const hn::Rebind<float, decltype(dd)> df;  // as many float lanes as double lanes
  constexpr size_t nd = hn::MaxLanes(dd);
  static_assert(kParts % nd == 0, "the partial sums are whole vectors");
  constexpr size_t kVecs = kParts / nd;
  const auto zero = hn::Zero(dd);
  hn::Vec<decltype(dd)> acc[kVecs];
  for (size_t v = 0; v < kVecs; ++v) acc[v] = zero;
  size_t cnt = 0;
  size_t i = 0;
  for (; i + kParts <= n; i += kParts)
    for (size_t v = 0; v < kVecs; ++v) {
      const auto x = hn::PromoteTo(dd, hn::LoadU(df, d + i + v * nd));  // exact
      const auto keep = hn::Ge(x, zero);                                // false for NaN
      // Adding +0 for a value left out changes no partial sum: each starts at
      // +0, so none is ever -0.
      acc[v] = hn::Add(acc[v], hn::IfThenElseZero(keep, x));
      cnt += hn::CountTrue(dd, keep);
    }
  double part[kParts];
  for (size_t v = 0; v < kVecs; ++v) hn::StoreU(acc[v], dd, part + v * nd);
  for (; i < n; ++i)
    if (d[i] >= 0.f) {
      part[i % kParts] += double(d[i]);
      ++cnt;
    }
  double s = 0;
  for (size_t p = 0; p < kParts; ++p) s += part[p];
  *sum = s;
  *count = cnt;
}

void ThresholdWords(const float* d, size_t n_words, float threshold, uint64_t* words) {
  const DF df;
  const auto zero = hn::Zero(df), t = hn::Set(df, threshold);
  for (size_t w = 0; w < n_words; ++w) {
    uint64_t bits = 0;
    for (size_t b = 0; b < 64; b += kN) {
      const auto v = hn::LoadU(df, d + 64 * w + b);
      uint8_t bytes[8] = {0, 0, 0, 0, 0, 0, 0, 0};
      hn::StoreMaskBits(df, hn::Or(hn::Lt(v, zero), hn::Gt(v, t)), bytes);
      uint64_t x;
      std::memcpy(&x, bytes, sizeof x);  // lane j in bit j
      if (kN < 64) x &= (uint64_t(1) << kN) - 1;
      bits |= x << b;
    }
    words[w] = bits;
  }
}

#if HWY_TARGET != HWY_SCALAR
// LoadCorners for vectors of 4 lanes or more, from the vertices first ..
// first + kN (s >= 2), first + kN + 1 (s == 1) or first + 2 kN (s == 0).
static_assert(kN >= 4, "every target but HWY_SCALAR has 4 float lanes or more");
HWY_INLINE void LoadCornersWide(const float* v, size_t first, int s, int x_cell0, hn::Vec<DF> (&V)[2][4]) {
  const DF d;
  if (s == 0) {  // lane j: vertices first + 2 j (+1)
    hn::Vec<DF> a[4], b[4];
    hn::LoadInterleaved4(d, v + 4 * first, a[0], a[1], a[2], a[3]);
    hn::LoadInterleaved4(d, v + 4 * (first + kN), b[0], b[1], b[2], b[3]);
    for (int k = 0; k < 4; ++k) {
      V[0][k] = hn::ConcatEven(d, b[k], a[k]);
      V[1][k] = hn::ConcatOdd(d, b[k], a[k]);
    }
  } else if (s == 1) {  // lane j: vertices first + j (+1)
    hn::LoadInterleaved4(d, v + 4 * first, V[0][0], V[0][1], V[0][2], V[0][3]);
    hn::LoadInterleaved4(d, v + 4 * (first + 1), V[1][0], V[1][1], V[1][2], V[1][3]);
  } else {  // lane j: vertex first + (cx_j - cx_0) (+1), at most kN / 2 + 1 < kN
    const hn::RebindToSigned<DF> di;
    const auto x = hn::Add(hn::Set(di, x_cell0), hn::ShiftLeft<1>(hn::Iota(di, 0)));
    const auto pos = hn::Sub(hn::ShiftRightSame(x, s), hn::Set(di, x_cell0 >> s));
    const auto i0 = hn::IndicesFromVec(d, pos), i1 = hn::IndicesFromVec(d, hn::Add(pos, hn::Set(di, 1)));
    hn::Vec<DF> a[4];
    hn::LoadInterleaved4(d, v + 4 * first, a[0], a[1], a[2], a[3]);
    for (int k = 0; k < 4; ++k) {
      V[0][k] = hn::TableLookupLanes(a[k], i0);
      V[1][k] = hn::TableLookupLanes(a[k], i1);
    }
  }
}
#endif

// The 4 channels of corners dx = 0, 1 of lanes v0 + j in vertex row `row`
// of level L: lane j's corner is the vertex row + cx_j + dx, where cx_j =
// (x_cell0 + 2 j) >> shift. V[dx][k]: channel k in lanes. The lanes from
// `valid` on may hold anything.
HWY_INLINE void LoadCorners(const PyramidLevelView& L, size_t row, int x_cell0, size_t valid, hn::Vec<DF> (&V)[2][4]) {
  const DF d;
  const int s = L.shift;
  const float* v = L.value;
#if HWY_TARGET != HWY_SCALAR
  const size_t n = size_t(L.res) + 1;
  const size_t first = row + size_t(x_cell0 >> s);             // lane 0's corner dx = 0
  const size_t need = s == 0 ? 2 * kN : s == 1 ? kN + 1 : kN;  // vertices read from `first` on
  if (first + need <= n * n * n) {
    LoadCornersWide(v, first, s, x_cell0, V);
    return;
  }
#endif
  // Lane by lane (narrow vectors, or the grid's last vertices).
  HWY_ALIGN float lanes[2][4][kN];
  for (size_t j = 0; j < kN; ++j) {
    const size_t at = row + size_t((x_cell0 + 2 * int(j)) >> s);
    for (int dx = 0; dx < 2; ++dx)
      for (int k = 0; k < 4; ++k) lanes[dx][k][j] = j < valid ? v[4 * (at + size_t(dx)) + size_t(k)] : 0.f;
  }
  for (int dx = 0; dx < 2; ++dx)
    for (int k = 0; k < 4; ++k) V[dx][k] = hn::Load(d, lanes[dx][k]);
}

void InterpolateRow(const PyramidLevelView* levels, int n_levels, int x_first, int y, int z, int nl, const float* px,
                    const float* py, const float* pz, float* x0) {
  const DF d;
  const hn::RebindToSigned<DF> di;
  for (int li = 0; li < n_levels; ++li) {
    const PyramidLevelView& L = levels[li];
    float* out = x0 + size_t(li) * 4 * kLanes;
    if (!L.active) {
      std::memset(out, 0, 4 * kLanes * sizeof(float));
      continue;
    }
    const int s = L.shift;
    const float inv = 1.f / float(1 << s);  // exact: a power of two
    const int cy = y >> s, cz = z >> s;
    const size_t n = size_t(L.res) + 1;
    // Vertex rows of the corners: c = 2 r + dx for row r = (dy, dz) in the
    // order (0, 0), (1, 0), (0, 1), (1, 1), as FeaturePyramid::interpolate.
    const size_t row0 = n * (size_t(cy) + n * size_t(cz));
    const size_t rows[4] = {row0, row0 + n, row0 + n * n, row0 + n * n + n};
    const auto vinv = hn::Set(d, inv), one = hn::Set(d, 1.f);
    for (size_t v0 = 0; v0 < size_t(kLanes); v0 += kN) {
      const size_t valid = nl > int(v0) ? std::min(kN, size_t(nl) - v0) : 0;
      if (valid == 0) {
        for (int k = 0; k < 4; ++k) hn::StoreU(hn::Zero(d), d, out + size_t(k) * kLanes + v0);
        continue;
      }
      const int x_cell0 = x_first + 2 * int(v0);  // lane 0's micro x
      const auto x = hn::Add(hn::Set(di, x_cell0), hn::ShiftLeft<1>(hn::Iota(di, 0)));
      const auto cx = hn::ConvertTo(d, hn::ShiftRightSame(x, s));
      // trilinear_weights, operation by operation.
      const auto fx = hn::Sub(hn::Mul(hn::LoadU(d, px + v0), vinv), cx);
      const auto fy = hn::Sub(hn::Mul(hn::LoadU(d, py + v0), vinv), hn::Set(d, float(cy)));
      const auto fz = hn::Sub(hn::Mul(hn::LoadU(d, pz + v0), vinv), hn::Set(d, float(cz)));
      const auto gx = hn::Sub(one, fx), gy = hn::Sub(one, fy), gz = hn::Sub(one, fz);
      const hn::Vec<DF> w[8] = {hn::Mul(hn::Mul(gx, gy), gz), hn::Mul(hn::Mul(fx, gy), gz),
                                hn::Mul(hn::Mul(gx, fy), gz), hn::Mul(hn::Mul(fx, fy), gz),
                                hn::Mul(hn::Mul(gx, gy), fz), hn::Mul(hn::Mul(fx, gy), fz),
                                hn::Mul(hn::Mul(gx, fy), fz), hn::Mul(hn::Mul(fx, fy), fz)};
      hn::Vec<DF> acc[4] = {hn::Zero(d), hn::Zero(d), hn::Zero(d), hn::Zero(d)};
      for (int r = 0; r < 4; ++r) {
        hn::Vec<DF> V[2][4];
        LoadCorners(L, rows[r], x_cell0, valid, V);
        for (int dx = 0; dx < 2; ++dx)
          for (int k = 0; k < 4; ++k) acc[k] = hn::Add(acc[k], hn::Mul(w[2 * r + dx], V[dx][k]));
      }
      const auto live = hn::FirstN(d, valid);
      for (int k = 0; k < 4; ++k) hn::StoreU(hn::IfThenElseZero(live, acc[k]), d, out + size_t(k) * kLanes + v0);
    }
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace edrnr::train
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace edrnr::train {

HWY_EXPORT(SumNonnegative);
HWY_EXPORT(ThresholdWords);
HWY_EXPORT(InterpolateRow);

void occupancy_sum_nonnegative(const float* d, size_t n, double* sum, size_t* count) {
  HWY_DYNAMIC_DISPATCH(SumNonnegative)(d, n, sum, count);
}

void occupancy_threshold_words(const float* d, size_t n_words, float threshold, uint64_t* words) {
  HWY_DYNAMIC_DISPATCH(ThresholdWords)(d, n_words, threshold, words);
}

void refresh_interpolate_row(const PyramidLevelView* levels, int n_levels, int x_first, int y, int z, int nl,
                             const float* px, const float* py, const float* pz, float* x0) {
  HWY_DYNAMIC_DISPATCH(InterpolateRow)(levels, n_levels, x_first, y, z, nl, px, py, pz, x0);
}

}  // namespace edrnr::train
#endif
