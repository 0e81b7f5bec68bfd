#pragma once
// The on-chip SRAM budget of a chip preset: every buffer the simulator models,
// in bytes computed from its entries and field widths, summed per Table I
// class (micro grid 8 KB, feature 256 KB, MLP 8.25 KB, others 43.2 KB) and
// checked against the class budgets (docs/simulator.md, "SRAM budget").
//
// The sizes depend on the model only through its shape: the micro-grid
// resolution (bitmaps, index widths), the feature channels (block bytes) and
// the MLP's stored bytes (the TME's weight registers).
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "sim/sim_config.h"

namespace edrnr::sim {

enum class SramClass { MicroGrid, Feature, Mlp, Others };
inline constexpr int kSramClasses = 4;
const char* sram_class_name(SramClass c);  // "micro_grid", "feature", "mlp", "others"

struct SramBuffer {
  std::string name;  // e.g. "rp_buffer"
  SramClass sram_class = SramClass::Others;
  uint64_t bytes = 0;
  std::string formula;  // how the bytes follow from the config, for people
};

// The shape of the model a preset is checked for.
struct SramModelShape {
  int micro_res = 256;
  int feature_channels = 16;
  uint64_t mlp_bytes = 0;  // TmeMlp::stored_bytes of one MLP (0: no MLP)
};

struct SramBudget {
  std::vector<SramBuffer> buffers;
  uint64_t class_bytes[kSramClasses] = {};   // sum of the buffers of each class
  uint64_t class_budget[kSramClasses] = {};  // Table I (config.sram_budget)

  uint64_t total_bytes() const;
  bool over_budget() const;
  // One line per class over its budget, naming the class, its largest buffers
  // and the overrun in bytes; empty when everything fits.
  std::vector<std::string> violations() const;
  // A table for people: each buffer, then each class against its budget.
  std::string format() const;
  nlohmann::json to_json() const;
};

// Sizes every buffer of `config` for a model of `shape`.
SramBudget compute_sram_budget(const SimConfig& config, const SramModelShape& shape);

}  // namespace edrnr::sim
