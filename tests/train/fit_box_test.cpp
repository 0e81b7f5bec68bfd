// Fitting the scene box to the object (train/fit_box.h).
#include "train/fit_box.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"
#include "model/model_io.h"
#include "model/procedural.h"
#include "train/trainer.h"
#include "train_fixture.h"

namespace edrnr::train {
namespace {

void expect_box(const Box3f& b, Vec3f lo, Vec3f hi) {
  for (int a = 0; a < 3; ++a) {
    EXPECT_FLOAT_EQ(b.lo[a], lo[a]) << "axis " << a;
    EXPECT_FLOAT_EQ(b.hi[a], hi[a]) << "axis " << a;
  }
}

const Box3f kWithin{{-1.5f, -1.5f, -1.5f}, {1.5f, 1.5f, 1.5f}};

TEST(FitBox, CubeAroundTheObjectWithItsMargin) {
  // Extents 0.6, 0.4, 0.2: the side is the largest plus two margins, 0.7,
  // centred on the object on each axis.
  expect_box(cube_around({{-0.2f, -0.1f, 0.f}, {0.4f, 0.3f, 0.2f}}, 0.05f, kWithin), {-0.25f, -0.25f, -0.25f},
             {0.45f, 0.45f, 0.45f});
  // At the box's side the cube moves inside, keeping its size.
  // Extents 0.3, 0.5, 0.3: side 0.7.
  expect_box(cube_around({{1.2f, -0.25f, -1.5f}, {1.5f, 0.25f, -1.2f}}, 0.1f, kWithin), {0.8f, -0.35f, -1.5f},
             {1.5f, 0.35f, -0.8f});
  // A least side widens the cube about the object's centre.
  expect_box(cube_around({{-0.2f, -0.1f, 0.f}, {0.4f, 0.3f, 0.2f}}, 0.05f, kWithin, 1.f), {-0.4f, -0.4f, -0.4f},
             {0.6f, 0.6f, 0.6f});
  // An object as large as the box (with its margin) keeps the box.
  expect_box(cube_around({{-1.45f, 0.f, 0.f}, {1.45f, 0.1f, 0.1f}}, 0.05f, kWithin), kWithin.lo, kWithin.hi);
}

TEST(FitBox, LeastSideKeepsThePredictedBlocks) {
  EXPECT_EQ(least_side_for_blocks(10000, 3.f, 0), 0.f);  // no limit
  EXPECT_EQ(least_side_for_blocks(0, 3.f, 5000), 0.f);
  // 2^2.5 times the blocks allowed: the voxels may be half as fine, so the
  // side twice as long; as many blocks as allowed: the same side.
  EXPECT_NEAR(least_side_for_blocks(size_t(std::round(1000 * std::pow(2.0, 2.5))), 1.5f, 1000), 3.f, 1e-3f);
  EXPECT_FLOAT_EQ(least_side_for_blocks(4000, 3.f, 4000), 3.f);
}

// The pilot runs for a time budget or a run of at least 4 times its steps.
TEST(FitBox, PilotOnlyForLongRuns) {
  TrainConfig c;
  EXPECT_EQ(c.fit_box_steps, 1500);  // the default preset fits the box
  c.iters = 5999;
  EXPECT_FALSE(pilot_pays(c));
  c.iters = 6000;
  EXPECT_TRUE(pilot_pays(c));
  c.iters = 10;
  c.minutes = 30;
  EXPECT_TRUE(pilot_pays(c));
  c.fit_box_steps = 0;
  EXPECT_FALSE(pilot_pays(c));
}

TEST(FitBox, PilotFindsTheObjectAndTheRunTrainsInItsCube) {
  const Dataset data = load("train");
  TrainConfig c = short_config();
  c.fit_box_steps = 100;
  c.fit_box_margin = 0.1f;
  c.fit_box_max_blocks = 0;
  TrainOptions one, two;
  one.threads = 1;
  two.threads = 2;
  const BoxFit a = fit_scene_box(data, c, one);
  // The pilot is a plain run of fit_box_steps steps (deterministic, as every
  // run is, for any thread count).
  TrainConfig plain = c;
  plain.fit_box_steps = 0;
  plain.iters = 100;
  Trainer t(data, plain);
  ASSERT_TRUE(t.run(two));
  const SceneModel pilot = t.export_model(false);
  expect_box(a.object, pilot.object_aabb.lo, pilot.object_aabb.hi);

  // The scene's shapes (known, not learned) lie in the object box, to within
  // a micro voxel of the pilot's grid (their soft edges are not all dense).
  Box3f shapes{{1e9f, 1e9f, 1e9f}, {-1e9f, -1e9f, -1e9f}};
  for (const Shape& s : procedural_shapes("several")) {
    const Box3f sb = shape_bounds(s);
    shapes.lo = vmin(shapes.lo, sb.lo);
    shapes.hi = vmax(shapes.hi, sb.hi);
  }
  const float voxel = 3.f / float(c.micro_res);
  for (int ax = 0; ax < 3; ++ax) {
    EXPECT_LE(a.object.lo[ax], shapes.lo[ax] + voxel) << "axis " << ax;
    EXPECT_GE(a.object.hi[ax], shapes.hi[ax] - voxel) << "axis " << ax;
  }

  // The run proper: a cube around the object with the margin (where the
  // scene box leaves room for it), smaller than the scene box, no second
  // pilot; its model lives in that box.
  const TrainConfig& f = a.config;
  EXPECT_EQ(f.fit_box_steps, 0);
  EXPECT_NO_THROW(f.validate());
  const float side = f.scene_box.hi.x - f.scene_box.lo.x;
  EXPECT_LT(side, 3.f);
  for (int ax = 0; ax < 3; ++ax) {
    EXPECT_LE(f.scene_box.lo[ax], std::max(a.object.lo[ax] - 0.1f, -1.5f) + 1e-5f);
    EXPECT_GE(f.scene_box.hi[ax], std::min(a.object.hi[ax] + 0.1f, 1.5f) - 1e-5f);
  }
  // A block budget below the pilot's count keeps a larger box.
  TrainConfig capped = c;
  capped.fit_box_max_blocks = int64_t(a.pilot_blocks / 2);
  const BoxFit cap = fit_scene_box(data, capped, two);
  EXPECT_EQ(cap.pilot_blocks, a.pilot_blocks);
  EXPECT_NEAR(cap.config.scene_box.hi.x - cap.config.scene_box.lo.x,
              std::min(3.f, least_side_for_blocks(a.pilot_blocks, 3.f, a.pilot_blocks / 2)), 1e-5f);
  EXPECT_GT(cap.config.scene_box.hi.x - cap.config.scene_box.lo.x, side);
  Trainer run(data, f);
  ASSERT_TRUE(run.run(two));
  const SceneModel m = run.export_model(true);
  expect_box(m.scene_box, f.scene_box.lo, f.scene_box.hi);
  for (const ModelCheck& chk : model_checks(m)) EXPECT_TRUE(chk.passed) << chk.name << ": " << chk.detail;
}

TEST(FitBox, ConfigErrorsNameTheKey) {
  TrainConfig c = short_config();
  c.fit_box_steps = 2;  // before the object is first found (aabb_start 32)
  try {
    c.validate();
    FAIL() << "accepted fit_box_steps 2";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("fit_box_steps 2"), std::string::npos) << e.what();
  }
  c.fit_box_steps = 100;
  c.fit_box_margin = -0.1f;
  try {
    c.validate();
    FAIL() << "accepted a negative margin";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("fit_box_margin"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace edrnr::train
