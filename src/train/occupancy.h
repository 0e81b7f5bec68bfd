#pragma once
// The training-time occupancy grid at the micro resolution (Instant-NGP /
// nerfacc style): a decayed running maximum of the density per micro voxel,
// refreshed a part at a time, thresholded into the micro bitmap; plus the
// object AABB taken from the Gaussian-filtered occupancy, outside which
// nothing is occupied.
#include <cstdint>
#include <vector>

#include "core/vec.h"
#include "model/scene_model.h"

namespace edrnr::train {

inline constexpr int kSweepParts = 8;  // cells are refreshed in 8 interleaved parts (coordinate parities)

struct OccupancyGrid {
  int res = 0;
  std::vector<float> density;  // running max of sigma per micro voxel; < 0: not evaluated yet
  Bitmap3 micro;               // occupancy, res^3
  Bitmap3 fine;                // OR of 4^3 micro voxels (the fine tier)
  // Changes (to a value no grid had before) whenever rebuild_macro runs, so
  // that what is derived from the bitmaps can tell when to derive it again.
  uint64_t generation = 0;
  bool aabb_known = false;
  Vec3i aabb_lo{0, 0, 0}, aabb_hi{0, 0, 0};  // inclusive micro voxel bounds of the object AABB

  explicit OccupancyGrid(int micro_res = 0);

  bool occupied(int x, int y, int z) const { return micro.get(x, y, z); }
  // Micro voxels in sweep part p, in linear (x fastest) order.
  static bool in_part(int x, int y, int z, int part) { return ((x & 1) | ((y & 1) << 1) | ((z & 1) << 2)) == part; }

  // Mean density over evaluated voxels.
  double mean_density() const;
  // Rebuilds the micro and fine bitmaps: occupied iff not yet evaluated or
  // density > threshold, and inside the AABB when it is known.
  void rebuild(float threshold);
  // Rebuilds the fine bitmap from the micro bitmap; a new generation.
  void rebuild_macro();
  // Recomputes the AABB from the occupancy (density > threshold or not yet
  // evaluated, ignoring the current AABB) filtered by a Gaussian of
  // filter_sigma voxels, keeping voxels whose filtered value >= keep. Returns
  // false (AABB unchanged) if nothing is kept.
  bool update_aabb(float threshold, float filter_sigma, float keep);
};

// Empties the connected parts (26-neighbour) of the occupied micro voxels
// that hold fewer than min_fraction of the largest part's voxels and lie
// wholly outside the box around the larger parts: floaters away from the
// object, which would otherwise widen its AABB. Small parts inside or
// touching that box stay (fine detail of the object). Deterministic.
// Returns the number of micro voxels emptied; min_fraction <= 0: none.
size_t drop_outlying_parts(Bitmap3& micro, float min_fraction);

// Separable Gaussian filter of a res^3 grid (x fastest), zero outside.
std::vector<float> gaussian_filter3(const std::vector<float>& grid, int res, float sigma_voxels);

}  // namespace edrnr::train
