#pragma once
// ABT, the AABB tester (paper Sections III-A, IV-A, Fig. 3).
//
// Drops rays that cannot meet the object's axis-aligned bounding box, so their
// pixels take the background without any traversal. The box is given in
// micro-grid units; the chip uses the object AABB widened to whole micro
// voxels (every occupied micro voxel lies inside it, so no sample is lost).
// The slab test runs in the ray float format on the box widened by one micro
// voxel, which covers the rounding of the test itself: a dropped ray has no
// candidate sample in the box. A ray that passes may still have none (a
// grazing ray); the TSPS finds that exactly.
#include "chip/chip_ray.h"
#include "core/custom_float.h"

namespace edrnr::chip {

class Abt {
 public:
  Abt(const Vec3d& box_lo, const Vec3d& box_hi, const FloatFormat& ray_float);

  // False only if no point of the ray at t >= 0 comes within one micro voxel of the box.
  bool hits(const ChipRay& ray) const { return hits(ray, from(ray.origin)); }

  // The slab test's terms that depend on the ray's origin only (the widened
  // faces minus the origin, rounded), for rays that share it.
  struct Origin {
    Vec3d origin, lo_minus_o, hi_minus_o;
  };
  Origin from(const Vec3d& origin) const;
  // hits(ray) for a ray whose origin is o.origin.
  bool hits(const ChipRay& ray, const Origin& o) const;

  const Vec3d& lo() const { return lo_; }
  const Vec3d& hi() const { return hi_; }

 private:
  Vec3d lo_, hi_;
  Vec3d lo_wide_, hi_wide_;  // the box widened by one micro voxel, in the ray float
  FloatFormat rf_;
};

}  // namespace edrnr::chip
