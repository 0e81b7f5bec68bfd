#pragma once
// The fast renderer's march: exactly the samples of SampleMarcher
// (render/traversal.h: the same candidates k, the same float points p_k, the
// same range of k inside the widened object AABB), found with less work.
//
//   - Empty space is skipped a box at a time: FastSkipGrid holds, per fine
//     voxel, its reach e: how many micro voxels its box can be widened by on
//     every side and stay empty (far from the object e = 4 (r - 1) for the
//     Chebyshev distance r in fine voxels, capped; near it the exact micro
//     gap), so a ray at an empty fine voxel jumps past that box. This stands
//     in for the coarse and fine tiers (a coarse cell is empty iff its fine
//     voxels are), with few steps through large empty regions, and jumps a
//     few micro voxels past the empty fine voxels next to the object.
//   - From a candidate in a fine voxel with reach 0 (occupied, or touching
//     an occupied micro voxel) on, a SIMD vector of consecutive
//     candidates (16 with AVX-512) is tested at once: points, micro voxels
//     and one gather from 64-bit masks of the fine voxels' 4x4x4 micro voxels
//     (the leaf and micro tiers in one bit), with no branch per candidate.
//     The samples found are handed out in order.
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
#include "render/fast_kernels.h"
#include "render/traversal.h"

namespace edrnr {

// Chebyshev distances of the fine voxels to the nearest occupied one, and
// the micro occupancy of every fine voxel as a 64-bit mask.
struct FastSkipGrid {
  static constexpr int kMaxDistance = 15;  // cap, fine voxels
  static constexpr int kExactReach = 2;    // distance up to which reach is the exact micro gap (capped)
  int res = 0;                             // fine resolution
  int micro_res = 0;                       // micro resolution (4 res)
  Box3d region;  // scene units: the object AABB's micro voxels widened by one, where candidates are considered
  // Per fine voxel: 0: occupied; r: every fine voxel within r - 1 is empty.
  // Followed by 3 bytes of padding, so that a 32-bit read at any voxel stays inside.
  std::vector<uint8_t> distance;
  // Per fine voxel f (linear index x + res (y + res z)) kCellWords 32-bit
  // words, all in one 16-byte run: bit lx + 4 ly + 16 (lz & 1) of word
  // kCellWords f + (lz >> 1) is set iff micro voxel (lx, ly, lz) of it is
  // occupied (the 64-bit mask of its 4x4x4 micro voxels, low half first);
  // word kCellWords f + kCellBlock: its feature block (model.fine_to_block,
  // as int32), + kCellMlp: its coarse voxel's MLP (model.coarse_to_mlp), both
  // -1 for an empty fine voxel. A sample's block and MLP then come from the
  // cache line the occupancy test read.
  static constexpr int kCellWords = 4, kCellBlock = 2, kCellMlp = 3;
  std::vector<uint32_t> fine_words;
  // Per fine voxel: 0 if occupied; else e, in micro voxels, such that the
  // box of the fine voxel's 4x4x4 micro voxels widened by e on every side
  // holds no occupied micro voxel (per fine_words): the Chebyshev gap to the
  // nearest one, capped at 4 r for fine voxels at distance r <= kExactReach,
  // and 4 (r - 1) beyond (exact gaps up to r = 3 saved 0.3 % of the lookups
  // on lego). Padded like `distance`.
  std::vector<uint8_t> reach;

  // Built from the fine and micro tiers of a model (check_structure()d).
  explicit FastSkipGrid(const SceneModel& model);
  // Built from occupancy alone (the trainer's): fine and micro bitmaps of
  // res and 4 res, the fine one the OR of the micro one's 4x4x4 cubes. No
  // fine voxel has a block or an MLP (their words are -1), and `region` is
  // empty: marchers are set up with FastMarcher::set_up_range.
  FastSkipGrid(const Bitmap3& fine, const Bitmap3& micro);
  FastSkipGrid() = default;
  uint8_t at(int x, int y, int z) const { return distance[size_t(x) + size_t(res) * (size_t(y) + size_t(res) * z)]; }

 private:
  // distance, fine_words (block and MLP words -1) and reach from the two tiers.
  void build(const Bitmap3& fine, const Bitmap3& micro);
};

class FastMarcher {
 public:
  FastMarcher(const SceneModel& model, const FastSkipGrid& skip, const Ray& ray, const MicroRay& micro_ray);
  // A marcher without candidates, to be set up (set_up, or fast_setup_rays).
  FastMarcher() = default;

  // What the constructor does, on an existing marcher.
  void set_up(const SceneModel& model, const FastSkipGrid& skip, const Ray& ray, const MicroRay& micro_ray);
  // A fresh march of micro_ray over the candidates [k, k_end] (k_end < k:
  // none) of skip's occupancy, without a model: the samples are the
  // candidates in occupied micro voxels, as any march gives them, and
  // block() is -1. (The trainer's march: its range is its own.)
  void set_up_range(const FastSkipGrid& skip, const MicroRay& micro_ray, int64_t k, int64_t k_end);
  // A fresh march of micro_ray over candidates [k, k_end] with skip_box's
  // terms per axis (State::exit, scale, offset), computed by the caller as
  // set_up does.
  void assign(const SceneModel& model, const FastSkipGrid& skip, const MicroRay& micro_ray, int64_t k, int64_t k_end,
              const double exit[3], const double scale[3], const double offset[3]) {
    assign(&model, skip, micro_ray, k, k_end, exit, scale, offset);
  }
  // A marcher of `model` without candidates (empty(), no occupancy checks);
  // the ray and the jump terms it held stay, unread (a march of it ends at
  // once).
  void clear(const SceneModel& model, const FastSkipGrid& skip) {
    st_.model = &model;
    st_.skip = &skip;
    st_.k = 0;
    st_.k_end = -1;
    st_.pending = 0;
    st_.checks = 0;
  }

  // The next sample; false once the ray has no more.
  bool next(MarchSample& s);
  // Distance lookups plus candidates tested against the micro masks, so far.
  uint64_t occupancy_checks() const { return st_.checks; }
  // Whether the ray has no candidates at all (it misses the region, or the
  // region lies behind it); known from construction on.
  bool empty() const { return st_.k_end < st_.k && st_.pending == 0; }
  // The feature block of the last sample's fine voxel (-1: none; the model
  // then breaks its invariants).
  int32_t block() const { return st_.block; }

  // What the march kernel (fast_march_group) reads and advances; no other
  // code touches it.
  struct State {
    const SceneModel* model = nullptr;  // null after set_up_range
    const FastSkipGrid* skip = nullptr;
    MicroRay ray;
    // skip_box's terms per axis: the exit face (0 or 1), 1 / (d_a delta) and
    // (-/+ margin - o_a) / (d_a delta) - 0.5.
    double exit[3] = {0, 0, 0}, scale[3] = {0, 0, 0}, offset[3] = {0, 0, 0};
    int64_t k = 0, k_end = -1;  // next candidate to consider; the last one
    int64_t chunk_k = 0;        // first candidate of the last chunk tested
    uint32_t pending = 0;       // its samples not handed out yet: bit i for candidate chunk_k + i
    bool dense = false;         // the last chunk tested held a sample: test the next one without a lookup
    int32_t block = -1;
    uint64_t checks = 0;
    // The last chunk's samples in order, as the vector test found them (the
    // candidate of the lowest pending bit first): its point's position in its micro
    // voxel v (p - v per axis: exact, so v + f is p), the fine voxel index
    // (its block and MLP: FastSkipGrid::fine_words) and the micro voxel's
    // block vertex (lx + 5 (ly + 5 lz)); entries [found_next, found_next +
    // popcount(pending)) are pending. (The renderer's records need no v: the
    // sample path finds it from the point again.)
    static constexpr int kMaxChunk = 16;
    int found_next = 0;
    alignas(64) float found_f[3][kMaxChunk];
    alignas(64) int32_t found_fine[kMaxChunk];
    alignas(64) int32_t found_vertex[kMaxChunk];

    // A candidate after k (whose point lies in the box of `size` micro
    // voxels from micro voxel `lo`) such that every candidate between them
    // lies in the box: the last one whose exact ray point is at least the
    // margin inside it.
    int64_t skip_box(int64_t k0, const Vec3i& lo, int size) const {
      // x_a: the candidate position j (t = (j + 0.5) delta) at which the
      // exact line o_m + d_m t is the margin inside the box's exit face on
      // axis a; exit[a] selects the face (1: lo + size, 0: lo); axes the ray
      // does not move along give +inf (scale 0, offset +inf). Candidates up
      // to min_a x_a have float points in the box (their rounding error is
      // below the margin), those from k0 on entered it already (each
      // coordinate is monotone in k), so all of them can be skipped without
      // computing one.
      const double x0 = (double(lo.x) + double(size) * exit[0]) * scale[0] + offset[0];
      const double x1 = (double(lo.y) + double(size) * exit[1]) * scale[1] + offset[1];
      const double x2 = (double(lo.z) + double(size) * exit[2]) * scale[2] + offset[2];
      const double x = std::min(x0, std::min(x1, x2));  // candidates j <= x are inside
      if (!(x < double(k_end))) return k_end + 1;
      const double xc = std::max(x, -4e18);
      const int64_t t = int64_t(xc);                        // toward zero
      const int64_t floor_x = t - int64_t(xc < double(t));  // floor
      return std::max(k0 + 1, floor_x + 1);
    }
  };
  State& state() { return st_; }

 private:
  // assign, the model null for set_up_range.
  void assign(const SceneModel* model, const FastSkipGrid& skip, const MicroRay& micro_ray, int64_t k, int64_t k_end,
              const double exit[3], const double scale[3], const double offset[3]) {
    st_.model = model;
    st_.skip = &skip;
    st_.ray = micro_ray;
    for (int a = 0; a < 3; ++a) {
      st_.exit[a] = exit[a];
      st_.scale[a] = scale[a];
      st_.offset[a] = offset[a];
    }
    st_.k = k;
    st_.k_end = k_end;
    st_.chunk_k = 0;
    st_.pending = 0;
    st_.dense = false;
    st_.block = -1;
    st_.checks = 0;
    st_.found_next = 0;
  }

  State st_;
};

// Fine voxels whose reach (FastSkipGrid::reach) is at least this many micro
// voxels are jumped past (the fine voxel widened by its reach); from the
// others on (occupied fine voxels, and empty ones touching an occupied micro
// voxel) the candidates are tested a vector at a time. Thresholds 2, 4 and 8
// (8: the fine-voxel cubes only) were slower on lego.
inline constexpr int kFastJumpReach = 1;

// The most marchers fast_march_group advances together.
inline constexpr int kFastMarchGroup = 4;

// Advances marchers[i], i < n <= kFastMarchGroup, with their iterations
// interleaved, until each has `limit` more samples or has ended: sample j of
// marcher i (and its block()) goes to samples[i * limit + j] (blocks[...]),
// counts[i] says how many, ended[i] whether its march has ended (no samples
// left). SIMD (render/fast_march_kernels.cpp): empty fine voxels are skipped
// by the distance field; from a candidate in an occupied fine voxel on, a
// vector of consecutive candidates is tested against the micro masks at once.
void fast_march_group(FastMarcher* const* marchers, int n, int limit, MarchSample* samples, int32_t* blocks,
                      int* counts, bool* ended);

// fast_march_group with the samples written as the renderer's records
// (FastSample, render/fast_kernels.h): ray rays[i], the MLP of the coarse
// voxel (model.coarse_to_mlp), block * 125 + the micro voxel's block vertex
// (model.fine_to_block), and the point's position in the micro voxel. Up to
// `limit` samples of marcher i are handed out; records[i * limit + j], j <
// counts[i], are those whose coarse voxel has an MLP and whose fine voxel
// has a block (the others, which a valid model does not have, are added to
// *missing).
void fast_march_records(FastMarcher* const* marchers, const uint32_t* rays, int n, int limit, FastSample* records,
                        int* counts, bool* ended, uint64_t* missing);

// The marchers of n rays of a tile: ray r < n through the centre of pixel
// (x0 + r % tw, y0 + r / tw). marchers[r] ends up as set_up(model, skip,
// camera.pixel_ray(...), make_micro_ray(model, ray, delta)) leaves it, bit for
// bit (or, if no candidate is left, empty with the same occupancy checks),
// with the per-ray divisions and square roots in SIMD lanes (rays with a
// zero or tiny direction component, or candidate indices from 2^51 on, take
// set_up itself), and then advanced in the lanes through the empty space in
// front of the object: the march's jumps from fine voxels with a reach of
// kFastJumpReach or more (and its single steps past candidates outside the
// grid) are made there until a candidate with a shorter reach, exactly as the march would
// make them (the same candidates, the same occupancy_checks count); the
// vector test from that candidate is left to the march (marked dense: it
// makes no second lookup). Also writes the unit
// direction as floats (dx, dy, dz)[r], and hit_aabb[r]: whether the march has
// candidates and the ray meets `aabb` (intersect_box) with t_far >= 0.
//
// t_start[r] (scene units along the unit ray, >= 0; null: 0 for all) is
// where ray r may start looking (tile_start_distances): the lanes' marches
// begin at the candidate before it if that is later than their own first one
// (the rays set up by set_up ignore it). The candidates skipped lie before
// t_start by at least one step, where, for the distances
// tile_start_distances gives, no sample can be, so the samples are the same;
// the jumps and lookups (occupancy_checks) are fewer. hit_aabb does not
// depend on it.
void fast_setup_rays(const SceneModel& model, const FastSkipGrid& skip, const Camera& camera, float delta,
                     const Box3d& aabb, int x0, int y0, int tw, int n, const double* t_start, FastMarcher* marchers,
                     float* dx, float* dy, float* dz, bool* hit_aabb);

// For the image cut into tiles of `tile` pixels (tiles_x by tiles_y, row
// by row), a distance from the camera along the unit pixel rays of each tile
// before which none of those rays meets an occupied fine voxel widened by one
// micro voxel on every side: the least distance from the camera to such a
// box whose projection, widened by a pixel, meets the tile (a box the
// camera does not see wholly in front of it counts for every tile); +inf for
// a tile no box meets. Samples lie in occupied micro voxels, so no ray has a
// sample before its tile's distance, and none at all in a tile at +inf.
// Made on `threads` threads (OpenMP); the result does not depend on them.
std::vector<double> tile_start_distances(const SceneModel& model, const FastSkipGrid& skip, const Camera& camera,
                                         int tile, int tiles_x, int tiles_y, int threads = 1);

}  // namespace edrnr
