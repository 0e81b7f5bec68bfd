#include "data/camera.h"

#include <cmath>

#include "core/error.h"

namespace edrnr {

Ray Camera::ray_at(double u, double v) const {
  Vec3d d_cam{(u - cx) / fx, -(v - cy) / fy, -1.0};
  Vec3d d{c2w[0] * d_cam.x + c2w[1] * d_cam.y + c2w[2] * d_cam.z,
          c2w[4] * d_cam.x + c2w[5] * d_cam.y + c2w[6] * d_cam.z,
          c2w[8] * d_cam.x + c2w[9] * d_cam.y + c2w[10] * d_cam.z};
  return {origin(), normalize(d)};
}

Camera Camera::downscaled(int factor) const {
  if (factor < 1) fail("downscale factor must be a positive integer, got {}", factor);
  if (width % factor || height % factor)
    fail("downscale factor {} does not divide the image size {}x{}", factor, width, height);
  Camera out = *this;
  out.width = width / factor;
  out.height = height / factor;
  out.fx = fx / factor;
  out.fy = fy / factor;
  out.cx = cx / factor;
  out.cy = cy / factor;
  return out;
}

double focal_from_fov(double size_px, double fov_rad) { return 0.5 * size_px / std::tan(0.5 * fov_rad); }

}  // namespace edrnr
