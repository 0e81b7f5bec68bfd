#include "render/cameras.h"

#include <cmath>
#include <nlohmann/json.hpp>
#include <numbers>

#include "core/error.h"
#include "core/file_io.h"

namespace edrnr {
namespace {

double deg_to_rad(double deg) { return deg * (std::numbers::pi / 180.0); }

double number_field(const nlohmann::json& j, const char* key, const std::string& source) {
  const auto it = j.find(key);
  if (it == j.end()) fail("{}: missing field \"{}\"", source, key);
  if (!it->is_number()) fail("{}: field \"{}\" is not a number", source, key);
  const double v = it->get<double>();
  if (!std::isfinite(v)) fail("{}: field \"{}\" is not finite", source, key);
  return v;
}

}  // namespace

Camera orbit_camera(int width, int height, double azimuth_deg, double elevation_deg, double radius, double fov_x_deg) {
  if (width <= 0 || height <= 0) fail("orbit camera image size {}x{} is empty", width, height);
  if (!(elevation_deg > -90.0 && elevation_deg < 90.0))
    fail("orbit elevation {} degrees is outside (-90, 90)", elevation_deg);
  if (!(radius > 0.0 && std::isfinite(radius))) fail("orbit radius {} must be positive", radius);
  if (!(fov_x_deg > 0.0 && fov_x_deg < 180.0)) fail("field of view {} degrees is outside (0, 180)", fov_x_deg);
  if (!std::isfinite(azimuth_deg)) fail("orbit azimuth {} is not finite", azimuth_deg);

  const double az = deg_to_rad(azimuth_deg), el = deg_to_rad(elevation_deg);
  const Vec3d pos{radius * std::cos(el) * std::cos(az), radius * std::cos(el) * std::sin(az), radius * std::sin(el)};
  const Vec3d back{std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};  // camera +Z
  const Vec3d right{-std::sin(az), std::cos(az), 0.0};                                       // camera +X
  const Vec3d up = cross(back, right);                                                       // camera +Y

  Camera cam;
  cam.width = width;
  cam.height = height;
  cam.fx = cam.fy = 0.5 * width / std::tan(0.5 * deg_to_rad(fov_x_deg));
  cam.cx = 0.5 * width;
  cam.cy = 0.5 * height;
  cam.c2w = {right.x, up.x, back.x, pos.x, right.y, up.y, back.y, pos.y, right.z, up.z, back.z, pos.z, 0, 0, 0, 1};
  return cam;
}

Camera parse_camera_json(const std::string& text, const std::string& source) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    fail("{}: not valid JSON: {}", source, e.what());
  }
  if (!j.is_object()) fail("{}: expected a JSON object", source);
  Camera cam;
  const double w = number_field(j, "w", source), h = number_field(j, "h", source);
  if (w < 1 || h < 1 || w != std::floor(w) || h != std::floor(h) || w > 65536 || h > 65536)
    fail("{}: image size {}x{} is not a positive whole number of pixels (at most 65536)", source, w, h);
  cam.width = int(w);
  cam.height = int(h);
  if (j.contains("fl_x")) {
    cam.fx = number_field(j, "fl_x", source);
    cam.fy = j.contains("fl_y") ? number_field(j, "fl_y", source) : cam.fx;
  } else if (j.contains("camera_angle_x")) {
    const double angle = number_field(j, "camera_angle_x", source);
    if (!(angle > 0 && angle < std::numbers::pi))
      fail("{}: camera_angle_x {} is outside (0, pi) radians", source, angle);
    cam.fx = cam.fy = 0.5 * w / std::tan(0.5 * angle);
  } else {
    fail("{}: needs \"camera_angle_x\" or \"fl_x\"", source);
  }
  if (!(cam.fx > 0 && cam.fy > 0)) fail("{}: focal lengths {}, {} must be positive", source, cam.fx, cam.fy);
  cam.cx = j.contains("cx") ? number_field(j, "cx", source) : 0.5 * w;
  cam.cy = j.contains("cy") ? number_field(j, "cy", source) : 0.5 * h;

  const auto it = j.find("transform_matrix");
  if (it == j.end()) fail("{}: missing field \"transform_matrix\"", source);
  const auto& m = *it;
  if (!m.is_array() || m.size() != 4) fail("{}: transform_matrix must be 4 rows of 4 numbers", source);
  for (int r = 0; r < 4; ++r) {
    if (!m[size_t(r)].is_array() || m[size_t(r)].size() != 4)
      fail("{}: transform_matrix must be 4 rows of 4 numbers", source);
    for (int c = 0; c < 4; ++c) {
      const auto& v = m[size_t(r)][size_t(c)];
      if (!v.is_number() || !std::isfinite(v.get<double>()))
        fail("{}: transform_matrix[{}][{}] is not a finite number", source, r, c);
      cam.c2w[size_t(4 * r + c)] = v.get<double>();
    }
  }
  return cam;
}

Camera load_camera_json(const std::filesystem::path& path) {
  return parse_camera_json(read_file_text(path), path.string());
}

Camera resize_camera(const Camera& camera, int width, int height) {
  if (width <= 0 || height <= 0) fail("image size {}x{} is empty", width, height);
  Camera c = camera;
  const double sx = double(width) / camera.width, sy = double(height) / camera.height;
  c.width = width;
  c.height = height;
  c.fx *= sx;
  c.cx *= sx;
  c.fy *= sy;
  c.cy *= sy;
  return c;
}

}  // namespace edrnr
