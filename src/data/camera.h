#pragma once
// Pinhole cameras in the NeRF / Blender convention: the camera looks along its
// -Z axis, +Y is up, +X is right; c2w maps camera to world coordinates.
#include <array>

#include "core/vec.h"

namespace edrnr {

struct Ray {
  Vec3d origin;
  Vec3d dir;  // unit length
};

struct Camera {
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;                                       // pixels
  std::array<double, 16> c2w{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};  // row-major 4x4

  // The ray through image position (u, v) in pixels, where (0, 0) is the
  // top-left corner of the image and pixel (i, j) has its centre at
  // (i + 0.5, j + 0.5). Camera-space direction: ((u-cx)/fx, -(v-cy)/fy, -1).
  Ray ray_at(double u, double v) const;
  Ray pixel_ray(int i, int j) const { return ray_at(i + 0.5, j + 0.5); }
  Vec3d origin() const { return {c2w[3], c2w[7], c2w[11]}; }

  // The same camera for an image box-filtered by an integer factor: size and
  // intrinsics divided by `factor`, so that output pixel (i, j) sees the centre
  // of the factor x factor input pixels it averages. Throws Error unless
  // factor >= 1 divides width and height.
  Camera downscaled(int factor) const;
};

// Focal length in pixels of a pinhole camera whose image, `size_px` pixels
// wide, spans the full field-of-view angle `fov_rad`: 0.5 * size / tan(fov / 2).
double focal_from_fov(double size_px, double fov_rad);

}  // namespace edrnr
