#include "chip/tsps.h"

namespace edrnr::chip {

Tsps::Tsps(const RayMath& math, const Vec3d& box_lo, const Vec3d& box_hi)
    : math_(math), box_(math.prepare_box(box_lo, box_hi)) {}

KInterval Tsps::search(const ChipRay& ray) { return math_.box_interval(ray, box_, &evals_); }

}  // namespace edrnr::chip
