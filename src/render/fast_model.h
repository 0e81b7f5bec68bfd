#pragma once
// The fast CPU renderer's form of a scene model: every per-CV MLP packed into
// one contiguous run of floats (weights, biases and per-neuron scales of all
// layers, then the input-stage scales), so that one MLP's parameters occupy a
// few KiB of consecutive cache lines and stay in L1 while a batch of samples
// runs through them. The features are not copied: the kernels read the
// model's fine-voxel blocks (INT4 codes or floats) in place.
//
// Two arithmetics:
//   Float: the reference renderer's arithmetic (float activations, weights
//          dequantized when the model's MLPs are INT8), summed in another order.
//   Int8:  the chip's arithmetic (INT4 features, INT8 weights and
//          activations, integer accumulators, per-neuron requantization,
//          16-bit raw outputs with 8 fraction bits), evaluated with floats
//          that hold integers exactly. Rounding and the activation functions
//          are not bit-exact with the chip model (docs/performance.md).
#include <cstddef>
#include <cstdint>
#include <vector>

#include "model/scene_model.h"
#include "render/reference.h"

namespace edrnr {

enum class FastArithmetic { Float, Int8 };

// One dense layer inside a packed MLP: offsets (in floats) from the MLP's first
// parameter. w: out x in row-major; b: out biases (Int8: in accumulator units);
// m: out requantization multipliers (Int8 only: to the next layer's INT8 input,
// or to the raw output in 1/256 steps).
struct FastLayer {
  int in = 0, out = 0;
  size_t w = 0, b = 0, m = 0;
  // Int8 byte form (FastModel::quads): the first q_in inputs (the colour
  // net's first layer: those before the direction), per output ceil(q_in / 4)
  // words of 4 signed weight bytes (input 4j + k in byte k) at wq, and per
  // output at bq the bias minus byte_offset times the sum of those weights.
  int q_in = 0;
  size_t wq = 0, bq = 0;
  // The colour net's first layer only: its direction inputs (from q_in on)
  // the same way, per output ceil(D / 4) words at dwq and minus byte_offset
  // times their weights' sum at dbq (no bias).
  size_t dwq = 0, dbq = 0;
};

struct FastModel {
  const SceneModel* model = nullptr;
  FastArithmetic arithmetic = FastArithmetic::Float;
  ResolvedForm form;
  int feature_channels = 0;  // F
  int geo_width = 0;         // G, density-net outputs
  int dir_dims = 0;          // D, direction-encoding values
  int dir_frequencies = 0;   // L
  std::vector<FastLayer> density, color;
  size_t feature_in = 0;      // Int8: F multipliers, feature (code steps) -> density-net input
  size_t geo_in = 0;          // Int8: multiplier, raw density output (1/256 steps) -> colour-net input
  size_t dir_in = 0;          // Int8: multiplier, direction partial sum -> accumulator units
  size_t mlp_stride = 0;      // floats per packed MLP (a multiple of 16)
  std::vector<float> params;  // mlp_count * mlp_stride
  // Per channel: float features are (code - zero_point) * scale.
  std::vector<float> feature_scale, feature_zero_point;
  // Int8: the layers in byte form (FastLayer::wq, bq) for kernels that
  // multiply the inputs, packed as bytes plus byte_offset, by signed weight
  // bytes: 128 with AVX-512 VNNI (unsigned bytes), 0 with AVX2 (signed
  // bytes; no weight -128). Empty when a weight or bias does not fit it or
  // the CPU has neither: the float form is used then, with the same results.
  size_t quad_stride = 0;
  std::vector<int32_t> quads;
  int byte_offset = 0;

  // Whether the kernels may run the default MLP shape's fused chunk
  // (fast_fused_shape); false: always the general layers, which give the
  // same bits (tests compare the two).
  bool fused = true;

  const float* mlp(size_t index) const { return params.data() + index * mlp_stride; }
  const int32_t* mlp_quads(size_t index) const { return quads.data() + index * quad_stride; }
};

// The widest layer the kernels evaluate (and the widest F and G + D).
inline constexpr int kFastMaxWidth = 64;

// Rows of the direction buffer fast_encode_directions writes (render/
// fast_kernels.h): the D direction inputs, and with the byte form (Int8
// with FastModel::quads) ceil(D / 4) more rows of packed bytes.
inline int fast_direction_rows(const FastModel& fm) {
  return fm.dir_dims + (fm.quads.empty() ? 0 : (fm.dir_dims + 3) / 4);
}

// Packs `model` for the fast renderer. `form` says which stored forms are read
// (resolve_model_form); Int8 needs the INT4 features and INT8 MLPs. Throws
// Error naming the MLP, net and layer when the model is not usable (not
// finalize()d, sizes that do not match mlp_arch, a layer wider than
// kFastMaxWidth, a non-finite or negative scale).
FastModel pack_fast_model(const SceneModel& model, const ResolvedForm& form, FastArithmetic arithmetic);

}  // namespace edrnr
