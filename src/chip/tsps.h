#pragma once
// TSPS, the traversal starting point searcher (paper Section IV-A).
//
// Refines where a ray of a packet starts and ends its march: the run of
// candidates k whose point lies in the (closed) traversal box, found by a
// binary search on k for each face of the box. Each coordinate of p_k is
// monotone in k, so the search is exact: the run begins at the first
// candidate inside the box and ends at the first past it. An empty run means
// the ray has no candidate in the box and is dropped like an ABT miss.
#include <cstdint>

#include "chip/chip_ray.h"

namespace edrnr::chip {

class Tsps {
 public:
  // math is kept by reference.
  Tsps(const RayMath& math, const Vec3d& box_lo, const Vec3d& box_hi);

  // The ray's run of candidates inside the box (RayMath::box_interval).
  KInterval search(const ChipRay& ray);

  // Positions computed so far by the searches.
  uint64_t position_evals() const { return evals_; }

 private:
  const RayMath& math_;
  RayMath::PreparedBox box_;
  uint64_t evals_ = 0;
};

}  // namespace edrnr::chip
