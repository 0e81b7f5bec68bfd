#include "serve_view.h"

#include <fmt/format.h>

#include <algorithm>

#include "render/cameras.h"

namespace edrnr::serve {

ViewChoice parse_view(const Params& params, const Catalog& catalog, const std::string& model, int max_side) {
  ViewChoice v;
  if (!params.count("view")) {
    if (params.count("dataset")) reject(400, "dataset", "parameter 'dataset' needs 'view' (a test view index)");
    const double az = number_param(params, "az", -kMaxAzimuthDeg, kMaxAzimuthDeg, 30.0);
    const double el = number_param(params, "el", -kMaxElevationDeg, kMaxElevationDeg, 30.0);
    const double radius = number_param(params, "radius", kMinRadius, kMaxRadius, 4.0);
    const double fov = number_param(params, "fov", kMinFovDeg, kMaxFovDeg, 40.0);
    const int w = int_param(params, "w", kMinRenderSide, max_side, std::min(400, max_side));
    const int h = int_param(params, "h", kMinRenderSide, max_side, w);
    v.camera = orbit_camera(w, h, az, el, radius, fov);
    v.description = {{"kind", "orbit"}, {"azimuth_deg", az}, {"elevation_deg", el}, {"radius", radius},
                     {"fov_deg", fov},  {"width", w},        {"height", h}};
    return v;
  }
  for (const char* orbit_only : {"az", "el", "radius", "fov", "h"})
    if (params.count(orbit_only))
      reject(400, orbit_only,
             fmt::format("parameter '{}' cannot be combined with 'view' (a test view has its own camera)", orbit_only));
  const std::string own = catalog.model_entry(model).dataset;
  const std::string dataset =
      name_param(params, "dataset", catalog.dataset_names(), own.empty() ? std::nullopt : std::optional(own));
  const DatasetEntry& d = catalog.dataset(dataset);
  const int view = int_param(params, "view", 0, int(d.views.size()) - 1);
  const Camera& full = d.views[size_t(view)].camera;
  // Whole fractions of the view's size, largest first, within max_side.
  std::vector<int> widths;
  for (int f = 1; f <= full.width; ++f)
    if (full.width % f == 0 && full.height % f == 0 && full.width / f <= max_side && full.width / f >= kMinRenderSide)
      widths.push_back(full.width / f);
  if (widths.empty()) reject(400, "view", fmt::format("view {} of '{}' has no size within the limits", view, dataset));
  const int w = int_param(params, "w", kMinRenderSide, max_side, widths.front());
  if (std::find(widths.begin(), widths.end(), w) == widths.end()) {
    std::string list;
    for (size_t i = 0; i < widths.size() && i < 8; ++i) list += (i ? ", " : "") + std::to_string(widths[i]);
    reject(400, "w",
           fmt::format("parameter 'w' = {}: a test view ({}x{}) scales down by whole factors only ({}, ...)", w,
                       full.width, full.height, list));
  }
  v.factor = full.width / w;
  v.camera = full.downscaled(v.factor);
  v.dataset = dataset;
  v.view = view;
  v.description = {{"kind", "test_view"},
                   {"dataset", dataset},
                   {"view", view},
                   {"width", v.camera.width},
                   {"height", v.camera.height}};
  return v;
}

}  // namespace edrnr::serve
