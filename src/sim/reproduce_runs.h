#pragma once
// The simulations behind `edrnr reproduce` (docs/reproduction.md): for every
// scene and view, the full design at the preset's clock, each data-reuse
// technique switched off alone, all of them off together, and the full design
// at each of Table I's operating points (each at its own clock).
//
// Every simulation is cached as <runs_dir>/<key>.json, where the key is a hash
// of the model file's bytes, the camera (the view), the image size, the ground
// truth and the fully resolved config (sim_config_to_yaml), so a rerun skips
// what is done, and a changed preset or model runs again. The JSON holds the
// simulator's own statistics (SimResult::stats as to_json writes them), the
// hit-rate series, the SRAM budget and the energy, exactly as the simulator
// produced them: the report reads its numbers from these files only.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/image.h"
#include "data/camera.h"
#include "model/scene_model.h"
#include "sim/sim_config.h"

namespace edrnr::sim {

// The techniques a run can switch off, in the order of `edrnr simulate
// --disable`: zorder, aabb, lagfirst, reorder, ooo, balanced.
const std::vector<std::string>& technique_names();
// The paper's name of a technique ("ZORG (Z-order)", ...), for reports.
const char* technique_label(const std::string& technique);
// Switches one technique off in `chip`. Throws Error naming it if unknown.
void disable_technique(ChipConfig& chip, const std::string& technique);

// One configuration of the evaluation.
struct RunVariant {
  enum class Kind { Full, TechniqueOff, AllOff, OperatingPoint };
  Kind kind = Kind::Full;
  std::string technique;  // TechniqueOff: which one
  double clock_MHz = 0;   // OperatingPoint: the point's clock

  // "full", "off_zorder", ..., "all_off", "point_50MHz".
  std::string name() const;
};

// The variants of one view, in the order they are best run (the slowest,
// everything off, first): all off, each technique off, the full design, and
// each Table I point whose clock differs from the preset's (the one that
// equals it is the full design).
std::vector<RunVariant> evaluation_variants(const SimConfig& preset);
// The preset with the variant applied (switches, bank mapping or clock).
SimConfig variant_config(const SimConfig& preset, const RunVariant& variant);

struct ReproView {
  int index = 0;       // test view of the dataset, or orbit position in --quick
  Camera camera;       // at the simulated size
  Image ground_truth;  // composited on the chip's background; empty without one
};

struct ReproScene {
  std::string name;                         // "lego", or a procedural scene's name
  std::string model_source;                 // the model's path, or how it was made
  std::shared_ptr<const SceneModel> model;  // finalize()d, checked
  std::string model_hash;                   // run_hash of the model file's bytes
  std::string data_source;                  // the dataset folder; empty without one
  std::vector<ReproView> views;
};

// A 128-bit hash of bytes, as 32 hex digits (FNV-1a 64 beside a
// multiply-xorshift hash; for cache keys, not for security).
std::string run_hash(const void* data, size_t size);

// One simulation to have: which scene, view and variant, its config and key.
struct RunSpec {
  size_t scene = 0, view = 0;  // indices into the scenes and their views
  RunVariant variant;
  SimConfig config;
  std::string key;
};

// The text that identifies a resolved config: sim_config_to_yaml, then the
// contents of its energy tables (a refitted table row is a different config).
std::string config_identity_text(const SimConfig& config);
// run_hash of config_identity_text: one config, one hash (edrnr sweep's
// config_hash).
std::string config_hash(const SimConfig& config);

// The cache key of a run (see the top of this file).
std::string run_key(const ReproScene& scene, const ReproView& view, const SimConfig& config);

// Every run of every scene and view, variant order as evaluation_variants.
// Validates each config (Error naming the variant).
std::vector<RunSpec> plan_runs(const std::vector<ReproScene>& scenes, const SimConfig& preset);

// Where a run's files are: <runs_dir>/<key>.json and, for the full design, the
// rendered image <runs_dir>/<key>.png.
std::filesystem::path run_json_path(const std::filesystem::path& runs_dir, const std::string& key);
std::filesystem::path run_image_path(const std::filesystem::path& runs_dir, const std::string& key);

// A cached run: its JSON if the file exists, parses and carries this key
// (anything else is treated as not done).
std::optional<nlohmann::json> load_cached_run(const std::filesystem::path& runs_dir, const std::string& key);

struct RunProgress {
  size_t done = 0;    // simulations finished in this call (cached ones not counted)
  size_t to_run = 0;  // simulations this call runs
  double elapsed_s = 0;
};

struct ExecuteOptions {
  int jobs = 1;  // simulations at once, each on its own thread
  // Called from the worker threads (serialised) after each simulation.
  std::function<void(const RunProgress&)> progress;
};

struct ExecuteSummary {
  size_t distinct = 0;  // distinct simulations in the plan
  size_t cached = 0;    // found in runs_dir
  size_t ran = 0;       // simulated now
  double seconds = 0;   // wall time of this call
};

// Simulates every distinct run of the plan that runs_dir does not hold yet,
// on `jobs` threads, and writes its JSON (and image) atomically. The first
// failing simulation stops the others and its Error is rethrown.
ExecuteSummary execute_runs(const std::vector<ReproScene>& scenes, const std::vector<RunSpec>& plan,
                            const std::filesystem::path& runs_dir, const ExecuteOptions& options);

}  // namespace edrnr::sim
