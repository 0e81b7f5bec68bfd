#pragma once
// Highway kernels of the block features (train/feature_grid.h): rows of F
// float channels, one row per block vertex, handled a SIMD vector at a time
// (runtime dispatch: one binary, AVX-512 where the CPU has it).
//
// Determinism: every lane does the scalar loop's IEEE operations in the
// scalar loop's order (a product, then a sum: never fused), so the results
// are the same bits on every target and equal to the scalar forms below.
#include <cstddef>
#include <cstdint>

#include "train/adam.h"

namespace edrnr::train {

// out[k] = sum over c = 0..7, in that order, of w[c] * rows[c][k], k < F
// (the sum starts from 0).
void feature_blend_rows(const float* const rows[8], const float w[8], size_t F, float* out);

// feature_blend_rows of the rows as the INT4 export stores them: each value
// through its channel's Int4Channel::fake (quantize, then dequantize), given
// as scale[k], inv_scale[k] and zero_point[k] (a float holding the integer).
void feature_blend_rows_fake_quant(const float* const rows[8], const float w[8], size_t F, const float* scale,
                                   const float* inv_scale, const float* zero_point, float* out);

// For each c = 0..7: grad[c][k] += w[c] * g[k] for k < F. Returns a mask
// with bit c set when row c was all zeros before and is not all zeros after
// (the row has just been touched). Rows must not overlap.
uint32_t feature_scatter_rows(float* const grad[8], const float w[8], const float* g, size_t F);

// One Adam step (AdamStep::update) of every row listed: for vertex list[i]
// the F parameters from list[i] * F in p, m, v, g; the gradients are zeroed.
void feature_adam_rows(float* p, float* m, float* v, float* g, const int32_t* list, size_t n, size_t F,
                       const AdamStep& step);

}  // namespace edrnr::train
