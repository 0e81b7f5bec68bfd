#pragma once
// A temporary folder with what edrnr serve's tests serve: models/tiny.edrnr (a
// procedural sphere), a model file whose name is not a plain name, and
// data/tiny, a two-view test split whose images are reference renders of the
// model written as 8-bit PNGs.
#include <unistd.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "core/file_io.h"
#include "core/image.h"
#include "model/model_io.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "render/reference.h"
#include "serve_catalog.h"

namespace edrnr::serve {

struct WebFixture {
  static constexpr int kViewSide = 32;
  std::filesystem::path dir;

  WebFixture() {
    static int counter = 0;
    dir = std::filesystem::temp_directory_path() /
          ("edrnr-web-test-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir / "models");
    std::filesystem::create_directories(dir / "data" / "tiny");
    ProceduralOptions po;
    po.micro_res = 64;
    const SceneModel model = make_procedural_model("sphere", procedural_shapes("sphere"), po);
    save_model(dir / "models" / "tiny.edrnr", model);
    write_file_atomic(dir / "models" / "bad name!.edrnr", std::string("not read"));
    nlohmann::json frames = nlohmann::json::array();
    for (int i = 0; i < 2; ++i) {
      const Camera cam = orbit_camera(kViewSide, kViewSide, 90.0 * i, 30.0, 4.0, 40.0);
      const Image img = render_reference(model, cam, RenderSettings{});
      Image rgba(img.width, img.height, 4, 1.f);
      for (size_t p = 0; p < size_t(img.width) * img.height; ++p)
        for (int c = 0; c < 3; ++c) rgba.data[p * 4 + c] = img.data[p * 3 + c];
      write_png(dir / "data" / "tiny" / ("r_" + std::to_string(i) + ".png"), rgba);
      nlohmann::json m = nlohmann::json::array();
      for (int r = 0; r < 4; ++r)
        m.push_back({cam.c2w[r * 4], cam.c2w[r * 4 + 1], cam.c2w[r * 4 + 2], cam.c2w[r * 4 + 3]});
      frames.push_back({{"file_path", "./r_" + std::to_string(i)}, {"transform_matrix", m}});
    }
    const nlohmann::json transforms = {{"camera_angle_x", 40.0 * M_PI / 180}, {"frames", frames}};
    write_file_atomic(dir / "data" / "tiny" / "transforms_test.json", transforms.dump(1));
  }
  ~WebFixture() {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }

  CatalogOptions options() const {
    CatalogOptions o;
    o.models_dir = dir / "models";
    o.data_dir = dir / "data";
    return o;
  }
  static std::vector<std::filesystem::path> chip_presets() {
    return {std::filesystem::path(EDRNR_SOURCE_DIR) / "configs" / "chip"};
  }
  static std::vector<std::filesystem::path> dram_presets() {
    return {std::filesystem::path(EDRNR_SOURCE_DIR) / "configs" / "dram"};
  }
  Catalog catalog() const { return Catalog(options(), chip_presets()); }
};

}  // namespace edrnr::serve
