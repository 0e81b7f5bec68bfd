#pragma once
// The renderers `edrnr render --engine` and `edrnr eval --engine` can pick.
// A new engine is one more line in engines.cpp.
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

}  // namespace edrnr::cli
