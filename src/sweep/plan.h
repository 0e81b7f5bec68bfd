#pragma once
// The plan of a sweep: its points (one resolved chip config each), its models
// and views, and its jobs (point x model x view), each with the key that
// identifies its result across runs (resume) and processes (workers, MPI
// ranks, Slurm shards). Every process that reads the same SPEC makes the same
// plan, bit for bit; plan_hash() lets them check it.
#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/image.h"
#include "data/camera.h"
#include "model/scene_model.h"
#include "sim/sim_config.h"
#include "sweep/spec.h"

namespace edrnr::sweep {

// Where presets are looked up: chip presets by name (base), DRAM presets
// (simulator.memory.dram given as a name).
struct SearchDirs {
  std::vector<std::filesystem::path> chip;
  std::vector<std::filesystem::path> dram;
};

// One design point: the values of the varied keys, in SPEC order.
struct Point {
  size_t index = 0;                      // 0-based, in SPEC order (product: the last key varies fastest)
  std::vector<YAML::Node> values;        // one per varied key
  std::optional<sim::SimConfig> config;  // resolved; empty when the values make no valid config
  std::string config_error;              // why not (then config_hash hashes the preset text instead)
  std::string config_yaml;               // the fully resolved config (sim_config_to_yaml) when valid
  std::string config_hash;               // run_hash of the resolved config and its energy tables
};

struct SweepModel {
  std::string name;     // the file's stem or the procedural scene's name
  std::string source;   // the path, or "procedural sphere res 64 channels 8 seed 0"
  std::string hash;     // run_hash of the serialized model
  std::string dataset;  // resolved dataset folder; empty without one
  std::shared_ptr<const SceneModel> model;
};

struct SweepView {
  std::string name;  // "orbit30" or "test/0"
  Camera camera;
  Image ground_truth;  // empty without a dataset
};

struct Job {
  size_t point = 0, model = 0, view = 0;  // view indexes views[model]
  std::string key;                        // run_hash(config hash, model hash, view name and camera)
};

struct SweepPlan {
  SweepSpec spec;
  std::filesystem::path base_preset;  // the chip preset file
  YAML::Node base_yaml;               // its YAML, as read
  sim::SimConfig base_config;         // the base with the `set` keys (the paper's design when base is edr_nr_40nm)
  std::vector<std::string> varied;    // varied keys, SPEC order
  std::vector<Point> points;
  std::vector<SweepModel> models;
  std::vector<std::vector<SweepView>> views;  // per model
  std::vector<Job> jobs;                      // point-major, then model, then view
  size_t duplicate_points = 0;                // points dropped because an earlier one had the same config
  std::string base_config_hash;               // config_hash of base_config
  std::optional<size_t> base_point;           // the point whose config is base_config, if any
};

// Makes the plan: loads the base preset and every model, makes the cameras,
// expands the points and resolves each point's config. With include_base the
// base design (the base preset with the `set` keys: its own values of the
// varied keys) is a point too, after the others unless one of them has its
// config already. A varied or fixed key
// that the preset does not have, or a value of the wrong type (text for a
// number, a number for a switch), throws Error naming SPEC's line. A value that
// is of the right type but out of range does not: that point's config_error
// says why and its jobs become error rows.
SweepPlan make_plan(const SweepSpec& spec, const SearchDirs& dirs);

// The chip config of `node` with key (dotted) set to `value`, creating maps
// on the way. Throws Error if a part of the path is not a map.
void set_key(YAML::Node& node, const std::string& dotted_key, const YAML::Node& value);

// A YAML scalar as JSON: an integer, a number, true/false, or text; a map or
// list as the same structure.
nlohmann::json yaml_to_json(const YAML::Node& node);

// One hash over every job key, in order: processes compare it before sharing work.
std::string plan_hash(const SweepPlan& plan);

// The n-th value of a 64-bit splitmix stream seeded with `seed` (random
// sampling; the same on every machine).
uint64_t splitmix64(uint64_t seed, uint64_t n);

}  // namespace edrnr::sweep
