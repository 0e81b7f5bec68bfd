#include "data/camera.h"

namespace edrnr {

Ray Camera::ray_at(double u, double v) const {
  Vec3d d_cam{(u - cx) / fx, -(v - cy) / fy, -1.0};
  Vec3d d{c2w[0] * d_cam.x + c2w[1] * d_cam.y + c2w[2] * d_cam.z,
          c2w[4] * d_cam.x + c2w[5] * d_cam.y + c2w[6] * d_cam.z,
          c2w[8] * d_cam.x + c2w[9] * d_cam.y + c2w[10] * d_cam.z};
  return {origin(), normalize(d)};
}

}  // namespace edrnr
