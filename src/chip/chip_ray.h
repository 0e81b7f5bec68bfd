#pragma once
// Ray and sample-position arithmetic shared by the traversal units (TSPS, CTU,
// FTU) and the OoO-SI's sample coordinate calculator.
//
// The chip works in micro-grid units: the scene box corner is 0 and a micro
// voxel edge is 1. Candidate k of a ray sits at
//   t_k = round(k + 0.5) * step          (traversal float, one rounding each)
//   p_k = fma(d, t_k, o)                 (per axis, a single rounding)
// where o and d are the ray origin and direction in micro units and step is
// the sample step in micro-voxel edges (the reference renderer's delta). Each
// coordinate of p_k is a monotone function of k (every rounding is monotone),
// so the candidates whose point lies in one cell of any tier form one
// contiguous run of k, and p_k depends on (ray, k) only: never on the order in
// which the units visit the candidates.
//
// A point belongs to micro voxel min(floor(p), Rm - 1) per axis when
// 0 <= p <= Rm (the reference renderer's convention), and to the cell of a
// tier with cells of S micro voxels given by that micro voxel divided by S.
#include <array>
#include <bit>
#include <cstdint>
#include <vector>

#include "core/custom_float.h"
#include "core/vec.h"

namespace edrnr::chip {

// A ray as the traversal sees it (all values of the traversal float format).
struct ChipRay {
  Vec3d origin;  // o, micro units
  Vec3d dir;     // d, micro units per micro-voxel edge of t (unit length for a cubic scene box)
};

// A half-open run of candidates [begin, end); empty when begin >= end.
struct KInterval {
  int64_t begin = 0, end = 0;
  bool empty() const { return begin >= end; }
};

// Candidate indices never exceed this (about 4 million steps).
inline constexpr int64_t kMaxCandidate = int64_t(1) << 22;

// The number of predicate evaluations a bisection for the first k in
// [lo, hi) whose monotone predicate holds (midpoint lo + (hi - lo) / 2, the
// upper half kept when it fails) makes when its answer is e (hi: none
// holds).
uint64_t first_true_steps(int64_t lo, int64_t hi, int64_t e);

class RayMath {
 public:
  // fmt: the traversal float; step_micro > 0; micro_res: Rm.
  RayMath(const FloatFormat& fmt, double step_micro, int micro_res);

  const FloatFormat& format() const { return fmt_; }
  double step() const { return step_; }
  int micro_res() const { return micro_res_; }

  // t_k; the values of the candidates a frame visits come from a table
  // filled at construction with the same arithmetic.
  double t_of(int64_t k) const { return uint64_t(k) < t_table_.size() ? t_table_[size_t(k)] : t_exact(k); }
  double coord(const ChipRay& r, int64_t k, int axis) const { return fmt_.fma(r.dir[axis], t_of(k), r.origin[axis]); }
  Vec3d point(const ChipRay& r, int64_t k) const {
    const double t = t_of(k);
    return {fmt_.fma(r.dir.x, t, r.origin.x), fmt_.fma(r.dir.y, t, r.origin.y), fmt_.fma(r.dir.z, t, r.origin.z)};
  }

  // The micro voxel of a point inside [0, Rm]^3 (clamped otherwise).
  int micro_index(double c) const {
    if (!(c >= 0.0)) return 0;
    if (c >= double(micro_res_)) return micro_res_ - 1;
    return int(c);  // c in [0, Rm): truncation is the floor
  }
  Vec3i micro_voxel(const Vec3d& p) const { return {micro_index(p.x), micro_index(p.y), micro_index(p.z)}; }
  // The cell of a tier with cells of cell_micro micro voxels per axis.
  Vec3i cell(const Vec3d& p, int cell_micro) const {
    const Vec3i m = micro_voxel(p);
    if (std::has_single_bit(unsigned(cell_micro))) {  // m >= 0: a shift divides
      const int s = std::countr_zero(unsigned(cell_micro));
      return {m.x >> s, m.y >> s, m.z >> s};
    }
    return {m.x / cell_micro, m.y / cell_micro, m.z / cell_micro};
  }
  Vec3i cell_at(const ChipRay& r, int64_t k, int cell_micro) const {
    const Vec3i m = micro_voxel_at(r, k);
    if (std::has_single_bit(unsigned(cell_micro))) {
      const int s = std::countr_zero(unsigned(cell_micro));
      return {m.x >> s, m.y >> s, m.z >> s};
    }
    return {m.x / cell_micro, m.y / cell_micro, m.z / cell_micro};
  }

  // Whether micro_index(coord(r, k, a)) >= f, decided from the double sum
  // d t_k + o against the rounding threshold of f (see thresholds_), without
  // rounding the coordinate. Always true for f <= 0, never for f >= Rm.
  bool micro_at_least(const ChipRay& r, int64_t k, int a, int f) const {
    if (f <= 0) return true;
    if (f >= micro_res_) return false;
    if (thresholds_.empty()) return micro_index(coord(r, k, a)) >= f;
    const double o = r.origin[a], prod = r.dir[a] * t_of(k);
    return sum_at_least(prod, o, prod + o, f);
  }
  // micro_index(coord(r, k, a)), exactly.
  int micro_index_at(const ChipRay& r, int64_t k, int a) const {
    if (thresholds_.empty()) return micro_index(coord(r, k, a));
    const double o = r.origin[a], prod = r.dir[a] * t_of(k), s = prod + o;
    // The sum's truncation m, or m + 1 when the sum passes that threshold.
    // Every threshold lies in [f - 1/2, f) (see make_thresholds), so a sum
    // s >= m passes m's and one below m + 1 cannot pass m + 2's.
    const int m = s >= 0.0 ? (s < double(micro_res_) ? int(s) : micro_res_ - 1) : 0;
    return m + 1 < micro_res_ && sum_at_least(prod, o, s, m + 1) ? m + 1 : m;
  }
  // micro_voxel(point(r, k)), exactly.
  Vec3i micro_voxel_at(const ChipRay& r, int64_t k) const {
    return {micro_index_at(r, k, 0), micro_index_at(r, k, 1), micro_index_at(r, k, 2)};
  }

  // The first candidate k in (k0, k_end) whose point is not in `cell` (cells
  // of cell_micro micro voxels), or k_end if the ray stays in it. The point of
  // k0 must be in the cell. A first guess from the ray's exit distance is
  // checked exactly (k-1 inside, k outside) and corrected by bisection, so the
  // result does not depend on the guess. `evals` (optional) counts the
  // positions computed.
  int64_t cell_exit(const ChipRay& r, int64_t k0, int64_t k_end, const Vec3i& cell, int cell_micro,
                    uint64_t* evals = nullptr) const;

  // Where one ray crosses the faces it met last, per axis: a ray crosses a
  // given face of an axis at one candidate whatever cell it leaves through
  // it, so a cell exit needs only the faces it has not met yet. A memo
  // belongs to one ray and one k_limit; value-initialise it (no face) for a
  // new ray.
  struct FaceCrossing {
    int face = 0;       // micro-grid coordinate of the face; 0: none (never a far face that is searched)
    int64_t guess = 0;  // the search's first guess for it (see guess_index in chip_ray.cpp)
    int64_t first = 0;  // min(first candidate past it, k_limit)
  };
  struct ExitMemo {
    std::array<std::array<FaceCrossing, 2>, 3> axis{};  // per axis, the latest face first
  };
  // cell_exit(r, k0, k_end, cell, cell_micro, evals), the same result and
  // count, with k_end <= k_limit and the crossings kept in `memo`.
  int64_t cell_exit(const ChipRay& r, int64_t k0, int64_t k_end, const Vec3i& cell, int cell_micro, uint64_t* evals,
                    ExitMemo& memo, int64_t k_limit) const {
    if (cell_micro == 4) return cell_exit_memo<2>(r, k0, k_end, cell, 4, evals, memo, k_limit);
    if (cell_micro == 2) return cell_exit_memo<1>(r, k0, k_end, cell, 2, evals, memo, k_limit);
    return cell_exit_memo<-1>(r, k0, k_end, cell, cell_micro, evals, memo, k_limit);
  }

  // The run of candidates k >= 0 whose point lies in the closed box
  // [lo, hi] (micro units), found exactly by bisection on each axis bound.
  KInterval box_interval(const ChipRay& r, const Vec3d& lo, const Vec3d& hi, uint64_t* evals = nullptr) const;

  // Where a fused multiply-add's result round(x) of the exact sum x reaches
  // a value: round(x) passes it exactly when x > mid, or x == mid and tie_up.
  struct Threshold {
    double mid = 0;
    bool tie_up = false;
  };
  // Whether the sum x = prod + o, of which s is the double rounding, passes
  // h. Rounding to double is monotone and mid is a double, so s decides
  // unless s == mid, where the sum's exact error (TwoSum) does.
  static bool sum_at_least(double prod, double o, double s, const Threshold& h) {
    if (s != h.mid) return s > h.mid;
    const double bv = s - prod;
    const double err = (prod - (s - bv)) + (o - bv);
    return err > 0.0 || (err == 0.0 && h.tie_up);
  }
  // The threshold of "round(x) >= v" (strict: "round(x) > v") for this
  // format's fused multiply-add; false if no finite sum passes it.
  bool find_threshold(double v, bool strict, Threshold& out) const;

  // A box with the thresholds of its faces, for repeated box_interval calls.
  struct PreparedBox {
    Vec3d lo, hi;
    std::array<Threshold, 3> at_least_lo, above_hi;  // coordinate >= lo, coordinate > hi
    std::array<bool, 3> fast{};                      // false: that axis rounds each position
  };
  PreparedBox prepare_box(const Vec3d& lo, const Vec3d& hi) const;
  // box_interval(r, box.lo, box.hi, evals), the same result and count.
  KInterval box_interval(const ChipRay& r, const PreparedBox& box, uint64_t* evals = nullptr) const;

 private:
  double t_exact(int64_t k) const { return fmt_.mul(fmt_.round(double(k) + 0.5), step_); }

  // For the exact sum x = prod + o of which s is the double rounding, whether
  // round(x) >= f for an integer f in [1, Rm) (thresholds_ must be filled).
  // round() is monotone, so round(x) >= f exactly when x lies past the
  // threshold mid_f (or on it when mid_f itself rounds up); mid_f is a double
  // and rounding to double is monotone too, so s decides unless s == mid_f,
  // where the sum's exact error (TwoSum) does.
  bool sum_at_least(double prod, double o, double s, int f) const {
    return sum_at_least(prod, o, s, thresholds_[size_t(f)]);
  }
  // Fills thresholds_, or leaves it empty (then every test rounds) if the
  // format has no threshold of the expected kind for some f.
  void make_thresholds();
  // The memo's cell exit for cells of cell_micro = 2^kShift micro voxels,
  // or of any cell_micro with kShift < 0.
  template <int kShift>
  int64_t cell_exit_memo(const ChipRay& r, int64_t k0, int64_t k_end, const Vec3i& cell, int cell_micro,
                         uint64_t* evals, ExitMemo& memo, int64_t k_limit) const;
  // The crossing of `face` on axis a (searched over [lo, k_limit) unless
  // kept[1] holds it), made kept[0].
  const FaceCrossing& crossing(const ChipRay& r, int a, int face, int64_t lo, int64_t k_limit,
                               std::array<FaceCrossing, 2>& kept) const;
  // cell_exit with every position rounded (formats without thresholds).
  int64_t cell_exit_rounded(const ChipRay& r, int64_t k0, int64_t k_end, const Vec3i& cell, int cell_micro,
                            uint64_t* evals) const;

  FloatFormat fmt_;
  double step_;
  int micro_res_;
  std::vector<double> t_table_;        // t_exact(k) for k in [0, size)
  std::vector<Threshold> thresholds_;  // by f in [0, Rm) (entry 0 unused); empty: no fast tests
};

}  // namespace edrnr::chip
