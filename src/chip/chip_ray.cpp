#include "chip/chip_ray.h"

#include <algorithm>
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
}  // namespace

RayMath::RayMath(const FloatFormat& fmt, double step_micro, int micro_res)
    : fmt_(fmt), step_(fmt.round(step_micro)), micro_res_(micro_res) {
  if (!(step_ > 0.0) || !std::isfinite(step_micro)) fail("sample step {} (micro voxels) must be positive", step_micro);
  if (micro_res < 1) fail("micro resolution {} must be positive", micro_res);
}

Vec3d RayMath::point(const ChipRay& r, int64_t k) const {
  const double t = t_of(k);
  return {fmt_.fma(r.dir.x, t, r.origin.x), fmt_.fma(r.dir.y, t, r.origin.y), fmt_.fma(r.dir.z, t, r.origin.z)};
}

int RayMath::micro_index(double c) const {
  if (!(c >= 0.0)) return 0;
  if (c >= double(micro_res_)) return micro_res_ - 1;
  return int(std::floor(c));
}

Vec3i RayMath::cell(const Vec3d& p, int cell_micro) const {
  Vec3i m = micro_voxel(p);
  return {m.x / cell_micro, m.y / cell_micro, m.z / cell_micro};
}

int64_t RayMath::cell_exit(const ChipRay& r, int64_t k0, int64_t k_end, const Vec3i& c, int cell_micro,
                           uint64_t* evals) const {
  int64_t best = k_end;
  for (int a = 0; a < 3; ++a) {
    const double d = r.dir[a];
    if (d == 0.0) continue;  // the coordinate never changes
    // Leaving the cell along this axis: past its far face in the direction of travel.
    auto outside = [&](int64_t k) {
      if (evals) ++*evals;
      return micro_index(coord(r, k, a)) / cell_micro != c[a];
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
  KInterval out{0, kMaxCandidate};
  for (int a = 0; a < 3; ++a) {
    const double d = r.dir[a];
    auto count = [&] {
      if (evals) ++*evals;
    };
    if (d == 0.0) {
      const double c = r.origin[a];  // fma(0, t, o) = o
      if (!(c >= lo[a] && c <= hi[a])) return {0, 0};
      continue;
    }
    // Inside along this axis: a run [enter, leave) of k (the coordinate is monotone).
    int64_t enter, leave;
    if (d > 0) {
      enter = first_true(0, kMaxCandidate, [&](int64_t k) {
        count();
        return coord(r, k, a) >= lo[a];
      });
      leave = first_true(enter, kMaxCandidate, [&](int64_t k) {
        count();
        return coord(r, k, a) > hi[a];
      });
    } else {
      enter = first_true(0, kMaxCandidate, [&](int64_t k) {
        count();
        return coord(r, k, a) <= hi[a];
      });
      leave = first_true(enter, kMaxCandidate, [&](int64_t k) {
        count();
        return coord(r, k, a) < lo[a];
      });
    }
    out.begin = std::max(out.begin, enter);
    out.end = std::min(out.end, leave);
  }
  if (out.empty()) return {0, 0};
  return out;
}

}  // namespace edrnr::chip
