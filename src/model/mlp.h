#pragma once
// Float evaluation of a per-CV MLP (the shape is in scene_model.h).
#include <vector>

#include "core/vec.h"
#include "model/scene_model.h"

namespace edrnr {

struct MlpOutput {
  float sigma = 0.f;      // density, exp(raw)
  float raw_sigma = 0.f;  // density net output 0 before exp
  float rgb[3] = {0, 0, 0};
};

// Direction encoding, dir_dims = 3 + 6L values:
// [dx, dy, dz, then for k = 0..L-1: sin(2^k dx), sin(2^k dy), sin(2^k dz), cos(2^k dx), cos(2^k dy), cos(2^k dz)].
void encode_direction(const Vec3f& dir, int frequencies, float* out);

// Forward pass. `feature` has F values, `dir_enc` has dir_dims values.
MlpOutput eval_mlp(const MlpArch& arch, const MlpF& mlp, const float* feature, const float* dir_enc);

// The float MLP an INT8 one stands for (weights = w_q * w_scale[row]; biases
// as stored). Activations are not quantized here.
MlpF dequantize_mlp(const MlpQ& q);

// Trilinear interpolation of the feature at micro-grid position p (in micro
// voxel units from the scene box corner, 0..Rm). Writes F values. Returns false
// (and writes nothing) if the fine voxel of p has no block.
bool interpolate_feature(const SceneModel& model, const Vec3f& p_micro, float* out);

}  // namespace edrnr
