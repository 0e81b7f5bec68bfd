#pragma once
// The camera a render or simulation request asks for: either an orbit
// (az, el, radius, fov, w, h) or a dataset's test view (view, optional
// dataset, w as a whole fraction of the view's width).
#include <nlohmann/json.hpp>
#include <string>

#include "data/camera.h"
#include "serve_catalog.h"
#include "serve_validate.h"

namespace edrnr::serve {

struct ViewChoice {
  Camera camera;
  std::string dataset;         // with a test view: its dataset
  int view = -1;               // the test view index, or -1 for an orbit
  int factor = 1;              // the test view's downscale factor
  nlohmann::json description;  // what was asked, for reports
};

// The parameters parse_view reads.
inline const std::vector<std::string_view> kViewParams = {"az", "el", "radius", "fov", "w", "h", "view", "dataset"};

// Reads the view parameters for `model` (a catalog name). Orbit: az in
// [-kMaxAzimuthDeg, kMaxAzimuthDeg] (default 30), el in [-89, 89] (30),
// radius in [kMinRadius, kMaxRadius] (4), fov in [kMinFovDeg, kMaxFovDeg]
// (40), w and h in [kMinRenderSide, max_side] (w default 400, h default w).
// Test view: view in 0..N-1 of the dataset (default: the model's own), w a
// whole fraction of the view's width that is at most max_side (default: the
// largest such fraction); the orbit parameters are then refused. Throws
// RequestError (400, or 404 for an unknown dataset).
ViewChoice parse_view(const Params& params, const Catalog& catalog, const std::string& model, int max_side);

}  // namespace edrnr::serve
