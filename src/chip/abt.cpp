#include "chip/abt.h"

#include <algorithm>

namespace edrnr::chip {

Abt::Abt(const Vec3d& box_lo, const Vec3d& box_hi, const FloatFormat& ray_float)
    : lo_(box_lo), hi_(box_hi), rf_(ray_float) {
  for (int a = 0; a < 3; ++a) {
    lo_wide_[a] = rf_.round(lo_[a] - 1.0);
    hi_wide_[a] = rf_.round(hi_[a] + 1.0);
  }
}

bool Abt::hits(const ChipRay& ray) const {
  double t_near = 0.0, t_far = rf_.max_finite();
  for (int a = 0; a < 3; ++a) {
    const double lo = lo_wide_[a], hi = hi_wide_[a];
    const double o = ray.origin[a], d = ray.dir[a];
    if (d == 0.0) {
      if (o < lo || o > hi) return false;
      continue;
    }
    double t0 = rf_.div(rf_.sub(lo, o), d), t1 = rf_.div(rf_.sub(hi, o), d);
    if (t0 > t1) std::swap(t0, t1);
    t_near = std::max(t_near, t0);
    t_far = std::min(t_far, t1);
  }
  return t_near <= t_far;
}

}  // namespace edrnr::chip
