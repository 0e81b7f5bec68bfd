#pragma once
// The fast renderer's march: exactly the samples of SampleMarcher
// (render/traversal.h: the same candidates k, the same float points p_k, the
// same range of k inside the widened object AABB), found with less work.
//
//   - Empty fine voxels are skipped a cube at a time: FastSkipGrid holds, per
//     fine voxel, its Chebyshev distance (in fine voxels, capped) to the
//     nearest occupied one, so a ray at an empty fine voxel at distance r
//     jumps past the cube of (2r - 1)^3 fine voxels around it, all empty. This
//     stands in for the coarse and fine tiers (a coarse cell is empty iff its
//     fine voxels are), with fewer steps through large empty regions.
//   - Inside an occupied fine voxel the leaf and micro tiers are read from a
//     64-bit mask of its 4x4x4 micro voxels (8 bytes per block, the chip's
//     micro-grid bitmap), loaded once when the ray enters the fine voxel, so
//     these checks are register bit tests instead of reads of the 2 MiB
//     micro bitmap.
//   - A jump goes to the last candidate whose exact ray point is still a
//     margin inside the empty box (exit distance from the ray's inverse
//     direction). The margin bounds the rounding error of the float points
//     p_k, and every coordinate of p_k is monotone in k, so all the skipped
//     candidates lie in the box: no sample is ever skipped, and no candidate
//     needs computing to check the jump. The candidate reached may still be
//     in the box; it is then tested like any other.
#include <algorithm>
#include <cstdint>
#include <vector>

#include "data/camera.h"
#include "model/scene_model.h"
#include "render/traversal.h"

namespace edrnr {

// Chebyshev distances of the fine voxels to the nearest occupied fine voxel.
struct FastSkipGrid {
  static constexpr int kMaxDistance = 15;  // cap, fine voxels
  int res = 0;                             // fine resolution
  Box3d region;  // scene units: the object AABB's micro voxels widened by one, where candidates are considered
  std::vector<uint8_t> distance;  // 0: occupied; r: every fine voxel within r - 1 is empty
  // Per feature block: bit lx + 4 ly + 16 lz set iff micro voxel (lx, ly, lz)
  // of its fine voxel is occupied.
  std::vector<uint64_t> micro_mask;

  // Built from the fine tier of a model (check_structure()d).
  explicit FastSkipGrid(const SceneModel& model);
  FastSkipGrid() = default;
  uint8_t at(int x, int y, int z) const { return distance[size_t(x) + size_t(res) * (size_t(y) + size_t(res) * z)]; }
};

class FastMarcher {
 public:
  FastMarcher(const SceneModel& model, const FastSkipGrid& skip, const Ray& ray, const MicroRay& micro_ray);

  // The next sample; false once the ray has no more.
  bool next(MarchSample& s);
  // One candidate of the march: End (no more), Sample (s filled) or More.
  enum class Step { More, Sample, End };
  Step step(MarchSample& s);
  // Bitmap and distance lookups so far.
  uint64_t occupancy_checks() const { return checks_; }
  // The feature block of the last sample's fine voxel (-1: none; the model
  // then breaks its invariants).
  int32_t block() const { return block_; }

 private:
  // The micro mask of an occupied fine voxel read from the micro bitmap
  // (for fine voxels without a feature block).
  uint64_t mask_from_bitmap(const Vec3i& fine) const;
  // A candidate after k (whose point lies in the box of `size` micro voxels
  // from micro voxel `lo`) such that every candidate between them lies in the
  // box: the last one whose exact ray point is at least margin_ inside it.
  int64_t skip_box(int64_t k, const Vec3i& lo, int size) const {
    // x_a: the candidate position j (t = (j + 0.5) delta) at which the exact
    // line o_m + d_m t is margin_ inside the box's exit face on axis a;
    // exit_[a] selects the face (1: lo + size, 0: lo); axes the ray does not
    // move along give +inf (scale_ 0, offset_ +inf). Candidates up to min_a
    // x_a have float points in the box (their rounding error is below
    // margin_), those from k on entered it already (each coordinate is
    // monotone in k), so all of them can be skipped without computing one.
    const double x0 = (double(lo.x) + double(size) * exit_[0]) * scale_[0] + offset_[0];
    const double x1 = (double(lo.y) + double(size) * exit_[1]) * scale_[1] + offset_[1];
    const double x2 = (double(lo.z) + double(size) * exit_[2]) * scale_[2] + offset_[2];
    const double x = std::min(x0, std::min(x1, x2));  // candidates j <= x are inside
    if (!(x < double(k_end_))) return k_end_ + 1;
    const double xc = std::max(x, -4e18);
    const int64_t t = int64_t(xc);                        // toward zero
    const int64_t floor_x = t - int64_t(xc < double(t));  // floor
    return std::max(k + 1, floor_x + 1);
  }

  const SceneModel* model_;
  const FastSkipGrid* skip_;
  MicroRay ray_;
  // skip_box's terms per axis: the exit face (0 or 1), 1 / (d_a delta) and
  // (-/+ margin - o_a) / (d_a delta) - 0.5.
  double exit_[3] = {0, 0, 0}, scale_[3] = {0, 0, 0}, offset_[3] = {0, 0, 0};
  double margin_ = 0;        // micro units: well above the rounding error of a candidate's float point
  bool small_step_ = false;  // empty leaf cells and micro voxels are passed by stepping
  int64_t k_ = 0, k_end_ = -1;
  uint64_t checks_ = 0;
  Vec3i fine_{-1, -1, -1};  // the occupied fine voxel the ray is in
  int32_t block_ = -1;      // its block
  uint64_t mask_ = 0;       // its micro mask
};

// The most marchers fast_march_group advances together.
inline constexpr int kFastMarchGroup = 4;

// Advances marchers[i], i < n <= kFastMarchGroup, with their iterations
// interleaved, until each has `limit` more samples or has ended: sample j of
// marcher i (and its block()) goes to samples[i * limit + j] (blocks[...]),
// counts[i] says how many, ended[i] whether its march ended.
void fast_march_group(FastMarcher* const* marchers, int n, int limit, MarchSample* samples, int32_t* blocks,
                      int* counts, bool* ended);

}  // namespace edrnr
