#include "render/traversal.h"

#include <algorithm>
#include <cmath>

namespace edrnr {

float sample_spacing(const SceneModel& model, float step_micro) {
  return step_micro * (model.scene_box.size().x / float(model.micro_res));
}

MicroRay make_micro_ray(const SceneModel& model, const Ray& ray, float delta) {
  const Vec3d lo = model.scene_box.lo.cast<double>();
  const Vec3d size = model.scene_box.size().cast<double>();
  const double R = double(model.micro_res);
  const Vec3d scale{R / size.x, R / size.y, R / size.z};
  MicroRay m;
  m.origin = ((ray.origin - lo) * scale).cast<float>();
  m.dir = (ray.dir * scale).cast<float>();
  m.delta = delta;
  return m;
}

SampleMarcher::SampleMarcher(const SceneModel& model, const Ray& ray, const MicroRay& micro_ray, bool use_tiers)
    : model_(model), ray_(micro_ray), use_tiers_(use_tiers) {
  // The candidates to consider: those whose exact ray point lies in a box one
  // micro voxel larger than the region of interest (whole micro voxels of the
  // object AABB, or the scene box), one step either side. A candidate whose
  // float point p_k lies in an occupied voxel is within float error of the
  // exact ray point, so it is always in this range.
  const Vec3d lo = model.scene_box.lo.cast<double>();
  const Vec3d vs = model.micro_voxel_size().cast<double>();
  Vec3d v_lo{0, 0, 0}, v_hi;  // region in micro units
  const double R = double(model.micro_res);
  v_hi = {R, R, R};
  if (use_tiers) {
    const Vec3d a_lo = (model.object_aabb.lo.cast<double>() - lo) / vs;
    const Vec3d a_hi = (model.object_aabb.hi.cast<double>() - lo) / vs;
    for (int a = 0; a < 3; ++a) {
      v_lo[a] = std::max(0.0, std::floor(a_lo[a]));
      v_hi[a] = std::min(R, std::ceil(a_hi[a]));
    }
  }
  const Box3d region{lo + vs * (v_lo - Vec3d{1, 1, 1}), lo + vs * (v_hi + Vec3d{1, 1, 1})};
  double t_near, t_far;
  if (!intersect_box(ray.origin, ray.dir, region, t_near, t_far) || !(t_far >= 0) || !std::isfinite(t_far) ||
      !std::isfinite(t_near))
    return;  // no candidates: k_ > k_end_
  const double delta = double(ray_.delta);
  k_ = std::max<int64_t>(0, int64_t(std::floor(std::max(t_near, 0.0) / delta - 0.5)) - 1);
  k_end_ = int64_t(std::ceil(t_far / delta - 0.5)) + 1;
}

bool SampleMarcher::in_cell(int64_t k, const Vec3i& cell, int cell_micro) const {
  Vec3i v;
  if (!micro_voxel_of(ray_.point(k), model_.micro_res, v)) return false;
  return v.x / cell_micro == cell.x && v.y / cell_micro == cell.y && v.z / cell_micro == cell.z;
}

int64_t SampleMarcher::skip_past_cell(int64_t k, const Vec3i& cell, int cell_micro) const {
  // Exit of the float ray from the cell, in scene units of t.
  double t_exit = INFINITY;
  for (int a = 0; a < 3; ++a) {
    const double o = ray_.origin[a], d = ray_.dir[a];
    if (d > 0) t_exit = std::min(t_exit, (double(cell[a] + 1) * cell_micro - o) / d);
    if (d < 0) t_exit = std::min(t_exit, (double(cell[a]) * cell_micro - o) / d);
  }
  const double k_exit = std::ceil(t_exit / double(ray_.delta) - 0.5);
  int64_t next = k_end_ + 1;
  if (k_exit < double(k_end_ + 1)) next = std::max(k + 1, int64_t(k_exit));
  if (next == k + 1 || in_cell(next - 1, cell, cell_micro)) return next;
  // The run of candidates in the cell ends before next - 1: bisect for its end.
  int64_t in = k, out = next - 1;
  while (out - in > 1) {
    const int64_t mid = in + (out - in) / 2;
    if (in_cell(mid, cell, cell_micro))
      in = mid;
    else
      out = mid;
  }
  return in + 1;
}

bool SampleMarcher::next(MarchSample& s) {
  const int R = model_.micro_res;
  const Bitmap3& micro = model_.occupancy[int(Tier::Micro)];
  while (k_ <= k_end_) {
    const int64_t k = k_;
    const Vec3f p = ray_.point(k);
    Vec3i v;
    if (!micro_voxel_of(p, R, v)) {
      k_ = k + 1;
      continue;
    }
    if (use_tiers_) {
      // Coarse (32^3 micro voxels), fine (4^3), leaf (2^3): jump past the
      // first empty cell. A cell found occupied for an earlier sample is not
      // looked up again.
      static constexpr int kCellMicro[3] = {kMicroPerFine * kFinePerCoarse, kMicroPerFine, 2};
      bool skipped = false;
      for (int t = 0; t < 3 && !skipped; ++t) {
        const int s_micro = kCellMicro[t];
        const Vec3i cell{v.x / s_micro, v.y / s_micro, v.z / s_micro};
        if (cell == occupied_cell_[t]) continue;
        ++checks_;
        if (model_.occupancy[t].get(cell.x, cell.y, cell.z)) {
          occupied_cell_[t] = cell;
        } else {
          k_ = skip_past_cell(k, cell, s_micro);
          skipped = true;
        }
      }
      if (skipped) continue;
    }
    ++checks_;
    if (!micro.get(v.x, v.y, v.z)) {
      k_ = use_tiers_ ? skip_past_cell(k, v, 1) : k + 1;
      continue;
    }
    s.k = k;
    s.p_micro = p;
    s.voxel = v;
    k_ = k + 1;
    return true;
  }
  return false;
}

}  // namespace edrnr
