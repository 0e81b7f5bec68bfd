#pragma once
// What the fast march's kernels (fast_march_kernels.cpp, fast_setup_kernels.cpp)
// share: the model's tables they read, and the scalar voxel and box helpers.
#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "core/vec.h"

namespace edrnr::fast_march_detail {

// What the march reads of the model, the same for all marchers of a render.
struct Grid {
  const uint32_t* words;  // FastSkipGrid::fine_words (kCellWords per fine voxel)
  const uint8_t* reach;   // FastSkipGrid::reach
  int micro_res, fine_res;
  float hi;  // micro_res as a float: the largest coordinate inside the grid
};

// micro_voxel_of (model/mlp.h) without a floor call: for the non-negative
// coordinates it accepts, truncation is floor.
inline bool VoxelOf(const Vec3f& p, const Grid& g, Vec3i& v) {
  if (!(p.x >= 0.f && p.x <= g.hi && p.y >= 0.f && p.y <= g.hi && p.z >= 0.f && p.z <= g.hi)) return false;
  v.x = std::min(int(p.x), g.micro_res - 1);
  v.y = std::min(int(p.y), g.micro_res - 1);
  v.z = std::min(int(p.z), g.micro_res - 1);
  return true;
}

inline size_t FineIndex(const Vec3i& v, int fine_res) {
  return size_t(v.x >> 2) + size_t(fine_res) * (size_t(v.y >> 2) + size_t(fine_res) * size_t(v.z >> 2));
}

// The box skip_box jumps from micro voxel v, whose fine voxel has reach e:
// the fine voxel's micro voxels widened by e.
inline Vec3i ReachLo(const Vec3i& v, int e) {
  return Vec3i{4 * (v.x >> 2) - e, 4 * (v.y >> 2) - e, 4 * (v.z >> 2) - e};
}

}  // namespace edrnr::fast_march_detail
