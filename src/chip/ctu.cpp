#include "chip/ctu.h"

#include "chip/lfau.h"

namespace edrnr::chip {

namespace {
// Each ray's coarse voxel at candidate k, kept across the iterations of one
// RP: a ray the LFAU did not select keeps its candidate, and its point
// depends on (ray, k) only.
struct KnownCells {
  std::array<int64_t, kRaysPerPacket> k{};
  std::array<Vec3i, kRaysPerPacket> cell{};
  uint8_t valid = 0;
};

Ctu::Step coarse_step(const SceneModel& model, const RayMath& math, bool lag_first, CtuCounters& counters,
                      RayPacket& rp, CtuResult& out, KnownCells& known) {
  const uint8_t live = rp.live_mask();
  if (!live) {
    out = {};
    return Ctu::Step::Finished;
  }
  std::array<Vec3i, kRaysPerPacket> cv{};
  for (int r = 0; r < kRaysPerPacket; ++r) {
    if (!(live >> r & 1)) continue;
    const RayState& ray = rp.rays[size_t(r)];
    if (!(known.valid >> r & 1) || known.k[size_t(r)] != ray.k) {
      const Vec3i c = math.cell_at(ray.ray, ray.k, kCoarseCellMicro);
      known.cell[size_t(r)] = c;
      known.k[size_t(r)] = ray.k;
      known.valid |= uint8_t(1u << r);
      cv[size_t(r)] = c;
    } else {
      cv[size_t(r)] = known.cell[size_t(r)];
    }
  }
  const LfauSelection sel = lfau_select(cv, live, rp.travel_sign, lag_first);
  ++counters.iterations;
  counters.rays_advanced += uint64_t(sel.selected_rays());
  ++counters.coarse_checks;
  const Bitmap3& coarse = model.occupancy[int(Tier::Coarse)];
  if (coarse.get(sel.voxel.x, sel.voxel.y, sel.voxel.z)) {
    out.found = true;
    out.cv_tag = linear_index(sel.voxel.x, sel.voxel.y, sel.voxel.z, coarse.res());
    out.ray_mask = sel.selected_mask;
    ++counters.candidates;
    return Ctu::Step::Found;
  }
  for (int r = 0; r < kRaysPerPacket; ++r) {
    if (!(sel.selected_mask >> r & 1)) continue;
    RayState& ray = rp.rays[size_t(r)];
    ray.k = math.cell_exit(ray.ray, ray.k, ray.k_end, sel.voxel, kCoarseCellMicro, &counters.position_evals);
  }
  return Ctu::Step::Advanced;
}
}  // namespace

Ctu::Ctu(const SceneModel& model, const RayMath& math, bool lag_first)
    : model_(model), math_(math), lag_first_(lag_first) {}

Ctu::Step Ctu::step(RayPacket& rp, CtuResult& out) {
  KnownCells known;
  return coarse_step(model_, math_, lag_first_, counters_, rp, out, known);
}

CtuResult Ctu::run(RayPacket& rp) {
  CtuResult out;
  KnownCells known;
  while (coarse_step(model_, math_, lag_first_, counters_, rp, out, known) == Step::Advanced) {
  }
  return out;
}

}  // namespace edrnr::chip
