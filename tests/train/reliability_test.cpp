// The trainer under careless settings (issue #16): runs too short to reach
// the freeze are refused up front, short runs and runs without a
// quantization-aware phase export a valid model, an occupancy grid that has
// not emptied is refused at the freeze before its blocks are allocated, and a
// periodic checkpoint that cannot be written does not end the run.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <string>

#include "core/error.h"
#include "data/dataset.h"
#include "model/model_io.h"
#include "model/procedural.h"
#include "temp_dir.h"
#include "train/checkpoint_io.h"
#include "train/config.h"
#include "train/feature_grid.h"
#include "train/images.h"
#include "train/synthetic.h"
#include "train/trainer.h"
#include "train_fixture.h"

namespace edrnr::train {
namespace {

namespace fs = std::filesystem;

// 8 training views at 32 x 32 of a sphere.
const Dataset& data() {
  static const TempDir tmp("edrnr_train_reliability");
  static const Dataset d = [] {
    ProceduralOptions po;
    po.micro_res = 32;
    po.feature_channels = 4;
    const SceneModel scene = make_procedural_model("sphere", procedural_shapes("sphere"), po);
    SyntheticViews v;
    v.train_views = 8;
    v.test_views = 1;
    v.width = v.height = 32;
    write_synthetic_dataset(scene, tmp.path / "sphere", v);
    DatasetOptions o;
    o.load_images = false;
    Dataset ds = load_dataset(tmp.path / "sphere", o);
    load_premultiplied_rgba(ds, 1);
    return ds;
  }();
  return d;
}

// small_config() (train_fixture.h) on this 32^3 sphere: three levels and
// fewer samples and rays per step.
TrainConfig tiny(int64_t iters) {
  TrainConfig c = small_config();
  c.micro_res = 32;
  c.levels = {8, 16, 32};
  c.iters = iters;
  c.batch_samples = 2048;
  c.min_rays = 32;
  c.max_rays = 512;
  c.seed = 0;
  return c;
}

TrainOptions one_thread() {
  TrainOptions o;
  o.threads = 1;
  return o;
}

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

// --iters 1 (and 2 or 3 with some presets) segfaulted in make_model: training
// ended before the freeze, or without a quantization-aware phase.
TEST(TrainReliability, TooFewStepsAreRefusedUpFront) {
  std::string m = error_of([] { tiny(1).validate(); });
  EXPECT_NE(m.find("iters 1 (--iters or the preset) is too few"), std::string::npos) << m;
  EXPECT_NE(m.find("give at least 2 steps"), std::string::npos) << m;
  TrainConfig no_after = tiny(100);
  no_after.per_cv_fraction = no_after.qat_fraction = 0.f;
  m = error_of([&] { no_after.validate(); });
  EXPECT_NE(m.find("per_cv_fraction and qat_fraction are both 0"), std::string::npos) << m;
  EXPECT_NO_THROW(tiny(2).validate());
}

TEST(TrainReliability, ShortRunsExportAValidModel) {
  for (int64_t iters : {2, 3, 4}) {
    for (float qat : {0.15f, 0.f}) {
      TrainConfig c = tiny(iters);
      c.qat_fraction = qat;
      if (c.freeze_step(iters) >= iters) continue;  // refused by validate (above)
      Trainer t(data(), c);
      ASSERT_TRUE(t.run(one_thread()));
      for (bool quantized : {true, false}) {
        const SceneModel m = t.export_model(quantized);
        const std::vector<uint8_t> bytes = serialize_model(m);  // validates sizes and values
        const SceneModel back = parse_model(bytes.data(), bytes.size(), "short run");
        for (const ModelCheck& check : model_checks(back)) EXPECT_TRUE(check.passed) << check.name << check.detail;
      }
    }
  }
}

// `train --iters 5` with the default preset kept every fine voxel at the
// freeze and peaked at 10.9 GiB; now the blocks are counted first.
TEST(TrainReliability, AnOccupancyThatHasNotEmptiedIsRefusedAtTheFreeze) {
  TrainConfig c = tiny(5);
  c.max_state_gib = 0.004;  // 4.3 MB: the main phase fits (1.9 MB), a full 8^3 grid of blocks (12 MB) does not
  Trainer t(data(), c);
  const std::string m = error_of([&] { t.run(one_thread()); });
  EXPECT_NE(m.find("at the freeze (step"), std::string::npos) << m;
  EXPECT_NE(m.find("over the limit max_state_gib = 0.004 GiB"), std::string::npos) << m;
  // The main phase's own state is checked when the config is validated.
  TrainConfig big = tiny(100);
  big.micro_res = 1024;
  big.levels = {128, 256, 512, 1024};
  const std::string m2 = error_of([&] { big.validate(); });
  EXPECT_NE(m2.find("over the limit max_state_gib = 4 GiB"), std::string::npos) << m2;
}

// A periodic checkpoint that cannot be written is a warning; training goes on
// to the end (it used to abort the run).
TEST(TrainReliability, AFailedPeriodicCheckpointDoesNotEndTheRun) {
  const TempDir tmp("edrnr_train_ckpt_fail");
  Trainer t(data(), tiny(6));
  TrainOptions o = one_thread();
  o.checkpoint_path = tmp.path / "no_such_folder" / "run.ckpt";
  o.checkpoint_minutes = 1e-9;  // every step
  std::vector<std::string> warnings;
  o.warn = [&](const std::string& w) { warnings.push_back(w); };
  EXPECT_TRUE(t.run(o));
  ASSERT_FALSE(warnings.empty());
  EXPECT_NE(warnings[0].find("not written"), std::string::npos) << warnings[0];
  EXPECT_NE(warnings[0].find("no_such_folder"), std::string::npos) << warnings[0];
  // The checkpoint written on a stop must exist, so its failure is an error.
  Trainer t2(data(), tiny(6));
  o.stop_after = 2;
  EXPECT_NE(error_of([&] { t2.run(o); }).find("no_such_folder"), std::string::npos);
}

// A checkpoint with one section's floats replaced (the CRC is redone, so
// only the trainer's own checks stand between the values and the run).
std::vector<uint8_t> with_floats(const std::vector<uint8_t>& ckpt, const std::string& section, float a, float b) {
  CheckpointReader r(ckpt, "edit");
  CheckpointWriter w;
  for (const std::string& name : r.names()) {
    if (name != section) {
      const std::string_view v = r.bytes(name);
      w.put_bytes(name, v.data(), v.size());
      continue;
    }
    std::vector<float> f = r.get<float>(name);
    if (f.size() >= 2) f[0] = a, f[1] = b;
    w.put(name, f);
  }
  return w.finish();
}

// Found by fuzz_train_checkpoint: block values that are not finite, or so
// large that their range overflows, reached an int conversion (undefined
// behaviour) when the INT4 ranges were fitted at export. They are refused on
// resume, and a huge finite range is clamped.
TEST(TrainReliability, CorruptCheckpointValuesAreRefusedOrClamped) {
  Trainer t(data(), tiny(6));
  TrainOptions o = one_thread();
  o.stop_after = 5;  // after the freeze (at step 4): the blocks exist
  ASSERT_FALSE(t.run(o));
  ASSERT_NE(t.stats().phase, Phase::Main);
  const std::vector<uint8_t> ckpt = t.checkpoint();
  const std::string m =
      error_of([&] { Trainer bad(data(), with_floats(ckpt, "block_value", INFINITY, 0.f), "c.ckpt"); });
  EXPECT_NE(m.find("c.ckpt: section 'block_value' item 0 is not a finite number"), std::string::npos) << m;
  EXPECT_NE(error_of([&] { Trainer bad(data(), with_floats(ckpt, "mlp_params", NAN, 0.f), "c.ckpt"); }), "");
  Trainer huge(data(), with_floats(ckpt, "block_value", -3e38f, 3e38f), "c.ckpt");
  const SceneModel q = huge.export_model(true);
  for (uint8_t zp : q.feature_quant.zero_point) EXPECT_LE(zp, 15);
}

// Also found by fuzz_train_checkpoint: a channel range so small that 1 / scale
// overflowed gave an infinite inverse scale, and a NaN value then reached an
// int conversion. Both now give valid codes; ordinary values are unchanged.
TEST(TrainReliability, Int4QuantizerHandlesTinyRangesAndNan) {
  const Int4Channel tiny_range = int4_channel_for_range(0.f, 1e-40f);
  EXPECT_TRUE(std::isfinite(tiny_range.inv_scale));
  EXPECT_EQ(tiny_range.quantize(0.f), tiny_range.zero_point);
  const Int4Channel q = int4_channel_for_range(-1.f, 2.f);
  EXPECT_EQ(q.quantize(NAN), 0);
  EXPECT_EQ(q.quantize(-5.f), 0);
  EXPECT_EQ(q.quantize(5.f), 15);
  EXPECT_EQ(q.quantize(0.f), q.zero_point);
  EXPECT_EQ(q.zero_point, 5);  // round(1 / 0.2)
  const Int4Channel huge = int4_channel_for_range(-3e38f, 3e38f);
  EXPECT_GE(huge.zero_point, 0);
  EXPECT_LE(huge.zero_point, 15);
}

}  // namespace
}  // namespace edrnr::train
