#pragma once
// Highway kernels of the training-time occupancy grid (train/occupancy.h) and
// of its refresh (Trainer::State::refresh_occupancy_part), compiled for every
// SIMD target and picked at run time (HWY_DYNAMIC_DISPATCH).
//
// Determinism: every lane does the scalar forms' IEEE operations in their
// order (products and sums, never fused), and sums across values follow the
// fixed order written below, so the results are the same bits on every target.
#include <cstddef>
#include <cstdint>

#include "train/mlp_kernels.h"

namespace edrnr::train {

// Sum (in double) and count of the values d[i] >= 0, i < n (NaN and negative
// values are left out). Value i is added to partial sum i % 8, in increasing
// i; the 8 partial sums are then added in order 0..7, starting from 0.
void occupancy_sum_nonnegative(const float* d, size_t n, double* sum, size_t* count);

// words[w] bit b = (d[64 w + b] < 0) || (d[64 w + b] > threshold), w < n_words.
void occupancy_threshold_words(const float* d, size_t n_words, float threshold, uint64_t* words);

// One level of a FeaturePyramid (train/feature_grid.h) as the refresh reads
// it: (res + 1)^3 vertices of 4 channels, x fastest.
struct PyramidLevelView {
  const float* value = nullptr;
  int res = 0;    // cells per axis
  int shift = 0;  // log2(micro_res / res)
  bool active = true;
};

// The features of the cells x_first + 2 i, i < nl <= kLanes, of micro row
// (y, z), each at its micro position (px[i], py[i], pz[i]) inside its cell,
// into x0[c * kLanes + i] for c < 4 * n_levels (level by level, 4 channels
// each); lanes from nl on are zero. Lane i's channels are the bits of
// FeaturePyramid::interpolate(p_i, {x_first + 2 i, y, z}): an inactive level
// reads zero.
void refresh_interpolate_row(const PyramidLevelView* levels, int n_levels, int x_first, int y, int z, int nl,
                             const float* px, const float* py, const float* pz, float* x0);

}  // namespace edrnr::train
