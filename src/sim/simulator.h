#pragma once
// The cycle simulator of the EDR-NR chip (paper Section IV, Fig. 10).
//
// It drives the functional model's unit code (src/chip: FrontEnd, Ctu, RpRob,
// Ftu, OooSi, Cfiu with its FeatureCache, Tme, Vru, RpBuffer) cycle by cycle,
// wrapped in timing shells:
//
//   front end (ZORG, ABT, TSPS) -> [queue] -> CTU -> RP-ROB -> FTU -> OoO-SI
//     -> CFIU -> [queue] -> TME -> [queue] -> VRU -> reschedule / retire
//
// Each shell takes one item at a time and holds it for a number of cycles
// that follows from the work the unit did on it (LFAU iterations, position
// evaluations, samples, bank conflicts, MACs), stalls while its output is
// full, and waits while its data are not on chip. The global RP buffer bounds
// the RPs in flight. The micro-grid cache and the MLP cache are tag caches
// (sim/cache.h) in front of the DDR3 model (sim/dram.h), which runs on its own
// clock; the feature cache is the CFIU's own (chip/feature_cache.h), with its
// fills coming from the DDR3 model.
//
// The arithmetic of a batch of samples (interpolation sums, MLP, compositing)
// is done when the FTU hands the batch to the OoO-SI, the bank reads when the
// OoO-SI issues it, and its outcome (reschedule or retire) takes effect when
// its last sample leaves the VRU. Every RP has at most one batch in flight and
// each unit's result depends only on the RP's own state, so the image is
// bit-identical to render_chip()'s for any timing (a test checks it). With
// threads = 2 the batch arithmetic runs on a second thread while the timing
// model goes on; the image and every statistic stay the same.
#include <cstdint>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "chip/chip.h"
#include "core/image.h"
#include "core/stats.h"
#include "data/camera.h"
#include "model/scene_model.h"
#include "sim/energy.h"
#include "sim/memory_system.h"
#include "sim/sim_config.h"
#include "sim/sram_budget.h"

namespace edrnr::sim {

struct SimProgress {
  uint64_t cycle = 0;
  uint64_t rps_done = 0;   // ray packets whose pixels are written
  uint64_t rps_total = 0;  // ray packets in the frame
};

struct SimOptions {
  // Chrome trace of unit activity over [trace_start_cycle, + trace_cycles); 0 cycles: none.
  uint64_t trace_start_cycle = 0;
  uint64_t trace_cycles = 0;
  size_t trace_max_events = 1000000;
  // 1: everything on the calling thread; 2: batch arithmetic on a second thread.
  int threads = 1;
  // Called about every progress_interval_cycles simulated cycles, and once at the end.
  std::function<void(const SimProgress&)> progress;
  uint64_t progress_interval_cycles = uint64_t(1) << 18;
  // An internal fault is reported after this many cycles in which no unit
  // worked and no memory transfer was in flight.
  uint64_t deadlock_cycles = 100000;
  // Cycles in which no unit can act are counted in bulk (host.skipped_cycles),
  // not stepped; off: every cycle is stepped (the same results, slower).
  bool skip_quiet_cycles = true;
  // When set, sees every DRAM request of the frame (MemorySystem::set_request_observer).
  DramRequestObserver dram_request_observer;
};

// The figures of a run that the report and the tests use; every one is also in
// the statistics registry.
struct SimSummary {
  uint64_t cycles = 0;
  double clock_MHz = 0;
  double frame_time_s = 0;
  double fps = 0;
  uint64_t pixels = 0;
  uint64_t samples = 0;  // samples interpolated
  double samples_per_cycle = 0;
  double peak_samples_per_cycle = 0;  // what the slowest of CFIU, TME and VRU allows
  double micro_grid_hit_rate = 0;     // micro-grid word reads that hit
  double feature_hit_rate = 0;        // feature block requests (one per batch) that hit
  double mlp_hit_rate = 0;            // batches at the TME whose MLP was on chip (MAC array or MLP cache)
  // Per access (per sample), as a cache serving samples one by one would
  // count them: a batch that hits is n hits; one that misses is one miss (its
  // first sample waits for the data) and n - 1 hits.
  double feature_hit_rate_per_access = 0;
  double mlp_hit_rate_per_access = 0;
  uint64_t dram_read_bytes = 0;  // bursts moved, as the DRAM counts them
  uint64_t dram_write_bytes = 0;
  double coarse_rays_per_iteration = 0;
  double fine_rays_per_iteration = 0;
  double rps_per_tag_switch = 0;
};

struct SimResult {
  Image image;
  ChipCounters chip;  // the units' own counters, as render_chip() reports them
  SimSummary summary;
  std::unique_ptr<StatsRegistry> stats;  // every statistic, in registration order
  // Hit rate per window of cycles (Fig. 8): {"micro_grid", "features",
  // "mlp_weights" (per batch, as mlp_hit_rate), "mlp_weight_lines" (per line
  // access of the MLP cache)}, each as hit_rate_series_json() writes it.
  nlohmann::json hit_rate_series;
  nlohmann::json trace;                // Chrome trace (null when not asked for)
  EnergyRun energy_run;                // event counts, to evaluate at any operating point
  std::optional<EnergyReport> energy;  // at the configured clock's operating point
  bool voltage_extrapolated = false;   // the clock is above every operating point
  SramBudget sram_budget;              // the config's buffers for this model, against Table I
};

// The SRAM budget of `config` for `model`'s shape (micro grid, channels, MLP).
SramBudget sram_budget_for(const SceneModel& model, const SimConfig& config);

// Simulates one frame. Throws Error for a bad config, camera or model (as
// render_chip does), and std::logic_error for an internal fault (a deadlock).
// The SRAM budget is computed (SimResult::sram_budget) but not enforced: the
// caller decides (edrnr simulate refuses a preset over budget).
SimResult simulate_chip(const SceneModel& model, const Camera& camera, const SimConfig& config,
                        const SimOptions& options = {});

// The energy of a run at an operating point (Error if the config has no energy
// table).
EnergyReport evaluate_energy(const SimConfig& config, const EnergyRun& run, const OperatingPoint& point);

// A report for people: frame rate, breakdown per unit, memory traffic by data
// type, hit rates, the paper's figures beside ours, energy.
std::string format_sim_report(const SimResult& result);

}  // namespace edrnr::sim
