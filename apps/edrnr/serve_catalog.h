#pragma once
// What `edrnr serve` offers: the models (*.edrnr files of one folder, plus
// small procedural scenes), the datasets (sub-folders of one folder holding a
// transforms_test.json) and the chip presets. Only names listed here can be
// requested, so a request can never reach a file outside the served folders.
// Loaded models and ground-truth images are kept in small caches. All member
// functions are safe to call from several threads.
#include <cstdint>
#include <filesystem>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/image.h"
#include "data/camera.h"
#include "model/scene_model.h"

namespace edrnr::serve {

struct CatalogOptions {
  std::filesystem::path models_dir;  // *.edrnr files (not searched recursively)
  std::filesystem::path data_dir;    // empty: no datasets
  bool procedural = true;            // also offer procedural-<scene> models
  int procedural_micro_res = 64;     // their micro-grid resolution (small: quick to simulate)
  size_t model_cache_entries = 3;    // loaded models kept in memory
  size_t ground_truth_cache_entries = 16;
};

struct ModelEntry {
  std::string name;              // file stem, or procedural-<scene>
  std::filesystem::path path;    // empty for a procedural scene
  std::string procedural_scene;  // empty for a file
  uint64_t file_bytes = 0;
  std::string dataset;  // the dataset of the same name, if served
};

// A dataset's test view: its camera and the orbit that comes closest to it.
struct TestView {
  Camera camera;
  std::filesystem::path image_path;
  double azimuth_deg = 0, elevation_deg = 0, radius = 0, fov_deg = 0;
};

struct DatasetEntry {
  std::string name;
  std::filesystem::path root;
  std::vector<TestView> views;  // the test split
};

struct ChipPresetEntry {
  std::string name;
  std::filesystem::path path;
};

class Catalog {
 public:
  // Scans the folders. Throws Error naming a folder that does not exist; a
  // model or dataset that cannot be read is left out (and named in skipped()).
  explicit Catalog(CatalogOptions options, std::vector<std::filesystem::path> preset_dirs);

  const std::vector<ModelEntry>& models() const { return models_; }
  const std::vector<DatasetEntry>& datasets() const { return datasets_; }
  const std::vector<ChipPresetEntry>& presets() const { return presets_; }
  const std::vector<std::string>& skipped() const { return skipped_; }
  std::vector<std::string> model_names() const;
  std::vector<std::string> dataset_names() const;
  std::vector<std::string> preset_names() const;

  // Entries by a name from the lists above (Error for another name).
  const ModelEntry& model_entry(const std::string& name) const;
  const DatasetEntry& dataset(const std::string& name) const;
  const ChipPresetEntry& preset(const std::string& name) const;

  // The model, loaded (or built) once and kept while it is among the most
  // recently used. Throws Error if its file is unusable.
  std::shared_ptr<const SceneModel> model(const std::string& name);

  // Test view `view` of `dataset` composited on a white background and
  // box-filtered down by `factor` (which must divide the view's size).
  std::shared_ptr<const Image> ground_truth(const std::string& dataset, int view, int factor);

  // {"models": [...], "datasets": [...], "presets": [...]} for the browser.
  nlohmann::json to_json() const;

 private:
  CatalogOptions options_;
  std::vector<ModelEntry> models_;
  std::vector<DatasetEntry> datasets_;
  std::vector<ChipPresetEntry> presets_;
  std::vector<std::string> skipped_;

  std::mutex model_mutex_;
  std::list<std::pair<std::string, std::shared_ptr<const SceneModel>>> model_cache_;  // most recent first
  std::mutex gt_mutex_;
  std::list<std::pair<std::string, std::shared_ptr<const Image>>> gt_cache_;
};

}  // namespace edrnr::serve
