#pragma once
// The reference renderer: float volume rendering of a SceneModel, eq. (1)-(2)
// of the paper. It is the algorithmic golden every other renderer (the chip
// model, the fast CPU renderer, the trainer's forward pass) is compared with.
//
// Sampling rule (shared by every renderer, so that skipping techniques never
// change which samples exist): along the unit ray o + t d, candidate samples
// sit at t_k = (k + 0.5) * delta for integers k >= 0, where
// delta = step_micro * (scene_box edge along x / micro_res). A candidate is a
// sample iff its point lies in an occupied micro voxel. Each sample
// contributes alpha = 1 - exp(-sigma * delta). Marching stops once the
// transmittance T falls below transmittance_min. The pixel is
// sum_i T_i alpha_i c_i + T_final * background. The exact float recipe for the
// sample points, and the tier traversal, are in render/traversal.h.
//
// Each sample uses the MLP of the CV that contains it and the feature
// trilinearly interpolated in its micro voxel; the view direction is encoded
// once per ray. Rows are rendered in parallel; every pixel is computed by one
// thread in a fixed order, so the image does not depend on the thread count.
#include <cstdint>

#include "core/image.h"
#include "data/camera.h"
#include "model/scene_model.h"

namespace edrnr {

enum class ModelForm { Auto, Float, Quantized };  // Auto: quantized if the model has it

struct RenderSettings {
  float step_micro = kDefaultStepMicro;  // delta in micro-voxel edge lengths
  float transmittance_min = 1e-4f;       // early termination threshold
  float background[3] = {1.f, 1.f, 1.f};
  ModelForm form = ModelForm::Auto;
  bool use_occupancy_tiers = true;  // false: test every candidate (a slow check of the skipping)
  int threads = 0;                  // 0: all cores
  // The fast engines (render/fast.h) end a ray once its transmittance is
  // below max(transmittance_min, X), X fast_transmittance_min on the float
  // path and fast_int8_transmittance_min on the INT8 path: every pixel then
  // differs from the image with the reference's samples by less than X per
  // channel (the weights still given sum to less than the transmittance
  // left, and each weighs a colour difference of at most 1). 0: the
  // reference's samples exactly. The INT8 path, held to 40 dB against the
  // chip model (the float path to 50 against the reference), ends earlier.
  float fast_transmittance_min = 1e-3f;
  float fast_int8_transmittance_min = 1e-2f;
};

struct RenderStats {
  uint64_t rays = 0;
  uint64_t rays_hit_aabb = 0;
  uint64_t samples = 0;           // samples evaluated by the MLP
  uint64_t occupancy_checks = 0;  // bitmap lookups at all tiers
};

// The forms a render of `model` with `requested` reads: features and MLPs
// are chosen separately under Auto (INT4 features if present, else float;
// INT8 MLPs if present, else float). Throws Error if a requested form is
// missing.
struct ResolvedForm {
  bool quantized_features = false;
  bool quantized_mlps = false;
};
ResolvedForm resolve_model_form(const SceneModel& model, ModelForm requested);

// Checks shared by the renderers (each throws Error naming the problem): the
// stored features of `form` hold exactly the model's blocks; the camera gives
// finite rays of a non-empty image, and the settings are in range.
void check_feature_storage(const SceneModel& model, const ResolvedForm& form);
void check_render_inputs(const Camera& camera, const RenderSettings& settings);

// Renders the whole image of `camera` (3 channels). Throws Error for an
// unusable model (not finalize()d, sizes that do not match, MLP layers that
// do not match mlp_arch, an occupied micro voxel without block or MLP), an
// empty camera or invalid settings.
Image render_reference(const SceneModel& model, const Camera& camera, const RenderSettings& settings,
                       RenderStats* stats = nullptr);

}  // namespace edrnr
