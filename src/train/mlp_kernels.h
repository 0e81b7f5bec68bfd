#pragma once
// Batched forward and backward passes of the per-CV MLP (scene_model.h) for
// training. Samples are processed in chunks of kLanes; every activation block
// is neuron-major ([neuron][lane]) so that the inner loops run across lanes
// and vectorize. Lanes past the chunk's sample count are padding: their
// inputs should be zero and their output gradients must be zero, so they add
// nothing to any parameter gradient.
//
// Determinism: every sum runs in a fixed order (inputs in index order, lanes
// in a fixed pairwise tree), and lane arithmetic is element-wise, so the
// results are the same bits whichever SIMD target Highway's runtime dispatch
// picks (train/mlp_layer_kernels.h: SSE2 to AVX-512).
#include <cstddef>
#include <cstdint>
#include <vector>

#include "model/scene_model.h"

namespace edrnr::train {

inline constexpr int kLanes = 32;

// Where each layer's weights (row-major [out][in]) and biases sit in one flat
// parameter vector: density layers first, then colour layers.
struct MlpLayout {
  struct Layer {
    int in = 0, out = 0;
    size_t w = 0, b = 0;  // offsets into the parameter vector
  };
  MlpArch arch;
  std::vector<Layer> density, color;
  size_t param_count = 0;
  int density_act_floats = 0;  // sum of density layer widths: activation floats per lane
  int color_act_floats = 0;    // the same for the colour net
  int max_width = 0;           // widest layer input or output

  // Throws Error unless the colour net's input is geo outputs + direction encoding.
  explicit MlpLayout(const MlpArch& arch);
  int feature_dims() const { return arch.feature_channels(); }
  int geo_dims() const { return arch.geo_width(); }
  int dir_dims() const { return arch.dir_dims(); }
};

// Float MLP <-> flat parameters.
std::vector<float> flatten_mlp(const MlpLayout& layout, const MlpF& mlp);
MlpF unflatten_mlp(const MlpLayout& layout, const float* params);

// Fresh parameters: uniform weights in +-sqrt(6 / in) for layers followed by a
// ReLU and +-sqrt(3 / in) for output layers, zero biases. Deterministic in seed.
void init_mlp_params(const MlpLayout& layout, uint64_t seed, float* params);

// INT8 weight quantization, per output row, symmetric: scale = max|row| / 127
// (1 for an all-zero row), q = clamp(round(w / scale), -127, 127).
float int8_row_scale(const float* row, int n);
int8_t int8_quantize(float w, float scale);

// Writes the parameters a quantized MLP stands for (weights q * scale, biases
// unchanged): the forward weights of quantization-aware training.
void fake_quantize_mlp(const MlpLayout& layout, const float* params, float* out);

// Cross-layer equalization: for every ReLU hidden unit j (between layer l and
// layer l + 1 of either net), row j of layer l (weights and bias) is divided
// by s_j and column j of layer l + 1 multiplied by s_j, s_j = (g / c_j)^strength
// where c_j is column j's largest |weight| and g the geometric mean of the
// layer's nonzero c_j (s_j clamped to 2^-8 .. 2^8). ReLU(x / s) = ReLU(x) / s,
// so the MLP computes the same function (up to float rounding), but the
// columns of layer l + 1 have more even ranges, which per-row INT8 scales
// quantize with less error. strength 0 changes nothing, 1 equalizes fully.
// Adam moments (m, v; may be null) are rescaled as the gradients are:
// a parameter multiplied by s has its gradient divided by s.
void equalize_mlp(const MlpLayout& layout, float strength, float* params, float* adam_m, float* adam_v);

// Layer k of a quantized MLP in the layout's order: density layers, then colour.
inline DenseQ& mlp_layer(MlpQ& q, size_t k) {
  return k < q.density.size() ? q.density[k] : q.color[k - q.density.size()];
}

// The INT8 MLP. layer_in_max_abs holds, per layer (density then colour), the
// largest |input| seen; in_scale = that / 127 (1 when zero).
MlpQ quantize_mlp(const MlpLayout& layout, const float* params, const std::vector<float>& layer_in_max_abs);

// Forward pass of one net (`layers` = layout.density or layout.color) over a
// chunk. x0: [layers[0].in][kLanes]. acts: every layer's output in turn
// ([out][kLanes] each; hidden layers after ReLU, the last layer linear).
// last_rows >= 0 computes only the first last_rows outputs of the last layer
// (the rest of its block is left untouched), e.g. 1 for the raw density alone.
// With in_steps (one step per layer of the net), each hidden layer's output
// is rounded to the next layer's INT8 input step (quantize_block, [0, 127]
// steps after the ReLU), as the chip's datapath rounds it; x0 is used as
// given (the caller rounds it). Backward passes treat the rounding as the
// identity (straight-through).
void net_forward(const std::vector<MlpLayout::Layer>& layers, const float* params, const float* x0, float* acts,
                 int last_rows = -1, const float* in_steps = nullptr);

// The chip's INT8 activations: the largest code, and the step of the
// direction encoding's codes (|d| <= 1, its own fixed step; chip/tme.h).
inline constexpr float kActivationMax = 127.f;
inline constexpr float kDirectionStep = 1.f / 127.f;

// Rounds rows x kLanes values to multiples of `step` (half up, as the chip
// narrows), clamped to [lo, hi] steps: activations as the chip's INT8 inputs
// hold them, for the quantization-aware phase (qat_activations).
void quantize_block(float* block, int rows, float step, float lo, float hi);

// Backward pass of one net over a chunk. d_last: [last out][kLanes], the loss
// gradient with respect to the last layer's (linear) output. Adds parameter
// gradients into grad (same layout as params). If d_x0 is not null it
// receives [layers[0].in][kLanes], the gradient with respect to x0. scratch
// holds net_backward_scratch_floats(layout) floats.
void net_backward(const std::vector<MlpLayout::Layer>& layers, const float* params, const float* x0, const float* acts,
                  const float* d_last, float* grad, float* d_x0, float* scratch);

size_t net_backward_scratch_floats(const MlpLayout& layout);

// Largest |value| of rows x kLanes values, over the first n lanes.
float block_max_abs(const float* block, int rows, int n);

}  // namespace edrnr::train
