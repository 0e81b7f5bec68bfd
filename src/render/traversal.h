#pragma once
// The sampling rule of reference.h in code, and the march that finds the
// samples of a ray with or without the occupancy tiers.
//
// Candidate k of a ray sits at t_k = (k + 0.5) * delta scene units from the
// ray origin. Its point is computed in micro-grid units, always the same way:
//   p_k = o_m + d_m * t_k   (per component, float, no fused multiply-add)
// where o_m = (o - scene_box.lo) * micro_res / box size and
// d_m = d * micro_res / box size are rounded to float once per ray. The
// candidate is a sample iff micro_voxel_of(p_k) exists and is occupied. Every
// traversal decides each candidate from this p_k, so skipping can only drop
// candidates that lie in empty space.
#include <cstdint>

#include "data/camera.h"
#include "model/mlp.h"
#include "model/scene_model.h"

namespace edrnr {

// Spacing delta of candidate samples in scene units: step_micro micro-voxel
// edges along x.
float sample_spacing(const SceneModel& model, float step_micro);

// A ray in micro-grid units with its sample spacing.
struct MicroRay {
  Vec3f origin;     // o_m
  Vec3f dir;        // d_m (micro units per scene unit of t)
  float delta = 0;  // sample spacing, scene units
  float t_of(int64_t k) const { return (float(k) + 0.5f) * delta; }
  Vec3f point(int64_t k) const {
    const float t = t_of(k);
    return {origin.x + dir.x * t, origin.y + dir.y * t, origin.z + dir.z * t};
  }
};

MicroRay make_micro_ray(const SceneModel& model, const Ray& ray, float delta);

struct MarchSample {
  int64_t k = 0;  // candidate index
  Vec3f p_micro;  // its point, micro units
  Vec3i voxel;    // its (occupied) micro voxel
};

// Yields the samples of one ray in increasing k.
//
// With use_tiers: candidates are limited to the object AABB (widened to whole
// micro voxels plus one, and one step either side), and at each candidate the
// coarse, fine, leaf and micro bitmaps are read top down. At the first empty
// cell the march jumps past the ray's exit from that cell. The jump is exact:
// each coordinate of p_k is monotone in k (every float operation above is), so
// the candidates whose point lies in a given cell form one run of k; the march
// checks that the last skipped candidate is still in the cell and otherwise
// finds the end of the run by bisection.
// Without use_tiers: every candidate inside the scene box is tested against
// the micro bitmap. Both yield exactly the same samples.
class SampleMarcher {
 public:
  SampleMarcher(const SceneModel& model, const Ray& ray, const MicroRay& micro_ray, bool use_tiers);

  // The next sample; false once the ray has no more.
  bool next(MarchSample& s);
  // Bitmap lookups so far, all tiers.
  uint64_t occupancy_checks() const { return checks_; }

 private:
  // The first candidate after k (whose point lies in `cell`, cells of
  // cell_micro^3 micro voxels) whose point is not in that cell.
  int64_t skip_past_cell(int64_t k, const Vec3i& cell, int cell_micro) const;
  bool in_cell(int64_t k, const Vec3i& cell, int cell_micro) const;

  const SceneModel& model_;
  MicroRay ray_;
  bool use_tiers_;
  int64_t k_ = 0, k_end_ = -1;
  uint64_t checks_ = 0;
  Vec3i occupied_cell_[3] = {{-1, -1, -1}, {-1, -1, -1}, {-1, -1, -1}};  // last occupied coarse, fine, leaf cell
};

}  // namespace edrnr
