#pragma once
// Float evaluation of a per-CV MLP (the shape is in scene_model.h) and the
// trilinear feature lookup that feeds it.
#include <cmath>
#include <vector>

#include "core/vec.h"
#include "model/scene_model.h"

namespace edrnr {

// The raw density (density net output 0) is clamped to this range before
// exp(), so sigma lies in [exp(-30), exp(15)] ~ [9.4e-14, 3.3e6] per scene
// unit: no overflow to infinity, and a "large negative" raw still gives a
// finite, negligible density.
inline constexpr float kRawSigmaMin = -30.f;
inline constexpr float kRawSigmaMax = 15.f;

// eval_mlp keeps its activations on the stack: no layer may be wider.
inline constexpr int kMlpEvalMaxWidth = 256;

struct MlpOutput {
  float sigma = 0.f;      // density, exp(clamp(raw, kRawSigmaMin, kRawSigmaMax))
  float raw_sigma = 0.f;  // density net output 0 before clamping and exp
  float rgb[3] = {0, 0, 0};
};

// The default per-CV MLP: density net [F, 32, 16], colour net
// [16 + dir_dims, 32, 32, 3], direction frequencies L = 2 (dir_dims = 15).
// Its INT8 form (q8_bytes) fits the chip's MLP cache (kMlpCacheBytes).
MlpArch default_mlp_arch(int feature_channels = 16);

// Checks that `arch` chains: a density net from feature_channels inputs, a
// colour net taking the density output plus the direction encoding and giving
// 3 values, every layer 1..max_width wide. Throws Error naming the mismatch;
// `limit_note` (may be empty) says whose limit max_width is.
void check_mlp_arch(const MlpArch& arch, int feature_channels, int max_width, const char* limit_note);

// Direction encoding, dir_dims = 3 + 6L values:
// [dx, dy, dz, then for k = 0..L-1: sin(2^k dx), sin(2^k dy), sin(2^k dz), cos(2^k dx), cos(2^k dy), cos(2^k dz)].
void encode_direction(const Vec3f& dir, int frequencies, float* out);

// Forward pass. `feature` has F values, `dir_enc` has dir_dims values. Hidden
// layers use ReLU, output layers are linear; sigma = exp of the clamped raw
// density, rgb = sigmoid of the colour net outputs. The layers must have the
// shapes of `arch` (not checked here) and be at most kMlpEvalMaxWidth wide
// (Error otherwise). Sums run in input order, so results are reproducible.
MlpOutput eval_mlp(const MlpArch& arch, const MlpF& mlp, const float* feature, const float* dir_enc);

// The float MLP an INT8 one stands for (weights = w_q * w_scale[row]; biases
// as stored). Activations are not quantized here.
MlpF dequantize_mlp(const MlpQ& q);

// Which stored form of the features a lookup reads.
enum class FeatureSource {
  Auto,       // float features if the model has them, else INT4
  Float,      // features_f32 (must be present)
  Quantized,  // features_q4 dequantized with feature_quant (must be present)
};

// The micro voxel that contains micro-grid position p (micro voxel units from
// the scene box corner): floor(p), except that a coordinate exactly equal to
// micro_res belongs to the last voxel. Returns false for points outside
// [0, micro_res]^3 (or NaN).
inline bool micro_voxel_of(const Vec3f& p_micro, int micro_res, Vec3i& voxel) {
  const float hi = float(micro_res);
  for (int a = 0; a < 3; ++a) {
    float c = p_micro[a];
    if (!(c >= 0.f && c <= hi)) return false;
    int v = int(std::floor(c));
    voxel[a] = v < micro_res ? v : micro_res - 1;
  }
  return true;
}

// Trilinear interpolation of the feature at micro-grid position p (in micro
// voxel units from the scene box corner, 0..Rm). The sample lies in micro
// voxel m = micro_voxel_of(p), fine voxel m / 4; the weights are p - m. Writes
// F values. Returns false (and writes nothing) if p is outside the grid or the
// fine voxel of p has no block. Requires a finalize()d model.
bool interpolate_feature(const SceneModel& model, const Vec3f& p_micro, float* out);
bool interpolate_feature(const SceneModel& model, const Vec3f& p_micro, FeatureSource source, float* out);

}  // namespace edrnr
