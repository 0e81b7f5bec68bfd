#include "train/synthetic.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/file_io.h"
#include "core/image.h"
#include "render/cameras.h"
#include "render/reference.h"

namespace edrnr::train {

void write_synthetic_dataset(const SceneModel& model, const std::filesystem::path& dir, const SyntheticViews& views) {
  if (views.train_views < 1 || views.test_views < 0 || views.width < 1 || views.height < 1)
    fail("synthetic dataset: need at least one training view and a positive image size");
  const double kPi = 3.14159265358979323846;
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  const int total = views.train_views + views.test_views;
  RenderSettings on_white, on_black;
  for (int c = 0; c < 3; ++c) on_black.background[c] = 0.f;
  nlohmann::json split_json[2];
  for (auto& j : split_json) {
    j["camera_angle_x"] = views.fov_x_deg * kPi / 180.0;
    j["frames"] = nlohmann::json::array();
  }
  int counts[2] = {0, 0};
  for (int v = 0; v < total; ++v) {
    // Every (total / test)-th view is a test view.
    const bool test =
        views.test_views > 0 && (v % std::max(1, total / views.test_views)) == 1 && counts[1] < views.test_views;
    const int s = test ? 1 : (counts[0] < views.train_views ? 0 : 1);
    // Elevations from -60 to +75 degrees, azimuths by the golden angle.
    const double u = (v + 0.5) / total;
    const double elevation = -60.0 + 135.0 * u;
    const double azimuth = std::fmod(v * golden * 180.0 / kPi, 360.0);
    const Camera cam = orbit_camera(views.width, views.height, azimuth, elevation, views.radius, views.fov_x_deg);
    const Image white = render_reference(model, cam, on_white);
    Image img = white;
    if (views.alpha) {
      // pixel = rgb a + (1 - a) bg, so 1 - a = white - black, the same in every channel.
      const Image black = render_reference(model, cam, on_black);
      img = Image(white.width, white.height, 4);
      for (size_t p = 0; p < size_t(white.width) * white.height; ++p) {
        float t = 0.f;
        for (int c = 0; c < 3; ++c) t += white.data[3 * p + size_t(c)] - black.data[3 * p + size_t(c)];
        const float a = std::clamp(1.f - t / 3.f, 0.f, 1.f);
        for (int c = 0; c < 3; ++c)
          img.data[4 * p + size_t(c)] = a > 0.f ? std::min(1.f, black.data[3 * p + size_t(c)] / a) : 0.f;
        img.data[4 * p + 3] = a;
      }
    }
    const std::string name = fmt::format("{}/r_{}", s ? "test" : "train", counts[s]);
    std::filesystem::create_directories(dir / (s ? "test" : "train"));
    write_png(dir / (name + ".png"), img);
    nlohmann::json frame;
    frame["file_path"] = "./" + name;
    nlohmann::json m = nlohmann::json::array();
    for (int r = 0; r < 4; ++r) {
      nlohmann::json row = nlohmann::json::array();
      for (int c = 0; c < 4; ++c) row.push_back(cam.c2w[size_t(4 * r + c)]);
      m.push_back(row);
    }
    frame["transform_matrix"] = m;
    split_json[s]["frames"].push_back(frame);
    ++counts[s];
  }
  write_file_atomic(dir / "transforms_train.json", split_json[0].dump(1));
  write_file_atomic(dir / "transforms_test.json", split_json[1].dump(1));
}

}  // namespace edrnr::train
