#include "chip/chip_ray.h"

#include <algorithm>
#include <bit>
#include <cmath>

#include "core/error.h"

namespace edrnr::chip {

namespace {
// Smallest k in [lo, hi) with pred(k) true, or hi if none; pred is monotone
// (false then true) on [lo, hi).
template <class Pred>
int64_t first_true(int64_t lo, int64_t hi, Pred pred) {
  while (lo < hi) {
    int64_t mid = lo + (hi - lo) / 2;
    if (pred(mid))
      hi = mid;
    else
      lo = mid + 1;
  }
  return lo;
}

// The number of predicate evaluations first_true(lo, hi, pred) makes when
// its answer is `e`: the bisection's path follows from e alone (pred(k) is
// k >= e on a monotone predicate), so it is replayed without evaluating.
uint64_t first_true_steps(int64_t lo, int64_t hi, int64_t e) {
  uint64_t steps = 0;
  while (lo < hi) {
    const int64_t mid = lo + (hi - lo) / 2;
    ++steps;
    if (mid >= e)
      hi = mid;
    else
      lo = mid + 1;
  }
  return steps;
}

// first_true(lo, hi, pred) found from a guess: a few steps from it, checked
// exactly (pred(e - 1) false unless e == lo, pred(e) true unless e == hi),
// and bisection on what remains if the guess is far off. The predicate must
// be monotone on [lo, hi).
template <class Pred>
int64_t first_true_from(int64_t lo, int64_t hi, double guess, Pred pred) {
  if (lo >= hi) return lo;
  constexpr int kWalk = 4;
  const int64_t g = std::isfinite(guess) ? int64_t(std::clamp(guess, double(lo), double(hi - 1))) : lo + (hi - lo) / 2;
  int64_t e = g;
  if (pred(g)) {
    for (int n = 0; e > lo && pred(e - 1); --e)
      if (++n == kWalk) return first_true(lo, e - 1, pred);  // pred(e - 1) is true
  } else {
    e = g + 1;
    for (int n = 0; e < hi && !pred(e); ++e)
      if (++n == kWalk) return first_true(e + 1, hi, pred);  // pred(e) is false
  }
  return e;
}
}  // namespace

RayMath::RayMath(const FloatFormat& fmt, double step_micro, int micro_res)
    : fmt_(fmt), step_(fmt.round(step_micro)), micro_res_(micro_res) {
  if (!(step_ > 0.0) || !std::isfinite(step_micro)) fail("sample step {} (micro voxels) must be positive", step_micro);
  if (micro_res < 1) fail("micro resolution {} must be positive", micro_res);
  // Cameras sit a few box sizes from the scene: t up to 16 box edges covers
  // the candidates of a frame; larger k are computed (same values). At most
  // 2^18 entries (2 MiB).
  const double reach = 16.0 * double(micro_res) / step_ + 2.0;
  const size_t entries = size_t(std::min(reach, double(int64_t(1) << 18)));
  t_table_.resize(entries);
  for (size_t k = 0; k < entries; ++k) t_table_[k] = t_exact(int64_t(k));
}

int64_t RayMath::cell_exit(const ChipRay& r, int64_t k0, int64_t k_end, const Vec3i& c, int cell_micro,
                           uint64_t* evals) const {
  int64_t best = k_end;
  for (int a = 0; a < 3; ++a) {
    const double d = r.dir[a];
    if (d == 0.0) continue;  // the coordinate never changes
    // Leaving the cell along this axis: past its far face in the direction of travel.
    // In the cell: a micro voxel of [first, last] (micro_index is never negative).
    const int first = c[a] * cell_micro, last = first + cell_micro - 1;
    auto outside = [&](int64_t k) {
      if (evals) ++*evals;
      const int m = micro_index(coord(r, k, a));
      return m < first || m > last;
    };
    const double face = d > 0 ? double((c[a] + 1) * cell_micro) : double(c[a] * cell_micro);
    if ((d > 0 && face >= double(micro_res_)) || (d < 0 && face <= 0.0))
      continue;                            // the last cell: only the box ends it
    const int64_t lo = k0 + 1, hi = best;  // only an exit before `best` matters
    if (lo >= hi) break;
    // First guess: the candidate just past the face, then checked exactly.
    const double guess = std::ceil((face - r.origin[a]) / (d * step_) - 0.5);
    const int64_t g = std::isfinite(guess) ? int64_t(std::clamp(guess, double(lo), double(hi - 1))) : hi - 1;
    int64_t e;
    if (outside(g))
      e = (g == lo || !outside(g - 1)) ? g : first_true(lo, g - 1, outside);
    else
      e = (g + 1 >= hi || outside(g + 1)) ? g + 1 : first_true(g + 2, hi, outside);
    best = std::min(best, e);
  }
  return best;
}

KInterval RayMath::box_interval(const ChipRay& r, const Vec3d& lo, const Vec3d& hi, uint64_t* evals) const {
  // The TSPS bisects each bound over [0, kMaxCandidate). The bounds are found
  // here from the ray's distance to each face, checked exactly (the
  // coordinate is monotone in k, so the first k past a face is unique), and
  // the bisection's evaluations are counted as the hardware makes them.
  KInterval out{0, kMaxCandidate};
  for (int a = 0; a < 3; ++a) {
    const double d = r.dir[a];
    if (d == 0.0) {
      const double c = r.origin[a];  // fma(0, t, o) = o
      if (!(c >= lo[a] && c <= hi[a])) return {0, 0};
      continue;
    }
    // Inside along this axis: a run [enter, leave) of k (the coordinate is monotone).
    auto k_at = [&](double face) { return std::ceil((face - r.origin[a]) / (d * step_) - 0.5); };
    int64_t enter, leave;
    if (d > 0) {
      enter = first_true_from(0, kMaxCandidate, k_at(lo[a]), [&](int64_t k) { return coord(r, k, a) >= lo[a]; });
      leave = first_true_from(enter, kMaxCandidate, k_at(hi[a]), [&](int64_t k) { return coord(r, k, a) > hi[a]; });
    } else {
      enter = first_true_from(0, kMaxCandidate, k_at(hi[a]), [&](int64_t k) { return coord(r, k, a) <= hi[a]; });
      leave = first_true_from(enter, kMaxCandidate, k_at(lo[a]), [&](int64_t k) { return coord(r, k, a) < lo[a]; });
    }
    if (evals) *evals += first_true_steps(0, kMaxCandidate, enter) + first_true_steps(enter, kMaxCandidate, leave);
    out.begin = std::max(out.begin, enter);
    out.end = std::min(out.end, leave);
  }
  if (out.empty()) return {0, 0};
  return out;
}

}  // namespace edrnr::chip
