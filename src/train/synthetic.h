#pragma once
// Small posed-image datasets rendered from a model with the reference
// renderer, written in the NeRF "transforms_<split>.json" layout, for tests,
// benchmarks and trying the trainer without downloading data.
#include <filesystem>
#include <string>

#include "model/scene_model.h"

namespace edrnr::train {

struct SyntheticViews {
  int train_views = 32;
  int test_views = 8;
  int width = 64, height = 64;
  double radius = 4.0;      // camera distance from the origin, scene units
  double fov_x_deg = 40.0;  // full horizontal field of view
  bool alpha = true;        // RGBA images (rendered on black and on white to recover alpha); false: RGB on white
};

// Renders the views (orbit cameras spread over the sphere by a golden-angle
// spiral; test views interleaved with the training ones) with the model's own
// form (render_reference, ModelForm::Auto) and writes
// dir/transforms_train.json, dir/transforms_test.json and dir/{train,test}/r_<i>.png.
void write_synthetic_dataset(const SceneModel& model, const std::filesystem::path& dir, const SyntheticViews& views);

}  // namespace edrnr::train
