#include "chip/ctu.h"

#include "chip/lfau.h"

namespace edrnr::chip {

Ctu::Ctu(const SceneModel& model, const RayMath& math, bool lag_first)
    : model_(model), math_(math), lag_first_(lag_first) {}

Ctu::Step Ctu::step(RayPacket& rp, CtuResult& out) {
  const uint8_t live = rp.live_mask();
  if (!live) {
    out = {};
    return Step::Finished;
  }
  std::array<Vec3i, kRaysPerPacket> cv{};
  for (int r = 0; r < kRaysPerPacket; ++r)
    if (live >> r & 1) cv[size_t(r)] = math_.cell_at(rp.rays[size_t(r)].ray, rp.rays[size_t(r)].k, kCoarseCellMicro);
  const LfauSelection sel = lfau_select(cv, live, rp.travel_sign, lag_first_);
  ++counters_.iterations;
  counters_.rays_advanced += uint64_t(sel.selected_rays());
  ++counters_.coarse_checks;
  const Bitmap3& coarse = model_.occupancy[int(Tier::Coarse)];
  if (coarse.get(sel.voxel.x, sel.voxel.y, sel.voxel.z)) {
    out.found = true;
    out.cv_tag = linear_index(sel.voxel.x, sel.voxel.y, sel.voxel.z, coarse.res());
    out.ray_mask = sel.selected_mask;
    ++counters_.candidates;
    return Step::Found;
  }
  for (int r = 0; r < kRaysPerPacket; ++r) {
    if (!(sel.selected_mask >> r & 1)) continue;
    RayState& ray = rp.rays[size_t(r)];
    ray.k = math_.cell_exit(ray.ray, ray.k, ray.k_end, sel.voxel, kCoarseCellMicro, &counters_.position_evals);
  }
  return Step::Advanced;
}

CtuResult Ctu::run(RayPacket& rp) {
  CtuResult out;
  while (step(rp, out) == Step::Advanced) {
  }
  return out;
}

}  // namespace edrnr::chip
