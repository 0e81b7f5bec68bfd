#pragma once
// Parsing of the render options the commands share. Each parser throws Error
// naming the flag and the text it could not use.
#include <string>

#include "core/vec.h"
#include "render/reference.h"

namespace edrnr {

// "white", "black" or "R,G,B" with each component in [0, 1].
void parse_background(const std::string& text, const std::string& flag, float rgb[3]);

// "auto", "float" or "quantized".
ModelForm parse_model_form(const std::string& text, const std::string& flag);
const char* model_form_name(ModelForm form);

// "X,Y,Z": three finite numbers.
Vec3f parse_vec3(const std::string& text, const std::string& flag);

// Checks a sample spacing in micro voxels against the limits (core/limits.h):
// finite, positive, at most kMaxStepMicro, and (with a model's micro_res > 0)
// at most kMaxSamplesPerRay candidate samples along the scene box's diagonal.
// `what` names the flag or config field. Throws Error naming the limit and the
// smallest step allowed.
void check_step_micro(double step_micro, int micro_res, const std::string& what);

// The same checks for a loaded model, and a warning on stderr when the model
// records (metadata "step_micro", written by the trainer) another step than
// the one about to be used: a model renders best at the step it was trained
// at (docs/training.md, "The sample step").
void check_step_micro(double step_micro, const SceneModel& model, const std::string& what);

// The step recorded in a model's metadata, or 0 when it records none.
double trained_step_micro(const SceneModel& model);

}  // namespace edrnr
