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

Abt::Origin Abt::from(const Vec3d& origin) const {
  Origin o;
  o.origin = origin;
  for (int a = 0; a < 3; ++a) {
    o.lo_minus_o[a] = rf_.sub(lo_wide_[a], origin[a]);
    o.hi_minus_o[a] = rf_.sub(hi_wide_[a], origin[a]);
  }
  return o;
}

bool Abt::hits(const ChipRay& ray, const Origin& o) const {
  double t_near = 0.0, t_far = rf_.max_finite();
  for (int a = 0; a < 3; ++a) {
    const double d = ray.dir[a];
    if (d == 0.0) {
      if (o.origin[a] < lo_wide_[a] || o.origin[a] > hi_wide_[a]) return false;
      continue;
    }
    double t0 = rf_.div(o.lo_minus_o[a], d), t1 = rf_.div(o.hi_minus_o[a], d);
    if (t0 > t1) std::swap(t0, t1);
    t_near = std::max(t_near, t0);
    t_far = std::min(t_far, t1);
  }
  return t_near <= t_far;
}

}  // namespace edrnr::chip
