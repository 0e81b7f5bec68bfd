// End-to-end: a small dataset rendered from a procedural scene is learned,
// exported, and rendered back with the reference renderer.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>

#include "core/error.h"
#include "core/metrics.h"
#include "data/dataset.h"
#include "model/model_io.h"
#include "model/procedural.h"
#include "render/fast.h"
#include "render/options.h"
#include "render/reference.h"
#include "temp_dir.h"
#include "train/calibrate.h"
#include "train/checkpoint_io.h"
#include "train/config.h"
#include "train/images.h"
#include "train/synthetic.h"
#include "train/trainer.h"
#include "train_fixture.h"

namespace edrnr::train {
namespace {

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
  // The AABB is the tight box of the occupied micro voxels (pruning tightens it).
  const Bitmap3& micro = t.quantized.occupancy[int(Tier::Micro)];
  Vec3i lo{1 << 20, 1 << 20, 1 << 20}, hi{-1, -1, -1};
  for (int z = 0; z < micro.res(); ++z)
    for (int y = 0; y < micro.res(); ++y)
      for (int x = 0; x < micro.res(); ++x)
        if (micro.get(x, y, z)) {
          lo = vmin(lo, Vec3i{x, y, z});
          hi = vmax(hi, Vec3i{x, y, z});
        }
  const Vec3f vs = t.quantized.micro_voxel_size();
  for (int a = 0; a < 3; ++a) {
    EXPECT_FLOAT_EQ(t.quantized.object_aabb.lo[a], t.quantized.scene_box.lo[a] + vs[a] * float(lo[a]));
    EXPECT_FLOAT_EQ(t.quantized.object_aabb.hi[a], t.quantized.scene_box.lo[a] + vs[a] * float(hi[a] + 1));
  }
  const Dataset test = load("test");
  const double pf = mean_psnr(t.float_model, test, ModelForm::Float);
  const double pq = mean_psnr(t.quantized, test, ModelForm::Quantized);
  std::printf("train PSNR float %.2f quantized %.2f; test PSNR float %.2f quantized %.2f; %zu blocks %zu MLPs\n",
              t.stats.psnr_float, t.stats.psnr_quantized, pf, pq, t.quantized.block_count(), t.quantized.mlp_count());
  // Measured: float 30.1 dB, quantized 31.0 dB (400 steps); asserted with a margin.
  EXPECT_GT(pf, 27.0);
  EXPECT_GT(pq, 27.0);
  EXPECT_GT(t.stats.psnr_float, 27.0);
  EXPECT_GT(t.stats.psnr_quantized, 27.0);
}

std::vector<uint8_t> model_bytes(const Trainer& t, bool quantized) {
  return serialize_model(t.export_model(quantized));
}

TEST(Train, ResumedRunEndsInTheSameBitsAsAnUninterruptedOne) {
  const Dataset data = load("train");
  const TrainConfig c = short_config();
  Trainer whole(data, c);
  ASSERT_TRUE(whole.run({}));
  // Interrupted in the main phase (step 30) and in the per-CV phase (step 70):
  // each time continued from the checkpoint bytes in a new trainer.
  std::vector<uint8_t> ckpt;
  {
    Trainer a(data, c);
    TrainOptions o;
    o.stop_after = 30;
    ASSERT_FALSE(a.run(o));
    EXPECT_EQ(a.stats().step, 30);
    ckpt = a.checkpoint();
  }
  {
    Trainer b(data, ckpt, "checkpoint 1");
    EXPECT_EQ(b.stats().step, 30);
    TrainOptions o;
    o.stop_after = 70;
    ASSERT_FALSE(b.run(o));
    EXPECT_EQ(b.stats().phase, Phase::PerCv);
    ckpt = b.checkpoint();
  }
  Trainer c3(data, ckpt, "checkpoint 2");
  ASSERT_TRUE(c3.run({}));
  EXPECT_EQ(model_bytes(c3, true), model_bytes(whole, true));
  EXPECT_EQ(model_bytes(c3, false), model_bytes(whole, false));
}

TEST(Train, AStepCountFixedAtTheCalibrationStepReplaysExactly) {
  // --minutes trains with a provisional count and fixes it by plan_step (120
  // here); the learning rate does not depend on the count before then, so
  // --iters with the chosen count gives the same bits.
  const Dataset data = load("train");
  TrainConfig provisional = short_config();
  provisional.iters = 5000;
  Trainer a(data, provisional);
  TrainOptions o;
  o.stop_after = 120;
  ASSERT_FALSE(a.run(o));
  a.set_iters(200);
  ASSERT_TRUE(a.run({}));
  TrainConfig fixed = short_config();
  fixed.iters = 200;
  Trainer b(data, fixed);
  ASSERT_TRUE(b.run({}));
  EXPECT_EQ(model_bytes(a, true), model_bytes(b, true));
}

TEST(Train, PlanSpreadsTheTimeLeftByEachPhasesCost) {
  TrainConfig c;  // main 45 %, per-CV 45 %, quantization-aware 10 %
  c.plan_cost_main = 0.9f;
  c.plan_cost_per_cv = 0.75f;
  c.plan_cost_qat = 1.1f;
  c.plan_reserve = 0.05f;
  // The model's time for a run of n steps after step 1000 at 0.05 s a step,
  // summed phase by phase here.
  const auto seconds = [&](int64_t n) {
    // (The fractions are floats: 0.45f and 0.1f, not 0.45 and 0.1.)
    const double main_share = 1.0 - double(c.per_cv_fraction) - double(c.qat_fraction);
    const int64_t freeze = std::llround(main_share * double(n));
    const int64_t qat = std::llround((1.0 - double(c.qat_fraction)) * double(n));
    return 0.05 * (0.9 * double(freeze - 1000) + 0.75 * double(qat - freeze) + 1.1 * double(n - qat));
  };
  // 1600 s left, 1520 s after the reserve: about (1520 / 0.05 + 900) / 0.8525 steps.
  const int64_t n = c.plan_iters(1000, 0.05, 1600.0);
  EXPECT_NEAR(double(n), 36715.0, 3.0);
  EXPECT_LE(seconds(n), 1520.0 * (1 + 1e-9));
  EXPECT_GT(seconds(n + 2), 1520.0);
  EXPECT_NEAR(c.planned_seconds(1000, n, 0.05), seconds(n), 1e-3);  // float costs; a step is 0.04 s
  // Every phase at the measured cost and a tenth kept: the steps that fill
  // nine tenths of the time left.
  c.plan_cost_main = c.plan_cost_per_cv = c.plan_cost_qat = 1.f;
  c.plan_reserve = 0.1f;
  EXPECT_NEAR(double(c.plan_iters(1000, 0.05, 1600.0)), 1000.0 + 0.9 * 1600.0 / 0.05, 1.0);
  // Too little time left: still enough steps that the main phase goes on
  // past this step (45 % of n beyond 1001).
  EXPECT_EQ(c.plan_iters(1000, 0.05, 1.0), int64_t(std::ceil(1001.0 / 0.45)) + 1);
}

TEST(Train, ResultDoesNotDependOnTheThreadCount) {
  const Dataset data = load("train");
  TrainOptions one, two;
  one.threads = 1;
  two.threads = 2;
  Trainer a(data, short_config()), b(data, short_config());
  ASSERT_TRUE(a.run(one));
  ASSERT_TRUE(b.run(two));
  EXPECT_EQ(model_bytes(a, true), model_bytes(b, true));
}

TEST(Train, RegularisersActAndKeepTheResultIndependentOfThreads) {
  const Dataset data = load("train");
  TrainConfig reg = short_config();
  reg.tv_weight = 1e-5f;
  reg.tv_levels = 2;
  reg.block_tv_weight = 1e-5f;
  reg.smooth_weight = 0.5f;
  reg.block_smooth_weight = 0.5f;
  reg.distortion_weight = 0.01f;
  reg.mlp_tie_weight = 1e-3f;
  reg.mlp_equalize = 0.f;  // the tie and the equalization exclude each other
  reg.pixel_jitter = true;
  reg.depth_jitter = 1.f;
  TrainOptions one, two;
  one.threads = 1;
  two.threads = 2;
  Trainer a(data, reg), b(data, reg), plain(data, short_config());
  ASSERT_TRUE(a.run(one));
  ASSERT_TRUE(b.run(two));
  ASSERT_TRUE(plain.run(two));
  EXPECT_EQ(model_bytes(a, true), model_bytes(b, true));
  EXPECT_NE(model_bytes(a, true), model_bytes(plain, true));
  // The terms that act after the freeze only (the others have gradient tests
  // in kernels_test.cpp), the rays' jitter in their pixels and their
  // samples' jitter along them each change the result alone.
  for (int term = 0; term < 5; ++term) {
    TrainConfig c = short_config();
    if (term == 0) c.block_tv_weight = 1e-5f;
    if (term == 1) c.mlp_tie_weight = 1e-3f, c.mlp_equalize = 0.f;
    if (term == 2) c.block_smooth_weight = 0.5f;
    if (term == 3) c.pixel_jitter = true;
    if (term == 4) c.depth_jitter = 1.f;
    Trainer t(data, c);
    ASSERT_TRUE(t.run(two));
    EXPECT_NE(model_bytes(t, false), model_bytes(plain, false)) << "term " << term;
  }
}

TEST(Train, ExportedModelRendersWhatTrainingRendered) {
  // The trainer's own forward pass and render_reference on the exported model
  // agree, in float (before quantization) and quantized (at the end).
  const Dataset data = load("train");
  const Dataset test = load("test");
  Trainer t(data, short_config());
  TrainOptions o;
  o.stop_after = 80;  // the per-CV phase: float
  ASSERT_FALSE(t.run(o));
  ASSERT_EQ(t.stats().phase, Phase::PerCv);
  auto max_diff = [](const Image& a, const Image& b) {
    float m = 0.f;
    for (size_t i = 0; i < a.data.size(); ++i) m = std::max(m, std::fabs(a.data[i] - b.data[i]));
    return m;
  };
  RenderSettings rs;
  const Camera& cam = test.frames[0].camera;
  rs.form = ModelForm::Float;
  EXPECT_LT(max_diff(t.render(cam), render_reference(t.export_model(false), cam, rs)), 1e-4f);
  ASSERT_TRUE(t.run({}));
  rs.form = ModelForm::Quantized;
  EXPECT_LT(max_diff(t.render(cam), render_reference(t.export_model(true), cam, rs)), 1e-4f);
}

TEST(Train, QatActivationsTrainTheChipsIntegerActivations) {
  // With qat_activations the quantization-aware phase rounds every MLP
  // layer's input to the INT8 steps the export writes (refreshed from the
  // calibration every few steps here). The trainer's own forward pass then
  // renders what the fast renderer's INT8 path (the chip's integer
  // activations) renders from the exported model, far closer than the
  // reference renderer (float activations) does (measured: 80.0 against
  // 68.4 dB); an interrupted run resumes to the same bits.
  const Dataset data = load("train");
  const Dataset test = load("test");
  TrainConfig c = short_config();  // 100 steps, quantization-aware from step 80
  c.qat_activations = true;
  c.quant_refit_every = 4;
  c.qat_activations_every = 6;  // step counts 84, 90, 96
  Trainer whole(data, c);
  TrainOptions o;
  o.stop_after = 93;  // after two refreshes
  ASSERT_FALSE(whole.run(o));
  const std::vector<uint8_t> ckpt = whole.checkpoint();
  ASSERT_TRUE(whole.run({}));
  const SceneModel q = whole.export_model(true);
  EXPECT_NE(q.metadata_json.find("\"activation_steps\""), std::string::npos);
  RenderSettings rs;
  rs.form = ModelForm::Quantized;
  rs.fast_transmittance_min = 0.f;  // the trainer's samples
  const FastRenderer int8(q, ModelForm::Quantized, FastPath::Int8);
  double mine_db = 0, reference_db = 0;
  for (int v = 0; v < 2; ++v) {
    const Camera& cam = test.frames[size_t(v)].camera;
    const Image chip_like = int8.render(cam, rs);
    mine_db += psnr(whole.render(cam), chip_like) / 2;
    reference_db += psnr(render_reference(q, cam, rs), chip_like) / 2;
  }
  std::printf("against the INT8 path: trainer %.2f dB, reference renderer %.2f dB\n", mine_db, reference_db);
  EXPECT_GT(mine_db, reference_db + 6.0);

  Trainer b(data, ckpt, "checkpoint");
  ASSERT_TRUE(b.run({}));
  EXPECT_EQ(model_bytes(b, true), model_bytes(whole, true));
}

TEST(Train, EqualizedMlpsRenderWhatTheMlpsRenderedBefore) {
  // mlp_equalize rescales the MLPs' hidden units when quantization-aware
  // training starts: the float snapshot taken then holds other weights but
  // renders the same image (pruning off, so the occupancy stays).
  const Dataset data = load("train");
  const Dataset test = load("test");
  TrainConfig c = short_config();
  c.prune_weight = 0.f;
  c.prune_part_fraction = 0.f;
  c.mlp_equalize = 1.f;
  Trainer t(data, c);
  TrainOptions o;
  o.stop_after = 80;  // the last per-CV step: the next one starts quantization
  ASSERT_FALSE(t.run(o));
  ASSERT_EQ(t.stats().phase, Phase::PerCv);
  const SceneModel before = t.export_model(false);
  ASSERT_TRUE(t.run({}));
  const SceneModel after = t.export_model(false);
  ASSERT_EQ(after.mlps_f32.size(), before.mlps_f32.size());
  EXPECT_NE(after.mlps_f32, before.mlps_f32);
  EXPECT_EQ(after.features_f32, before.features_f32);
  RenderSettings rs;
  rs.form = ModelForm::Float;
  const Image a = render_reference(before, test.frames[0].camera, rs);
  const Image b = render_reference(after, test.frames[0].camera, rs);
  float m = 0.f;
  for (size_t i = 0; i < a.data.size(); ++i) m = std::max(m, std::fabs(a.data[i] - b.data[i]));
  EXPECT_LT(m, 1e-4f);
}

TEST(Train, ActivationCalibrationDoesNotDependOnTheStepItStartsFrom) {
  // The exported model's INT8 input steps are calibrated (the default). The
  // same model with every step 8 times coarser calibrates back to the same
  // steps (the candidates are relative to the starting step, and 8 = 2^(12/4)
  // lies inside their range), for any thread count, and says so in its metadata.
  const Trained& t = trained();
  const Dataset data = load("train");
  std::vector<Camera> cameras;
  for (const auto& f : data.frames) cameras.push_back(f.camera);
  ASSERT_NE(t.quantized.metadata_json.find("activation_calibration"), std::string::npos);
  EXPECT_EQ(trained_step_micro(t.quantized), double(small_config().step_micro));  // the step it was trained at
  EXPECT_EQ(trained_step_micro(t.float_model), double(small_config().step_micro));
  SceneModel coarse = t.quantized;
  for (auto& q : coarse.mlps_q8)
    for (auto* net : {&q.density, &q.color})
      for (auto& l : *net) l.in_scale *= 8.f;
  SceneModel one = coarse, two = coarse;
  CalibrationSettings s;
  s.threads = 1;
  const CalibrationReport r = calibrate_activation_scales(one, cameras, s);
  s.threads = 2;
  calibrate_activation_scales(two, cameras, s);
  EXPECT_EQ(serialize_model(one), serialize_model(two));
  EXPECT_GT(r.samples, 1000);
  EXPECT_EQ(r.layers, int(t.quantized.mlp_count() * (t.quantized.mlps_q8[0].density.size() + 2)));
  EXPECT_LT(r.mean_step_log2, -2.0);  // about -3: back from 8x
  int compared = 0;
  for (size_t m = 0; m < one.mlps_q8.size(); ++m)
    for (size_t l = 0; l < one.mlps_q8[m].color.size(); ++l) {
      const float want = t.quantized.mlps_q8[m].color[l].in_scale, got = one.mlps_q8[m].color[l].in_scale;
      EXPECT_NEAR(got / want, 1.f, 1e-3f) << "MLP " << m << " colour layer " << l;
      ++compared;
    }
  EXPECT_GT(compared, 0);
}

TEST(Train, QatLearningRateScaleActsInTheQuantizationPhaseOnly) {
  // qat_lr_scale multiplies the learning rate once quantization-aware
  // training starts: the float model (the snapshot taken then) is the same,
  // the quantized one is not.
  const Dataset data = load("train");
  TrainConfig scaled = short_config();
  scaled.qat_lr_scale = 4.f;
  Trainer a(data, short_config()), b(data, scaled);
  ASSERT_TRUE(a.run({}));
  ASSERT_TRUE(b.run({}));
  const SceneModel fa = a.export_model(false), fb = b.export_model(false);
  EXPECT_EQ(fa.features_f32, fb.features_f32);
  EXPECT_EQ(fa.mlps_f32, fb.mlps_f32);
  EXPECT_NE(model_bytes(a, true), model_bytes(b, true));
}

// The raw block values and MLP parameters of a trainer, from its checkpoint.
struct RawWeights {
  std::vector<float> blocks, mlps;
};
RawWeights raw_weights(const Trainer& t) {
  const std::vector<uint8_t> bytes = t.checkpoint();  // (the reader keeps views into it)
  const CheckpointReader r(bytes, "checkpoint");
  return {r.has("block_value") ? r.get<float>("block_value") : std::vector<float>{}, r.get<float>("mlp_params")};
}

TEST(Train, EmaOfTheQuantizationPhaseIsTheAverageOfItsSteps) {
  // With ema_decay_qat the quantization-aware phase's steps are those of a
  // run without it (the average is passive), and the run ends with its
  // weights replaced by their running average, started at the phase's first
  // step and updated every ema_every steps with the decay to that power:
  // computed here from the plain run's weights after every step.
  const Dataset data = load("train");
  TrainConfig c = short_config();
  c.ema_decay_qat = 0.8f;
  c.ema_every = 2;
  const float w = 1.f - 0.8f * 0.8f;
  Trainer plain(data, short_config()), avg(data, c);
  RawWeights expect;
  int qat_steps = 0;
  while (!plain.done()) {
    const int64_t s = plain.stats().step;
    plain.step();
    avg.step();
    if (plain.stats().phase != Phase::Quantize && plain.stats().phase != Phase::Done) {
      EXPECT_EQ(avg.stats().loss, plain.stats().loss) << "step " << s;
      continue;
    }
    const RawWeights now = raw_weights(plain);
    if (!plain.done()) {  // (after the last step the averages replace the weights)
      const RawWeights a = raw_weights(avg);
      EXPECT_EQ(a.mlps, now.mlps) << "step " << s;
      EXPECT_EQ(a.blocks, now.blocks) << "step " << s;
    }
    if (qat_steps++ == 0) {
      expect = now;
    } else if (s % 2 == 0) {
      for (size_t i = 0; i < now.blocks.size(); ++i) expect.blocks[i] += w * (now.blocks[i] - expect.blocks[i]);
      for (size_t i = 0; i < now.mlps.size(); ++i) expect.mlps[i] += w * (now.mlps[i] - expect.mlps[i]);
    }
  }
  ASSERT_TRUE(avg.done());
  EXPECT_EQ(qat_steps, 20);  // steps 80 to 99
  const RawWeights got = raw_weights(avg);
  EXPECT_EQ(got.blocks, expect.blocks);
  EXPECT_EQ(got.mlps, expect.mlps);
  // The float model (the snapshot at the phase's start) is the plain run's.
  EXPECT_EQ(avg.export_model(false).features_f32, plain.export_model(false).features_f32);
  EXPECT_NE(model_bytes(avg, true), model_bytes(plain, true));
}

TEST(Train, EmaRunsResumeToTheSameBits) {
  // Both averages on; interrupted in the per-CV phase (step 70) and in the
  // quantization-aware phase (step 90), each time continued from the
  // checkpoint bytes. The per-CV average is where the quantization-aware
  // phase starts, so the float model differs from a run without it.
  const Dataset data = load("train");
  TrainConfig c = short_config();
  c.ema_decay_per_cv = 0.9f;
  c.ema_decay_qat = 0.9f;
  c.ema_every = 3;
  Trainer whole(data, c);
  ASSERT_TRUE(whole.run({}));
  std::vector<uint8_t> ckpt;
  for (int64_t stop : {70, 90}) {
    std::unique_ptr<Trainer> t =
        ckpt.empty() ? std::make_unique<Trainer>(data, c) : std::make_unique<Trainer>(data, ckpt, "checkpoint");
    TrainOptions o;
    o.stop_after = stop;
    ASSERT_FALSE(t->run(o));
    EXPECT_TRUE(CheckpointReader(t->checkpoint(), "checkpoint").has("ema_blocks"));
    ckpt = t->checkpoint();
  }
  Trainer last(data, ckpt, "checkpoint");
  ASSERT_TRUE(last.run({}));
  EXPECT_FALSE(CheckpointReader(last.checkpoint(), "checkpoint").has("ema_blocks"));
  EXPECT_EQ(model_bytes(last, true), model_bytes(whole, true));
  EXPECT_EQ(model_bytes(last, false), model_bytes(whole, false));
  Trainer plain(data, short_config());
  ASSERT_TRUE(plain.run({}));
  EXPECT_NE(model_bytes(whole, false), model_bytes(plain, false));
}

TEST(Train, BlockLearningRateScaleActsOnTheBlocksOnly) {
  // block_lr_scale multiplies the feature blocks' learning rate: the main
  // phase (the pyramid) runs the same (the same running loss at its last
  // step), the blocks trained afterwards differ.
  const Dataset data = load("train");
  TrainConfig scaled = short_config();
  scaled.block_lr_scale = 3.f;
  TrainOptions stop;
  stop.stop_after = 55;  // the main phase (the per-CV phase starts at 60 of 100 steps)
  Trainer a(data, short_config()), b(data, scaled);
  ASSERT_FALSE(a.run(stop));
  ASSERT_FALSE(b.run(stop));
  ASSERT_EQ(a.stats().phase, Phase::Main);
  EXPECT_EQ(a.stats().loss, b.stats().loss);
  ASSERT_TRUE(a.run({}));
  ASSERT_TRUE(b.run({}));
  EXPECT_NE(a.stats().loss, b.stats().loss);
  EXPECT_NE(a.export_model(false).features_f32, b.export_model(false).features_f32);
}

TEST(Train, CoarseVoxelPruningDropsWholeCoarseVoxelsAndTheirMlps) {
  // prune_cv_weight empties every coarse voxel whose samples never weighed
  // that much (here 2 of the scene's 8 coarse voxels reach 0.2), with their
  // blocks and MLPs. A threshold no coarse voxel reaches would empty the
  // scene: then nothing is pruned.
  const Dataset data = load("train");
  auto train = [&](float threshold) {
    TrainConfig c = short_config();
    c.step_micro = 1.f;  // the weights above are those of samples one micro voxel apart (finer samples weigh less)
    c.prune_cv_weight = threshold;
    Trainer t(data, c);
    EXPECT_TRUE(t.run({}));
    SceneModel m = t.export_model(true);
    EXPECT_NO_THROW(m.check_structure());
    return m;
  };
  const SceneModel none = train(0.f), high = train(0.2f), all = train(0.99f);
  EXPECT_LT(high.mlp_count(), none.mlp_count());
  EXPECT_LT(high.block_count(), none.block_count());
  EXPECT_GT(high.mlp_count(), 0u);
  // Nothing pruned at all (not even the micro voxels prune_weight would
  // empty): every coarse voxel of the frozen occupancy keeps its MLP.
  EXPECT_GE(all.mlp_count(), none.mlp_count());
  EXPECT_GE(all.block_count(), none.block_count());
}

TEST(Train, RejectsBadInputWithClearErrors) {
  auto message = [](auto&& f) -> std::string {
    try {
      f();
    } catch (const Error& e) {
      return e.what();
    }
    return "no error";
  };
  // A folder without transforms_train.json.
  TempDir empty("edrnr_train_empty");
  DatasetOptions o;
  EXPECT_NE(message([&] { load_dataset(empty.path, o); }).find("transforms_train.json"), std::string::npos);
  // No frames, and frames whose images were not loaded.
  Dataset none;
  none.root = "nowhere";
  EXPECT_NE(message([&] { Trainer t(none, small_config()); }).find("no frames"), std::string::npos);
  DatasetOptions cams_only;
  cams_only.load_images = false;
  const Dataset no_images = load_dataset(dataset_dir(), cams_only);
  EXPECT_NE(message([&] { Trainer t(no_images, small_config()); }).find("no RGB image"), std::string::npos);
  // A checkpoint from another dataset, and a damaged one.
  const Dataset data = load("train");
  const Dataset test = load("test");
  Trainer t(data, short_config());
  std::vector<uint8_t> ckpt = t.checkpoint();
  EXPECT_NE(message([&] { Trainer r(test, ckpt, "ck"); }).find("different dataset"), std::string::npos);
  ckpt[ckpt.size() / 2] ^= 1;
  EXPECT_NE(message([&] { Trainer r(data, ckpt, "ck"); }).find("corrupt"), std::string::npos);
  // Bad settings name the setting.
  EXPECT_NE(message([] { parse_train_config("iters: 10\nlevles: [32]\n", "p.yaml"); }).find("'levles'"),
            std::string::npos);
  EXPECT_NE(message([] { parse_train_config("levels: [48]\n", "p.yaml"); }).find("levels"), std::string::npos);
  EXPECT_NE(message([] { parse_train_config("iters: many\n", "p.yaml"); }).find("'iters'"), std::string::npos);
  EXPECT_NE(message([] {
              parse_train_config("mlp_equalize: 0.5\nmlp_tie_weight: 0.001\n", "p.yaml").validate();
            }).find("cannot both be on"),
            std::string::npos);
  EXPECT_NE(message([] { parse_train_config("color_hidden: [256, 256]\n", "p.yaml"); }).find("MLP cache"),
            std::string::npos);
  EXPECT_NE(message([] { parse_train_config("tv_levels: 5\n", "p.yaml"); }).find("tv_levels"), std::string::npos);
  EXPECT_NE(message([] { parse_train_config("level_unlock_steps: [0, 100]\n", "p.yaml"); }).find("4 levels"),
            std::string::npos);
  EXPECT_NE(message([] { parse_train_config("level_unlock_steps: [0, 0, -1, 5]\n", "p.yaml"); }).find("negative"),
            std::string::npos);
  EXPECT_EQ(parse_train_config("level_unlock_steps: [0, 0, 300, 600]\n", "p.yaml").level_unlock_steps,
            (std::vector<int>{0, 0, 300, 600}));
  EXPECT_NE(message([] { parse_train_config("distortion_weight: -1\n", "p.yaml"); }).find("distortion_weight"),
            std::string::npos);
  EXPECT_NE(message([] { parse_train_config("block_tv_weight: -1\n", "p.yaml"); }).find("block_tv_weight"),
            std::string::npos);
  EXPECT_NE(message([] { parse_train_config("mlp_tie_weight: -1\n", "p.yaml"); }).find("mlp_tie_weight"),
            std::string::npos);
  // Smoothing steps that would overshoot the neighbours' mean (lr_features 0.02: at most 1 / 0.12).
  EXPECT_NE(message([] { parse_train_config("smooth_weight: 9\n", "p.yaml"); }).find("smooth_weight"),
            std::string::npos);
  EXPECT_NE(message([] { parse_train_config("block_smooth_weight: -1\n", "p.yaml"); }).find("block_smooth_weight"),
            std::string::npos);
  EXPECT_EQ(parse_train_config("smooth_weight: 8\n", "p.yaml").smooth_weight, 8.f);
  EXPECT_NE(message([] { parse_train_config("block_lr_scale: 0\n", "p.yaml"); }).find("block_lr_scale"),
            std::string::npos);
}

TEST(Train, PresetsAreValid) {
  for (const auto& e : fs::directory_iterator(fs::path(EDRNR_SOURCE_DIR) / "configs" / "train")) {
    if (e.path().extension() != ".yaml") continue;
    const TrainConfig c = load_train_config(e.path());
    EXPECT_NO_THROW(c.validate()) << e.path();
    // The YAML dump reads back to the same settings.
    EXPECT_EQ(to_yaml(parse_train_config(to_yaml(c), "dump")), to_yaml(c)) << e.path();
  }
  // The ablation overlays (scripts/train-ablation.sh) on top of the default preset.
  const fs::path train_dir = fs::path(EDRNR_SOURCE_DIR) / "configs" / "train";
  int overlays = 0;
  for (const auto& e : fs::directory_iterator(train_dir / "ablation")) {
    const TrainConfig c = load_train_config(e.path(), load_train_config(train_dir / "default.yaml"));
    EXPECT_NO_THROW(c.validate()) << e.path();
    ++overlays;
  }
  EXPECT_GE(overlays, 5);
}

// default.yaml is the built-in defaults (what `edrnr train` uses without
// --config); the presets before it are base-v1.yaml with the pair the first
// ablations chose (base-v2.yaml) and base-v2.yaml with the overlays the
// validation runs chose, base-v3.yaml the overlays but the last
// (docs/training.md).
TEST(Train, DefaultPresetIsTheBuiltInDefaultsAndTheEarlierPresetsWithTheirOverlays) {
  const fs::path train_dir = fs::path(EDRNR_SOURCE_DIR) / "configs" / "train";
  const fs::path ablation = train_dir / "ablation";
  const TrainConfig preset = load_train_config(train_dir / "default.yaml");
  EXPECT_EQ(to_yaml(preset), to_yaml(TrainConfig{}));
  const TrainConfig base1 = load_train_config(train_dir / "base-v1.yaml");
  EXPECT_EQ(base1.per_cv_fraction, 0.1f);
  EXPECT_EQ(base1.distortion_weight, 0.f);
  const TrainConfig base2 = load_train_config(train_dir / "base-v2.yaml");
  EXPECT_EQ(to_yaml(load_train_config(ablation / "per-cv-0.3-distortion-0.01.yaml", base1)), to_yaml(base2));
  TrainConfig overlays = base2;
  for (const char* o : {"lr-2x-per-cv-0.45.yaml", "mlp-equalize-0.5.yaml", "prune-cv-0.2.yaml",
                        "calibrate-activations.yaml", "prune-parts-0.01.yaml", "qat-lr-0.33.yaml", "lr-final-0.2.yaml",
                        "fit-box-max-21000.yaml", "qat-activations.yaml"})
    overlays = load_train_config(ablation / o, overlays);
  EXPECT_EQ(to_yaml(overlays), to_yaml(load_train_config(train_dir / "base-v3.yaml")));
  EXPECT_EQ(to_yaml(load_train_config(ablation / "jitter-margin.yaml", overlays)), to_yaml(preset));
}

}  // namespace
}  // namespace edrnr::train
