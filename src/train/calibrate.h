#pragma once
// Activation calibration of a quantized model's INT8 MLPs: the input step
// (in_scale) of every layer, chosen from the samples the model's own rays
// evaluate, so that the chip's INT8 activations lose as little as they can.
//
// The trainer's quantization-aware phase sets each layer's step from the
// largest input it saw (max / 127). One rare large activation then makes
// the step of the whole layer coarse; on a fully trained lego the chip's
// image fell to 35 dB against the reference renderer's. Calibration tries
// steps in_scale * 2^(-k/4), k = -4 .. 24, and keeps, per MLP and layer, the
// one with the least squared error of the quantized inputs, each input
// weighted by the squared norm of its outgoing weights (an input that barely
// reaches the next layer may saturate).
#include <vector>

#include "data/camera.h"
#include "model/scene_model.h"

namespace edrnr::train {

struct CalibrationSettings {
  float step_micro = kDefaultStepMicro;  // the renderer's sample spacing (micro voxels)
  float transmittance_min = 1e-4f;       // samples past this transmittance are not evaluated (as the renderer)
  int activation_bits = 8;               // the chip's activations: [-2^(b-1), 2^(b-1) - 1] steps
  int64_t target_rays = 1 << 18;         // about this many rays, every stride-th pixel of every camera
  int threads = 0;                       // 0: all cores
};

struct CalibrationReport {
  int64_t rays = 0, samples = 0;
  int layers = 0;             // layers calibrated (MLPs x layers)
  int layers_changed = 0;     // of which got another step
  double mean_step_log2 = 0;  // mean log2(new step / old step) over the layers
};

// Rewrites model.mlps_q8[*].{density,color}[*].in_scale (nothing else). The
// model must be quantized (INT4 features, INT8 MLPs) and finalize()d.
// Deterministic: the same model and cameras give the same steps for any
// thread count. Throws Error if the model has no quantized form.
CalibrationReport calibrate_activation_scales(SceneModel& model, const std::vector<Camera>& cameras,
                                              const CalibrationSettings& settings);

}  // namespace edrnr::train
