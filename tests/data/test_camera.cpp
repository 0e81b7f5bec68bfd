#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/error.h"
#include "data/camera.h"

namespace edrnr {
namespace {

// A 4x4 image with focal length 2 px and the principal point at its centre.
Camera small_camera() {
  Camera cam;
  cam.width = 4;
  cam.height = 4;
  cam.fx = 2;
  cam.fy = 2;
  cam.cx = 2;
  cam.cy = 2;
  return cam;
}

void expect_vec_near(const Vec3d& got, const Vec3d& want, double tol = 1e-12) {
  EXPECT_NEAR(got.x, want.x, tol);
  EXPECT_NEAR(got.y, want.y, tol);
  EXPECT_NEAR(got.z, want.z, tol);
}

TEST(Camera, IdentityPoseLooksDownMinusZThroughPrincipalPoint) {
  Camera cam = small_camera();
  Ray r = cam.ray_at(2, 2);
  expect_vec_near(r.origin, {0, 0, 0}, 0);
  expect_vec_near(r.dir, {0, 0, -1}, 0);
}

TEST(Camera, CornerPixelCentresPointLeftUpAndRightDown) {
  Camera cam = small_camera();
  // Pixel (0, 0) has its centre at (0.5, 0.5): camera-space direction
  // ((0.5 - 2) / 2, -(0.5 - 2) / 2, -1) = (-0.75, 0.75, -1), |.| = sqrt(2.125).
  double len = std::sqrt(0.75 * 0.75 * 2 + 1);
  expect_vec_near(cam.pixel_ray(0, 0).dir, {-0.75 / len, 0.75 / len, -1 / len});
  // Pixel (3, 3): centre (3.5, 3.5), direction (0.75, -0.75, -1).
  expect_vec_near(cam.pixel_ray(3, 3).dir, {0.75 / len, -0.75 / len, -1 / len});
  // Pixel (3, 0), top right: (0.75, 0.75, -1).
  expect_vec_near(cam.pixel_ray(3, 0).dir, {0.75 / len, 0.75 / len, -1 / len});
}

TEST(Camera, SeparateFocalLengthsAndOffCentrePrincipalPoint) {
  Camera cam = small_camera();
  cam.fx = 4;
  cam.fy = 1;
  cam.cx = 1;
  cam.cy = 3;
  // (u, v) = (3, 1): ((3 - 1) / 4, -(1 - 3) / 1, -1) = (0.5, 2, -1), |.| = sqrt(5.25).
  double len = std::sqrt(5.25);
  expect_vec_near(cam.ray_at(3, 1).dir, {0.5 / len, 2 / len, -1 / len});
}

TEST(Camera, RotatedAndTranslatedPose) {
  Camera cam = small_camera();
  // Rotation by +90 degrees about world Y (camera X -> world -Z, camera Z ->
  // world X), camera placed at (1, 2, 3).
  cam.c2w = {0,  0, 1, 1,  //
             0,  1, 0, 2,  //
             -1, 0, 0, 3,  //
             0,  0, 0, 1};
  Ray centre = cam.ray_at(2, 2);
  expect_vec_near(centre.origin, {1, 2, 3}, 0);
  expect_vec_near(cam.origin(), {1, 2, 3}, 0);
  // Camera -Z maps to world -X.
  expect_vec_near(centre.dir, {-1, 0, 0});
  // Camera (-0.75, 0.75, -1) maps to world (-1, 0.75, 0.75).
  double len = std::sqrt(2.125);
  Ray corner = cam.pixel_ray(0, 0);
  expect_vec_near(corner.origin, {1, 2, 3}, 0);
  expect_vec_near(corner.dir, {-1 / len, 0.75 / len, 0.75 / len});
}

TEST(Camera, DirectionsAreUnitLength) {
  Camera cam = small_camera();
  cam.fx = 0.3;
  cam.c2w = {2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1};  // a scaled pose
  for (int j = 0; j < 4; ++j)
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(length(cam.pixel_ray(i, j).dir), 1.0, 1e-15);
}

TEST(Camera, FocalFromFieldOfView) {
  // A 90-degree field of view over 800 px: f = 400 / tan(45 deg) = 400.
  EXPECT_NEAR(focal_from_fov(800, std::numbers::pi / 2), 400.0, 1e-12);
  // 60 degrees: f = 400 / tan(30 deg) = 400 * sqrt(3).
  EXPECT_NEAR(focal_from_fov(800, std::numbers::pi / 3), 400.0 * std::sqrt(3.0), 1e-9);
}

TEST(Camera, DownscaledKeepsRaysThroughBlockCentres) {
  Camera cam;
  cam.width = 8;
  cam.height = 4;
  cam.fx = 10;
  cam.fy = 12;
  cam.cx = 4.5;
  cam.cy = 1.5;
  cam.c2w = {0, 0, 1, 1, 0, 1, 0, 2, -1, 0, 0, 3, 0, 0, 0, 1};
  Camera half = cam.downscaled(2);
  EXPECT_EQ(half.width, 4);
  EXPECT_EQ(half.height, 2);
  EXPECT_EQ(half.fx, 5);
  EXPECT_EQ(half.fy, 6);
  EXPECT_EQ(half.cx, 2.25);
  EXPECT_EQ(half.cy, 0.75);
  // Output pixel (i, j) averages input pixels 2i, 2i+1 (centres 2i+0.5 and
  // 2i+1.5), so its centre is input position 2i+1.
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 4; ++i) expect_vec_near(half.pixel_ray(i, j).dir, cam.ray_at(2 * i + 1, 2 * j + 1).dir);
  Camera same = cam.downscaled(1);
  EXPECT_EQ(same.width, 8);
  EXPECT_EQ(same.fx, 10);
}

TEST(Camera, DownscaledRejectsBadFactors) {
  Camera cam = small_camera();
  EXPECT_THROW(cam.downscaled(3), Error);
  EXPECT_THROW(cam.downscaled(0), Error);
  try {
    cam.downscaled(3);
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("does not divide"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace edrnr
