#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"
#include "core/metrics.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "render/reference.h"

namespace edrnr {
namespace {

// A camera at (0, 0, 4) looking down -z, W x W pixels, focal length f pixels.
Camera top_camera(int w, double f) {
  Camera c;
  c.width = c.height = w;
  c.fx = c.fy = f;
  c.cx = c.cy = 0.5 * w;
  c.c2w = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 4, 0, 0, 0, 1};
  return c;
}

SceneModel sphere_model(int res, float sigma, Vec3f color) {
  Shape s;
  s.center = {0, 0, 0};
  s.radius = 1.f;
  s.sigma = sigma;
  s.color = color;
  ProceduralOptions o;
  o.micro_res = res;
  return make_procedural_model("sphere", {s}, o);
}

SceneModel several_model(int res) {
  ProceduralOptions o;
  o.micro_res = res;
  return make_procedural_model("several", procedural_shapes("several"), o);
}

RenderSettings settings_with_background(float r, float g, float b) {
  RenderSettings s;
  s.background[0] = r;
  s.background[1] = g;
  s.background[2] = b;
  return s;
}

// Optical depth through a sphere of constant density. With micro voxel edge h
// and step delta: every candidate within r - sqrt(3) h of the centre has all
// 8 corners inside, so density exactly sigma; no sample lies farther than
// r + sqrt(3) h (its voxel overlaps the sphere); no sample exceeds sigma
// (interpolated log densities never exceed log sigma); and a segment of length
// l holds between l / delta - 1 and l / delta + 1 candidates. So for a ray at
// distance b from the centre, with chord(R) = 2 sqrt(R^2 - b^2):
//   sigma (chord(r - sqrt3 h) - delta) <= tau <= sigma (chord(r + sqrt3 h) + delta).
TEST(Reference, OpacityThroughAConstantDensitySphere) {
  const int res = 64;
  const float sigma = 0.5f, color = 0.8f;
  const SceneModel m = sphere_model(res, sigma, {color, color, color});
  const Camera cam = top_camera(21, 40);
  RenderSettings s = settings_with_background(0, 0, 0);
  s.form = ModelForm::Float;
  RenderStats stats;
  const Image img = render_reference(m, cam, s, &stats);
  ASSERT_EQ(img.width, 21);
  ASSERT_EQ(img.channels, 3);

  const double h = 3.0 / res, delta = h, r = 1.0, slack = std::sqrt(3.0) * h;
  auto chord = [](double radius, double b) { return radius > b ? 2 * std::sqrt(radius * radius - b * b) : 0.0; };
  int inside = 0, missed = 0;
  for (int y = 0; y < 21; ++y)
    for (int x = 0; x < 21; ++x) {
      const Ray ray = cam.pixel_ray(x, y);
      const double b = length(cross(ray.origin, ray.dir));  // distance of the centre from the ray
      const float px = img.at(x, y)[0];
      EXPECT_EQ(px, img.at(x, y)[2]);  // grey: all channels alike
      if (b > r + slack) {
        ++missed;
        EXPECT_EQ(px, 0.f) << x << "," << y;  // no sample at all: exactly the background
        continue;
      }
      ++inside;
      const double tau = -std::log(1.0 - px / color);  // pixel = c (1 - T) on black
      const double lo = std::max(0.0, sigma * (chord(r - slack, b) - delta)),
                   hi = sigma * (chord(r + slack, b) + delta);
      EXPECT_GE(tau, lo - 1e-4) << x << "," << y << " b=" << b;
      EXPECT_LE(tau, hi + 1e-4) << x << "," << y << " b=" << b;
    }
  EXPECT_GT(inside, 100);
  EXPECT_GT(missed, 20);
  // Through the centre: 1 - exp(-2 sigma r) = 0.632 nominal; tau within 1 +- 0.105.
  const double tau_c = -std::log(1.0 - img.at(10, 10)[0] / color);
  EXPECT_NEAR(tau_c, 2 * sigma * r, sigma * (4 * slack + 2 * delta) / 2 + 1e-4);
  EXPECT_EQ(stats.rays, 21u * 21u);
  EXPECT_GT(stats.samples, 0u);
}

TEST(Reference, RayThatMissesGivesExactlyTheBackground) {
  const SceneModel m = sphere_model(32, 5.f, {0.8f, 0.3f, 0.2f});
  // From (0, 0, 4), looking away from the scene (along +z).
  Camera cam = top_camera(9, 20);
  cam.c2w = {1, 0, 0, 0, 0, -1, 0, 0, 0, 0, -1, 4, 0, 0, 0, 1};  // camera -Z = world +z
  const RenderSettings s = settings_with_background(0.25f, 0.5f, 0.75f);
  RenderStats stats;
  const Image img = render_reference(m, cam, s, &stats);
  for (int y = 0; y < 9; ++y)
    for (int x = 0; x < 9; ++x) {
      EXPECT_EQ(img.at(x, y)[0], 0.25f);
      EXPECT_EQ(img.at(x, y)[1], 0.5f);
      EXPECT_EQ(img.at(x, y)[2], 0.75f);
    }
  EXPECT_EQ(stats.rays, 81u);
  EXPECT_EQ(stats.rays_hit_aabb, 0u);
  EXPECT_EQ(stats.samples, 0u);
}

TEST(Reference, EmptyModelGivesTheBackground) {
  Shape far;
  far.center = {4, 4, 4};
  ProceduralOptions o;
  o.micro_res = 32;
  const SceneModel procedural_empty = make_procedural_model("empty", {far}, o);
  SceneModel bare;
  bare.micro_res = 32;
  bare.init_grids();
  bare.finalize();
  for (const SceneModel* m : {&procedural_empty, static_cast<const SceneModel*>(&bare)}) {
    for (bool tiers : {true, false}) {
      RenderSettings s = settings_with_background(0.1f, 0.2f, 0.3f);
      s.use_occupancy_tiers = tiers;
      RenderStats stats;
      const Image img = render_reference(*m, top_camera(7, 10), s, &stats);
      for (size_t i = 0; i < img.data.size(); ++i) EXPECT_EQ(img.data[i], s.background[i % 3]);
      EXPECT_EQ(stats.samples, 0u);
    }
  }
}

// An opaque box of one colour: marching stops once T < 1e-4, so the pixel is
// c (1 - T) + T bg with T < 1e-4: within 1e-4 of c (plus float rounding).
TEST(Reference, OpaqueObjectShowsItsColour) {
  Shape b;
  b.kind = ShapeKind::Box;
  b.half_size = {0.5f, 0.5f, 0.5f};
  b.sigma = 1000.f;
  b.color = {0.2f, 0.6f, 0.9f};
  ProceduralOptions o;
  o.micro_res = 32;
  const SceneModel m = make_procedural_model("box", {b}, o);
  const Camera cam = top_camera(9, 40);  // rays within 0.5 of the axis at z = 0.5
  RenderSettings s = settings_with_background(1, 1, 1);
  s.form = ModelForm::Float;
  RenderStats early;
  const Image img = render_reference(m, cam, s, &early);
  for (int y = 0; y < 9; ++y)
    for (int x = 0; x < 9; ++x)
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(img.at(x, y)[c], b.color[c], 1.1e-4f) << x << "," << y;
  // Without early termination the march goes on through the box: more
  // samples, the same picture.
  s.transmittance_min = 0.f;
  RenderStats all;
  const Image full = render_reference(m, cam, s, &all);
  EXPECT_GT(all.samples, 3 * early.samples);
  for (size_t i = 0; i < img.data.size(); ++i) EXPECT_NEAR(full.data[i], img.data[i], 1.1e-4f);
}

TEST(Reference, TierSkippingDoesNotChangeTheImage) {
  const SceneModel m = several_model(64);
  // Outside the box, low and close, inside the box, and axis-aligned rays.
  std::vector<Camera> cams = {orbit_camera(40, 32, 30, 25, 4, 40), orbit_camera(33, 33, 200, -40, 2.2, 70),
                              orbit_camera(30, 30, 300, 10, 1.2, 90), top_camera(32, 30)};
  for (size_t i = 0; i < cams.size(); ++i) {
    RenderSettings s;
    s.threads = 2;
    RenderStats with, without;
    const Image a = render_reference(m, cams[i], s, &with);
    s.use_occupancy_tiers = false;
    const Image b = render_reference(m, cams[i], s, &without);
    EXPECT_EQ(a.data, b.data) << "camera " << i;
    EXPECT_EQ(with.samples, without.samples) << "camera " << i;
    EXPECT_EQ(with.rays_hit_aabb, without.rays_hit_aabb) << "camera " << i;
    EXPECT_GT(with.samples, 0u);
    EXPECT_LT(with.occupancy_checks, without.occupancy_checks) << "camera " << i;
  }
}

TEST(Reference, ThreadCountDoesNotChangeTheImage) {
  const SceneModel m = several_model(32);
  const Camera cam = orbit_camera(37, 29, 120, 35, 4, 40);
  RenderSettings s;
  s.threads = 1;
  RenderStats one, two;
  const Image a = render_reference(m, cam, s, &one);
  s.threads = 2;
  const Image b = render_reference(m, cam, s, &two);
  s.threads = 3;
  const Image c = render_reference(m, cam, s);
  EXPECT_EQ(a.data, b.data);
  EXPECT_EQ(a.data, c.data);
  EXPECT_EQ(one.samples, two.samples);
  EXPECT_EQ(one.occupancy_checks, two.occupancy_checks);
}

// INT4 features: a colour logit is off by at most half a quantization step,
// (range / 15) / 2 = 0.131 for the "several" red channel [-1.73, 2.20], so a
// colour by at most 0.25 * 0.131 = 0.033 (sigmoid slope <= 1/4): 29.6 dB if
// every pixel had the worst error. Log densities move by up to 0.46, which
// changes only translucent and edge pixels. We ask for 25 dB.
TEST(Reference, QuantizedFormRendersCloseToFloat) {
  const SceneModel m = several_model(64);
  const Camera cam = orbit_camera(48, 48, 45, 30, 4, 40);
  RenderSettings s;
  s.form = ModelForm::Float;
  const Image f = render_reference(m, cam, s);
  s.form = ModelForm::Quantized;
  const Image q = render_reference(m, cam, s);
  EXPECT_NE(f.data, q.data);
  EXPECT_GT(psnr(f, q), 25.0);
  s.form = ModelForm::Auto;  // quantized when present
  EXPECT_EQ(render_reference(m, cam, s).data, q.data);
}

TEST(Reference, QuantizedOnlyModelRendersItsQuantizedForm) {
  ProceduralOptions o;
  o.micro_res = 32;
  const SceneModel full = make_procedural_model("several", procedural_shapes("several"), o);
  o.store_float = false;
  const SceneModel q_only = make_procedural_model("several", procedural_shapes("several"), o);
  const Camera cam = orbit_camera(24, 24, 10, 20, 4, 40);
  RenderSettings s;
  s.form = ModelForm::Quantized;
  EXPECT_EQ(render_reference(full, cam, s).data, render_reference(q_only, cam, s).data);
  s.form = ModelForm::Float;
  EXPECT_THROW(render_reference(q_only, cam, s), Error);
}

TEST(Reference, BadInputsAreErrors) {
  SceneModel m = sphere_model(32, 1.f, {0.5f, 0.5f, 0.5f});
  const Camera cam = top_camera(5, 10);
  RenderSettings s;
  s.step_micro = 0.f;
  EXPECT_THROW(render_reference(m, cam, s), Error);
  s = RenderSettings{};
  s.transmittance_min = 2.f;
  EXPECT_THROW(render_reference(m, cam, s), Error);
  s = RenderSettings{};
  EXPECT_THROW(render_reference(m, top_camera(0, 10), s), Error);
  Camera degenerate = cam;
  degenerate.c2w = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 4, 0, 0, 0, 1};
  EXPECT_THROW(render_reference(m, degenerate, s), Error);
  SceneModel unfinalized = m;
  unfinalized.fine_to_block.clear();
  EXPECT_THROW(render_reference(unfinalized, cam, s), Error);
  SceneModel short_features = m;
  short_features.features_f32.resize(10);
  s.form = ModelForm::Float;
  EXPECT_THROW(render_reference(short_features, cam, s), Error);
  SceneModel bad_mlp = m;
  bad_mlp.mlps_f32[0].density[0].out = 31;
  EXPECT_THROW(render_reference(bad_mlp, cam, s), Error);
  // An occupied micro voxel whose fine voxel has no block breaks the invariants.
  SceneModel hole = m;
  hole.fine_to_block[linear_index(4, 4, 4, hole.fine_res())] = -1;
  try {
    render_reference(hole, cam, s);
    FAIL() << "missing block not reported";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("without a feature block"), std::string::npos) << e.what();
  }
}

// Smaller steps sample the same sphere more densely: the optical depth
// through the centre stays within the bounds above for each step.
TEST(Reference, StepSizeSetsTheSampleSpacing) {
  const SceneModel m = sphere_model(32, 0.5f, {0.8f, 0.8f, 0.8f});
  const Camera cam = top_camera(1, 10);  // one ray, straight through the centre
  for (float step : {0.5f, 1.f, 2.f}) {
    RenderSettings s = settings_with_background(0, 0, 0);
    s.step_micro = step;
    RenderStats stats;
    const Image img = render_reference(m, cam, s, &stats);
    const double h = 3.0 / 32, delta = step * h, slack = std::sqrt(3.0) * h;
    // Samples: the candidates in occupied voxels, which span at least the
    // chord 2 r and at most 2 (r + sqrt3 h).
    EXPECT_GE(double(stats.samples), 2.0 / delta - 1) << step;
    EXPECT_LE(double(stats.samples), 2 * (1 + slack) / delta + 1) << step;
    const double tau = -std::log(1.0 - img.data[0] / 0.8);
    EXPECT_GE(tau, 0.5 * (2 * (1 - slack) - delta) - 1e-4) << step;
    EXPECT_LE(tau, 0.5 * (2 * (1 + slack) + delta) + 1e-4) << step;
  }
}

}  // namespace
}  // namespace edrnr
