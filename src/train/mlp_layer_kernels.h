#pragma once
// The training MLP's layer kernels (train/mlp_kernels.h's chunks of kLanes
// samples, activations neuron-major [neuron][lane]), through Highway with
// runtime dispatch: the widest SIMD target the CPU has runs, and every target
// gives the same bits (the same operations per lane, in the same order).
#include "train/mlp_kernels.h"

namespace edrnr::train {

// y[o][:] = b[o] + sum_i W[o][i] x[i][:], inputs summed in index order; with
// relu, lanes not above 0 (a NaN too) are 0. W is row-major [out][in].
void mlp_layer_forward(const float* W, const float* b, int in, int out, const float* x, float* y, bool relu);

// Parameter gradients: gW[o][i] += sum over lanes of dy[o] x[i], gb[o] += sum
// over lanes of dy[o]; each lane sum in one fixed order (the four runs of 8
// lanes added lane by lane, then a pairwise tree over the 8).
void mlp_layer_param_grad(const float* x, const float* dy, int in, int out, float* gW, float* gb);

// dx[i][:] = sum_o W[o][i] dy[o][:], outputs in index order; with mask, lanes
// where mask[i] is not above 0 (an inactive ReLU) are 0.
void mlp_layer_input_grad(const float* W, int in, int out, const float* dy, const float* mask, float* dx);

// quantize_block (train/mlp_kernels.h) is defined with these kernels.

}  // namespace edrnr::train
