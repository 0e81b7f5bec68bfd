#pragma once
// Cameras for the render commands: an orbit around the origin, a single
// camera read from a JSON file (docs/rendering.md), and resizing.
#include <filesystem>
#include <string>

#include "data/camera.h"

namespace edrnr {

// A pinhole camera on a circle around the origin, looking at it, with z up
// (Blender axes). The position is radius * (cos(el) cos(az), cos(el) sin(az),
// sin(el)); the image x axis stays horizontal. fov_x_deg is the full
// horizontal field of view; pixels are square and the principal point is the
// image centre. Throws Error for a size <= 0, an elevation outside (-90, 90),
// a radius <= 0 or a field of view outside (0, 180).
Camera orbit_camera(int width, int height, double azimuth_deg, double elevation_deg, double radius, double fov_x_deg);

// One camera from a JSON object with "w" and "h" (pixels), either
// "camera_angle_x" (radians, full horizontal field of view) or "fl_x"
// (pixels; "fl_y" defaults to fl_x), optional "cx"/"cy" (default w/2, h/2),
// and "transform_matrix" (4x4 camera-to-world, rows; NeRF convention). Throws
// Error naming `source` and the field that is missing or wrong.
Camera parse_camera_json(const std::string& text, const std::string& source);
Camera load_camera_json(const std::filesystem::path& path);

// The same view at another image size: fx, cx scale with width / camera.width,
// fy, cy with height / camera.height. Throws Error for a size <= 0.
Camera resize_camera(const Camera& camera, int width, int height);

}  // namespace edrnr
