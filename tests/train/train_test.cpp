// End-to-end: a small dataset rendered from a procedural scene is learned,
// exported, and rendered back with the reference renderer.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "core/error.h"
#include "core/metrics.h"
#include "data/dataset.h"
#include "model/model_io.h"
#include "model/procedural.h"
#include "render/reference.h"
#include "train/synthetic.h"
#include "train/trainer.h"

namespace edrnr::train {
namespace {

namespace fs = std::filesystem;

// 32 training and 8 test views at 64 x 64 of the "several" scene, made once.
const fs::path& dataset_dir() {
  static const fs::path dir = [] {
    fs::path d = fs::temp_directory_path() / fmt::format("edrnr_train_test_{}", ::getpid());
    fs::remove_all(d);
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

Dataset load(const std::string& split) {
  DatasetOptions o;
  o.split = split;
  return load_dataset(dataset_dir(), o);
}

TrainConfig small_config() {
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
  c.seed = 7;
  return c;
}

double mean_psnr(const SceneModel& m, const Dataset& test, ModelForm form) {
  RenderSettings rs;
  rs.form = form;
  double sum = 0;
  for (const auto& f : test.frames) sum += psnr(render_reference(m, f.camera, rs), f.image);
  return sum / double(test.frames.size());
}

struct Trained {
  SceneModel quantized, float_model;
  TrainStats stats;
};

const Trained& trained() {
  static const Trained t = [] {
    const Dataset train = load("train");
    Trainer tr(train, small_config());
    TrainOptions o;
    EXPECT_TRUE(tr.run(o));
    return Trained{tr.export_model(true), tr.export_model(false), tr.stats()};
  }();
  return t;
}

TEST(Train, LearnsAProceduralSceneAndExportsAValidModel) {
  const Trained& t = trained();
  for (const SceneModel* m : {&t.quantized, &t.float_model})
    for (const ModelCheck& c : model_checks(*m)) EXPECT_TRUE(c.passed) << c.name << ": " << c.detail;
  EXPECT_TRUE(t.float_model.features_q4.empty());
  EXPECT_TRUE(t.quantized.features_f32.empty());
  EXPECT_EQ(t.quantized.mlps_q8.size(), t.quantized.mlp_count());
  EXPECT_LE(t.quantized.mlp_arch.q8_bytes(), kMlpCacheBytes);
  EXPECT_GT(t.quantized.block_count(), 0u);
  const Dataset test = load("test");
  const double pf = mean_psnr(t.float_model, test, ModelForm::Float);
  const double pq = mean_psnr(t.quantized, test, ModelForm::Quantized);
  std::printf("train PSNR float %.2f quantized %.2f; test PSNR float %.2f quantized %.2f; %zu blocks %zu MLPs\n",
              t.stats.psnr_float, t.stats.psnr_quantized, pf, pq, t.quantized.block_count(), t.quantized.mlp_count());
  EXPECT_GT(pf, 0.0);
  EXPECT_GT(pq, 0.0);
}

}  // namespace
}  // namespace edrnr::train
