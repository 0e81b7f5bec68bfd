#pragma once
// A design-space sweep, as its SPEC file describes it (docs/sweeps.md):
//
//   base: edr_nr_40nm              # chip preset: a name in configs/chip/ or a YAML file
//   combine: product               # product | zip | random
//   samples: 16                    # random: how many distinct points
//   seed: 1                        # random: the seed
//   set: {simulator.clock_MHz: 200}         # keys fixed for every point
//   vary:                          # keys of the preset, dotted, each a domain:
//     rp_rob.entries: [8, 16, 32]                         # a list
//     feature_cache.bytes: {from: 65536, to: 262144, factor: 2}  # a geometric range
//     simulator.clock_MHz: {from: 100, to: 380, step: 40}        # an arithmetic range
//     render.step_micro: {from: 0.5, to: 2.0}             # random only: uniform in [from, to]
//   models:
//     - assets/lego.edrnr                                  # a file (beside SPEC, else the working folder)
//     - {file: assets/mic.edrnr, dataset: /data/mic}       # with a dataset: its views and ground truth
//     - {procedural: sphere, res: 64, channels: 8}         # made in memory (edrnr make-scene)
//   views:
//     width: 64                    # image size (default 800; a dataset's: a whole fraction)
//     height: 64
//     orbit: [30, 120]             # azimuths in degrees, for models without a dataset
//     elevation: 30
//     radius: 4
//     fov: 40
//     indices: [0]                 # dataset views, for models with a dataset
//     split: test
//   allow_over_budget: false       # true: simulate points over Table I's SRAM (marked)
//   include_base: true             # also the base design itself (the Pareto report marks it)
//
// Parsing checks everything that does not need the preset: the SPEC's own
// keys, types and ranges, each error naming the file, the line and the key.
// Whether a varied key exists in the preset is checked when the plan is made
// (sweep/plan.h), again with the line.
#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace edrnr::sweep {

enum class Combine { Product, Zip, Random };
const char* combine_name(Combine c);

// The values one varied key takes.
struct Domain {
  enum class Kind { List, Uniform };  // Uniform: a real interval (random only)
  Kind kind = Kind::List;
  std::vector<YAML::Node> values;  // List: in order (a range is expanded here)
  double from = 0, to = 0;         // Uniform
};

struct VariedKey {
  std::string key;  // dotted path into the preset, e.g. "rp_rob.entries"
  Domain domain;
  int line = 0;  // 1-based line of the key in SPEC
};

struct FixedKey {
  std::string key;
  YAML::Node value;
  int line = 0;
};

struct ModelSpec {
  std::string file;        // a .edrnr file (as written in SPEC); empty for a procedural model
  std::string procedural;  // sphere, box, torus or several
  int res = 64, channels = 8;
  uint64_t seed = 0;
  std::string dataset;  // a NeRF dataset folder: dataset views and ground truth
  int line = 0;
};

struct ViewSpec {
  int width = 800, height = 0;  // height 0: the width (orbit) or the view's aspect (dataset)
  bool width_set = false, height_set = false;
  std::vector<double> orbit_azimuths_deg = {30.0};
  double elevation_deg = 30, radius = 4, fov_deg = 40;
  std::vector<int> indices = {0};
  std::string split = "test";
};

struct SweepSpec {
  std::filesystem::path path;  // the SPEC file
  std::string text;            // its bytes (part of the plan's identity)
  std::string base = "edr_nr_40nm";
  int base_line = 0;
  Combine combine = Combine::Product;
  uint64_t samples = 0;  // random
  uint64_t seed = 1;     // random
  std::vector<FixedKey> fixed;
  std::vector<VariedKey> vary;
  std::vector<ModelSpec> models;
  ViewSpec views;
  bool allow_over_budget = false;
  bool include_base = true;
};

// Limits on a SPEC, checked while parsing.
inline constexpr uint64_t kMaxSweepPoints = 1000000;
inline constexpr size_t kMaxSweepModels = 1000;
inline constexpr size_t kMaxSweepViews = 10000;

// Reads and checks a SPEC file. Throws Error "<path>:<line>: <key>: <what is
// wrong>" for malformed YAML, an unknown key, a wrong type, an empty list or
// range, zip lists of different lengths, a uniform interval outside random,
// or a sweep over the limits above.
SweepSpec load_sweep_spec(const std::filesystem::path& path);
// The same from text (`path` only names it in messages and resolves files).
SweepSpec parse_sweep_spec(const std::string& text, const std::filesystem::path& path);

}  // namespace edrnr::sweep
