#include "chip/front_end.h"

#include <algorithm>
#include <cmath>

#include "chip/tme.h"

namespace edrnr::chip {

namespace {
Vec3d box_corner(const SceneModel& m, bool use_aabb, bool upper) {
  const double R = m.micro_res;
  Vec3d out;
  for (int a = 0; a < 3; ++a) {
    out[a] = upper ? R : 0.0;
    if (!use_aabb) continue;
    const double box_lo = m.scene_box.lo[a], size = m.scene_box.size()[a];
    const double v = (double(upper ? m.object_aabb.hi[a] : m.object_aabb.lo[a]) - box_lo) / size * R;
    // Outward to whole micro voxels; the tolerance absorbs the float error
    // of a face that lies exactly on a voxel boundary.
    out[a] = std::clamp(upper ? std::ceil(v + 1e-3) : std::floor(v - 1e-3), 0.0, R);
  }
  return out;
}

Vec3i travel_sign(const Vec3d& dir) {
  return {std::signbit(dir.x) ? -1 : 1, std::signbit(dir.y) ? -1 : 1, std::signbit(dir.z) ? -1 : 1};
}
}  // namespace

void traversal_box(const SceneModel& model, bool use_aabb, Vec3d& lo, Vec3d& hi) {
  lo = box_corner(model, use_aabb, false);
  hi = box_corner(model, use_aabb, true);
}

FrontEnd::FrontEnd(const SceneModel& model, const Camera& camera, const ChipNumerics& numerics, const RayMath& math,
                   bool use_aabb)
    : model_(model),
      n_(numerics),
      gen_(camera, model.scene_box, model.micro_res, numerics.ray_float, numerics.traversal_float),
      lo_(box_corner(model, use_aabb, false)),
      hi_(box_corner(model, use_aabb, true)),
      abt_(lo_, hi_, numerics.ray_float),
      tsps_(math, lo_, hi_) {
  // Every ray of the frame starts at the camera: the ABT's terms of it once.
  abt_origin_ = abt_.from(gen_.origin());
}

RayPacket FrontEnd::build(const PixelQuad& quad, const Vru& vru) {
  RayPacket p;
  build(quad, vru, p);
  return p;
}

void FrontEnd::build(const PixelQuad& quad, const Vru& vru, RayPacket& p) {
  const auto rays = gen_.generate(quad);
  p.reset();
  p.pixels = quad;
  bool first = true;
  for (int r = 0; r < kRaysPerPacket; ++r) {
    if (!(quad.valid_mask >> r & 1)) continue;
    RayState& s = p.rays[size_t(r)];
    ++counters_.rays;
    s.valid = true;
    s.ray = rays[size_t(r)].ray;
    s.world_dir = rays[size_t(r)].world_dir;
    vru.start(s);
    if (first) p.travel_sign = travel_sign(s.ray.dir);
    first = false;
    if (!abt_.hits(s.ray, abt_origin_)) {  // every generated ray starts at gen_.origin()
      ++counters_.rays_dropped_abt;
      continue;
    }
    const KInterval run = tsps_.search(s.ray);
    if (run.empty()) {
      ++counters_.rays_dropped_tsps;
      continue;
    }
    s.k = run.begin;
    s.k_end = run.end;
    if (encode_directions_) Tme::encode_direction(s.world_dir, model_.mlp_arch.dir_frequencies, n_, s.dir_code);
  }
}

}  // namespace edrnr::chip
