#include "chip/tsps.h"

namespace edrnr::chip {

Tsps::Tsps(const RayMath& math, const Vec3d& box_lo, const Vec3d& box_hi) : math_(math), lo_(box_lo), hi_(box_hi) {}

KInterval Tsps::search(const ChipRay& ray) { return math_.box_interval(ray, lo_, hi_, &evals_); }

}  // namespace edrnr::chip
