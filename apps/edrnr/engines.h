#pragma once
// The renderers `edrnr render --engine` and `edrnr eval --engine` can pick.
// A new engine is one more line in engines.cpp.
#include <CLI/CLI.hpp>

#include "core/image.h"
#include "data/camera.h"
#include "model/scene_model.h"
#include "render/options.h"
#include "render/reference.h"

namespace edrnr::cli {

struct Engine {
  const char* name;
  const char* description;
  Image (*render)(const SceneModel&, const Camera&, const RenderSettings&, RenderStats*);
};

// The engine called `name`; an Error listing the available ones otherwise.
const Engine& find_engine(const std::string& name);

// Adds --fast-transmittance (in [0, 1]) to a command that renders with the
// engines; *value starts below 0 (not given).
void add_fast_transmittance_option(CLI::App* cmd, float* value);
// The option's value, when given, as both paths' threshold
// (RenderSettings::fast_transmittance_min and fast_int8_transmittance_min);
// else their defaults stay.
void apply_fast_transmittance(float value, RenderSettings& s);

}  // namespace edrnr::cli
