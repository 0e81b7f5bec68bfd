#pragma once
// Configuration of the cycle simulator: the functional chip (ChipConfig) plus
// the timing of each unit, the memory system, the energy tables and the
// operating points. All of it comes from one chip preset (configs/chip/*.yaml):
// the functional keys at the top level, the rest under `simulator:`
// (docs/simulator.md lists every key with its reason).
#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "chip/chip.h"
#include "sim/cache.h"
#include "sim/dram_config.h"
#include "sim/energy.h"

namespace edrnr::sim {

struct SimTiming {
  // Front end (ZORG, ABT, TSPS): an RP takes max(zorg_cycles_per_rp,
  // ceil(TSPS position evaluations / tsps_position_evals_per_cycle)) cycles;
  // its pointer reaches the CTU front_end_latency_cycles later.
  int zorg_cycles_per_rp = 1;
  int tsps_position_evals_per_cycle = 24;
  int front_end_latency_cycles = 6;
  // CTU and FTU: an LFAU iteration (ray selection, one bitmap check, the
  // exits of the selected rays) takes cycles_per_iteration cycles.
  int ctu_cycles_per_iteration = 1;
  int ftu_cycles_per_iteration = 1;
  // FTU inside an occupied fine voxel: every leaf visited and every candidate
  // of an occupied leaf tested against its micro bit takes one cycle of one of
  // ftu_lanes lanes.
  int ftu_lanes = 4;
  // CFIU: cycles_per_sample per sample plus one per bank conflict; its result
  // reaches the TME latency_cycles later through a queue of latency + slots.
  int cfiu_cycles_per_sample = 1;
  int cfiu_latency_cycles = 4;
  int cfiu_fifo_slots = 4;
  // TME: ceil(MACs per sample / macs_per_cycle) cycles per sample; a CV switch
  // copies the MLP into the MAC array at weight_load_bytes_per_cycle.
  int tme_macs_per_cycle = 1024;
  int tme_latency_cycles = 12;
  int tme_fifo_slots = 4;
  int tme_weight_load_bytes_per_cycle = 64;
  // 1: the array holds one MLP, a CV switch stops the TME; 2: a second
  // (shadow) set of weight registers takes the next CV's MLP while the
  // current samples finish.
  int tme_weight_buffers = 1;
  // VRU: cycles per sample; the retire/reschedule decision follows the last
  // sample of a batch latency_cycles later.
  int vru_cycles_per_sample = 1;
  int vru_latency_cycles = 2;
  bool operator==(const SimTiming&) const = default;
};

// Geometry and timing of a tag cache in front of DRAM; its size comes from
// the functional config (micro_grid_cache_bytes, mlp_cache_bytes).
struct SimCacheConfig {
  uint64_t line_bytes = 64;
  uint64_t ways = 4;  // 0: fully associative
  Replacement replacement = Replacement::Lru;
  uint64_t random_seed = 1;
  size_t mshr_entries = 4;
  uint64_t hit_latency_cycles = 1;
  bool operator==(const SimCacheConfig&) const = default;
};

struct SimMemory {
  std::string dram_source;  // the preset name or file the DRAM config came from
  DramConfig dram;
  uint32_t max_request_bytes = 64;  // larger transfers are split into DRAM requests of at most this size
  bool preload_bitmaps = true;      // read the coarse and fine bitmaps from DRAM before traversal starts
  bool write_output = false;        // write each finished RP's record (pixels, coordinates) to DRAM (else: to the host)
  uint32_t output_record_bytes = 16;
  SimCacheConfig micro_grid_cache{64, 4, Replacement::Lru, 1, 4, 1};
  SimCacheConfig mlp_cache{64, 0, Replacement::Lru, 1, 8, 1};
  // When the RP-ROB switches to a new CV tag, the MLP cache starts fetching
  // that CV's MLP lines (uncounted prefetches), so that the TME finds them on
  // chip when the tag's first batch reaches it.
  bool mlp_prefetch = false;
};

enum class DramEnergySource {
  Events,  // the energy table's dram_bit per bit moved (whole interface)
  Model,   // the DDR3 model's own current-based energy (DRAM core only)
  Access,  // the DDR3 model's access energy (activates, reads, writes; no background or refresh)
           // plus the table's dram_io_bit per bit moved
};
const char* dram_energy_source_name(DramEnergySource s);

struct SimEnergy {
  std::filesystem::path events_csv;   // empty: no energy evaluation
  std::filesystem::path leakage_csv;  // empty: no leakage
  double leakage_voltage_exponent = 1.0;
  DramEnergySource dram = DramEnergySource::Access;
};

// Table I's on-chip SRAM classes, in bytes (sim/sram_budget.h checks every
// buffer against them).
struct SramBudgetLimits {
  uint64_t micro_grid_bytes = 8192;  // 8 KB
  uint64_t feature_bytes = 262144;   // 256 KB
  uint64_t mlp_bytes = 8448;         // 8.25 KB
  uint64_t others_bytes = 44236;     // 43.2 KB
};

struct SimConfig {
  ChipConfig chip;
  double clock_MHz = 380.0;  // core clock
  SimTiming timing;
  SimMemory memory;
  SimEnergy energy;
  std::vector<OperatingPoint> operating_points;  // ascending frequency; the voltage at a clock comes from here
  uint64_t hit_rate_window_cycles = 20000;       // window of the hit-rate series (Fig. 8)
  SramBudgetLimits sram_budget;
};

// The tag store of one of the simulator's caches: its preset section `s`,
// named `name`, of `size_bytes`, with its hit-rate series in windows of
// `window_cycles` (not validated here).
CacheConfig make_cache_config(const SimCacheConfig& s, const char* name, int64_t size_bytes, uint64_t window_cycles);

// Throws Error naming the field when a value is out of range, including the
// limits of core/limits.h (clock, sizes that are allocated, latencies).
void validate(const SimConfig& config);

// The limits of core/limits.h on a functional chip config (sizes that are
// allocated: RP buffer, RP-ROB, queues, caches). edrnr::validate(ChipConfig)
// checks the values' meaning; this checks that they stay within what a run
// can hold. Throws Error naming the field, the value and the limit.
void check_chip_limits(const ChipConfig& config);

// Reads a chip preset. The `simulator` section's DRAM (a preset name looked up
// in <base_dir>/../dram and dram_search_dirs, a path, or a map in the
// configs/dram schema) and energy table paths are resolved relative to
// base_dir. Missing keys keep their defaults, which are the values of
// configs/chip/edr_nr_40nm.yaml: without a `simulator.memory.dram` the
// DDR3-1600 x16 16-bit preset is looked up, without `simulator.energy` the
// tables <base_dir>/../energy/{events,leakage}.csv are used if they exist. An
// unknown key or a bad value throws Error naming `where` and the key.
SimConfig sim_config_from_yaml(const YAML::Node& node, std::string_view where, const std::filesystem::path& base_dir,
                               const std::vector<std::filesystem::path>& dram_search_dirs);
// Loads a preset file; DRAM presets are looked for beside the chip presets
// (<dir>/../dram) and then in dram_search_dirs.
SimConfig load_sim_config(const std::filesystem::path& path,
                          const std::vector<std::filesystem::path>& dram_search_dirs = {});
// The fully resolved config: the functional keys plus a `simulator` section
// with the DRAM inline and absolute table paths (sim_config_from_yaml reads it
// back to the same values).
YAML::Node sim_config_to_yaml(const SimConfig& config);

// The operating point at a clock: the lowest listed point whose frequency is
// at least the clock, with the clock's own frequency. Above the highest point
// its voltage is used and `extrapolated` (optional) is set. Throws Error if no
// operating point is configured.
OperatingPoint operating_point_at(const SimConfig& config, double clock_MHz, bool* extrapolated = nullptr);

}  // namespace edrnr::sim
