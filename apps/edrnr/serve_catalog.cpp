#include "serve_catalog.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/file_io.h"
#include "data/dataset.h"
#include "model/model_io.h"
#include "model/procedural.h"
#include "serve_validate.h"

namespace edrnr::serve {

namespace fs = std::filesystem;

namespace {

constexpr double kPi = 3.14159265358979323846;

// Entries of `dir` sorted by name (so the listing is the same on every run).
std::vector<fs::directory_entry> sorted_entries(const fs::path& dir) {
  std::vector<fs::directory_entry> out;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) out.push_back(*it);
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.path() < b.path(); });
  return out;
}

void check_folder(const fs::path& dir, const char* flag) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) fail("{} '{}': no such folder", flag, dir.string());
}

TestView make_test_view(const Frame& f) {
  TestView v;
  v.camera = f.camera;
  v.image_path = f.image_path;
  const Vec3d o = f.camera.origin();
  v.radius = std::sqrt(o.x * o.x + o.y * o.y + o.z * o.z);
  v.elevation_deg = v.radius > 0 ? std::asin(std::clamp(o.z / v.radius, -1.0, 1.0)) * 180 / kPi : 0;
  v.azimuth_deg = std::atan2(o.y, o.x) * 180 / kPi;
  v.fov_deg = 2 * std::atan(0.5 * f.camera.width / f.camera.fx) * 180 / kPi;
  return v;
}

}  // namespace

Catalog::Catalog(CatalogOptions options, std::vector<fs::path> preset_dirs) : options_(std::move(options)) {
  check_folder(options_.models_dir, "--models");
  if (!options_.data_dir.empty()) check_folder(options_.data_dir, "--data");

  if (!options_.data_dir.empty()) {
    for (const fs::directory_entry& e : sorted_entries(options_.data_dir)) {
      const std::string name = e.path().filename().string();
      std::error_code ec;
      if (!is_safe_name(name) || !fs::is_regular_file(e.path() / "transforms_test.json", ec)) continue;
      try {
        DatasetEntry d;
        d.name = name;
        d.root = e.path();
        const fs::path json = e.path() / "transforms_test.json";
        for (const Frame& f : parse_transforms(read_file_text(json), e.path(), json.string()))
          d.views.push_back(make_test_view(f));
        if (d.views.empty()) fail("no test views");
        datasets_.push_back(std::move(d));
      } catch (const Error& err) {
        skipped_.push_back(fmt::format("dataset {}: {}", name, err.what()));
      }
    }
  }

  for (const fs::directory_entry& e : sorted_entries(options_.models_dir)) {
    std::error_code ec;
    if (e.path().extension() != ".edrnr" || !fs::is_regular_file(e.path(), ec)) continue;
    ModelEntry m;
    m.name = e.path().stem().string();
    if (!is_safe_name(m.name)) {
      skipped_.push_back(fmt::format("model file '{}': its name is not a plain name", e.path().filename().string()));
      continue;
    }
    m.path = e.path();
    m.file_bytes = fs::file_size(e.path(), ec);
    models_.push_back(std::move(m));
  }
  if (options_.procedural)
    for (const std::string& scene : procedural_scene_names()) {
      ModelEntry m;
      m.name = "procedural-" + scene;
      m.procedural_scene = scene;
      models_.push_back(std::move(m));
    }
  for (ModelEntry& m : models_)
    for (const DatasetEntry& d : datasets_)
      if (d.name == m.name) m.dataset = d.name;

  for (const fs::path& dir : preset_dirs)
    for (const fs::directory_entry& e : sorted_entries(dir)) {
      std::error_code ec;
      const std::string name = e.path().stem().string();
      if (e.path().extension() != ".yaml" || !fs::is_regular_file(e.path(), ec) || !is_safe_name(name)) continue;
      if (std::none_of(presets_.begin(), presets_.end(), [&](const auto& p) { return p.name == name; }))
        presets_.push_back({name, e.path()});
    }
}

std::vector<std::string> Catalog::model_names() const {
  std::vector<std::string> out;
  for (const ModelEntry& m : models_) out.push_back(m.name);
  return out;
}

std::vector<std::string> Catalog::dataset_names() const {
  std::vector<std::string> out;
  for (const DatasetEntry& d : datasets_) out.push_back(d.name);
  return out;
}

std::vector<std::string> Catalog::preset_names() const {
  std::vector<std::string> out;
  for (const ChipPresetEntry& p : presets_) out.push_back(p.name);
  return out;
}

const ModelEntry& Catalog::model_entry(const std::string& name) const {
  for (const ModelEntry& m : models_)
    if (m.name == name) return m;
  fail("model '{}': not served", name);
}

const DatasetEntry& Catalog::dataset(const std::string& name) const {
  for (const DatasetEntry& d : datasets_)
    if (d.name == name) return d;
  fail("dataset '{}': not served", name);
}

const ChipPresetEntry& Catalog::preset(const std::string& name) const {
  for (const ChipPresetEntry& p : presets_)
    if (p.name == name) return p;
  fail("chip preset '{}': not served", name);
}

std::shared_ptr<const SceneModel> Catalog::model(const std::string& name) {
  const ModelEntry& entry = model_entry(name);
  std::lock_guard lock(model_mutex_);
  for (auto it = model_cache_.begin(); it != model_cache_.end(); ++it)
    if (it->first == name) {
      model_cache_.splice(model_cache_.begin(), model_cache_, it);
      return model_cache_.front().second;
    }
  std::shared_ptr<const SceneModel> m;
  if (entry.procedural_scene.empty()) {
    m = std::make_shared<const SceneModel>(load_model(entry.path));
  } else {
    ProceduralOptions po;
    po.micro_res = options_.procedural_micro_res;
    po.store_float = false;
    m = std::make_shared<const SceneModel>(
        make_procedural_model(entry.procedural_scene, procedural_shapes(entry.procedural_scene), po));
  }
  model_cache_.emplace_front(name, m);
  while (model_cache_.size() > std::max<size_t>(1, options_.model_cache_entries)) model_cache_.pop_back();
  return m;
}

std::shared_ptr<const Image> Catalog::ground_truth(const std::string& dataset_name, int view, int factor) {
  const DatasetEntry& d = dataset(dataset_name);
  if (view < 0 || size_t(view) >= d.views.size())
    fail("dataset '{}': view {} out of range 0..{}", dataset_name, view, d.views.size() - 1);
  const std::string key = fmt::format("{}/{}/{}", dataset_name, view, factor);
  std::lock_guard lock(gt_mutex_);
  for (auto it = gt_cache_.begin(); it != gt_cache_.end(); ++it)
    if (it->first == key) {
      gt_cache_.splice(gt_cache_.begin(), gt_cache_, it);
      return gt_cache_.front().second;
    }
  Frame f;
  f.camera = d.views[size_t(view)].camera;
  f.image_path = d.views[size_t(view)].image_path;
  const float white[3] = {1.f, 1.f, 1.f};
  Image rgb = composite_rgba(read_frame_rgba(f, 1), white);
  if (factor > 1) rgb = downscale(rgb, factor);
  auto img = std::make_shared<const Image>(std::move(rgb));
  gt_cache_.emplace_front(key, img);
  while (gt_cache_.size() > std::max<size_t>(1, options_.ground_truth_cache_entries)) gt_cache_.pop_back();
  return img;
}

nlohmann::json Catalog::to_json() const {
  nlohmann::json models = nlohmann::json::array(), datasets = nlohmann::json::array(),
                 presets = nlohmann::json::array();
  for (const ModelEntry& m : models_)
    models.push_back({{"name", m.name},
                      {"kind", m.procedural_scene.empty() ? "file" : "procedural"},
                      {"file_bytes", m.file_bytes},
                      {"dataset", m.dataset}});
  for (const DatasetEntry& d : datasets_) {
    nlohmann::json views = nlohmann::json::array();
    for (const TestView& v : d.views)
      views.push_back({{"width", v.camera.width},
                       {"height", v.camera.height},
                       {"azimuth_deg", v.azimuth_deg},
                       {"elevation_deg", v.elevation_deg},
                       {"radius", v.radius},
                       {"fov_deg", v.fov_deg}});
    datasets.push_back({{"name", d.name}, {"test_views", views}});
  }
  for (const ChipPresetEntry& p : presets_) presets.push_back(p.name);
  return {{"models", models}, {"datasets", datasets}, {"presets", presets}};
}

}  // namespace edrnr::serve
