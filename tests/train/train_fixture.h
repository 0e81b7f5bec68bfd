#pragma once
// What the trainer's tests share: a small dataset of the "several"
// procedural scene, made once per test binary, and small training configs.
#include <filesystem>
#include <string>

#include "data/dataset.h"
#include "model/procedural.h"
#include "temp_dir.h"
#include "train/config.h"
#include "train/images.h"
#include "train/synthetic.h"

namespace edrnr::train {

namespace fs = std::filesystem;

// 32 training and 8 test views at 64 x 64 of the "several" scene, made once.
inline const fs::path& dataset_dir() {
  static const TempDir tmp("edrnr_train_test");
  static const fs::path dir = [] {
    const fs::path d = tmp.path / "several";
    ProceduralOptions po;
    po.micro_res = 64;
    const SceneModel scene = make_procedural_model("several", procedural_shapes("several"), po);
    SyntheticViews v;
    v.train_views = 32;
    v.test_views = 8;
    v.width = v.height = 64;
    write_synthetic_dataset(scene, d, v);
    return d;
  }();
  return dir;
}

// Training data as the CLI loads it (premultiplied RGBA, random backgrounds);
// test data composited on white.
inline Dataset load(const std::string& split) {
  DatasetOptions o;
  o.split = split;
  o.load_images = split != "train";
  Dataset d = load_dataset(dataset_dir(), o);
  if (split == "train") load_premultiplied_rgba(d, 1);
  return d;
}

inline TrainConfig small_config() {
  TrainConfig c;
  c.micro_res = 64;
  c.levels = {8, 16, 32, 64};
  c.iters = 400;
  c.batch_samples = 8192;
  c.min_rays = 64;
  c.max_rays = 4096;
  c.per_cv_fraction = 0.15f;
  c.qat_fraction = 0.15f;
  c.occupancy_every = 8;
  c.aabb_start = 64;
  c.aabb_every = 64;
  c.lr_warmup = 20;
  c.plan_step = 120;
  c.seed = 7;
  // A few coarse voxels, each part of the object: none is a floater.
  c.prune_cv_weight = 0.f;
  // Float activations in the quantization-aware phase: the tests of
  // qat_activations turn it on themselves.
  c.qat_activations = false;
  // Samples at fixed depths along each ray: the test of depth_jitter turns
  // it on itself.
  c.depth_jitter = 0.f;
  return c;
}

inline TrainConfig short_config() {
  TrainConfig c = small_config();
  c.iters = 100;
  c.per_cv_fraction = 0.2f;
  c.qat_fraction = 0.2f;
  c.aabb_start = 32;
  c.aabb_every = 32;
  return c;
}

}  // namespace edrnr::train
