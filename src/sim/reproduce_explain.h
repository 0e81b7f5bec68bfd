#pragma once
// Sentences for the report that say, from a run's own counters, where its
// cycles, bytes and energy went. Each names the statistics it read, so a
// reader can check it against the run's JSON. Used where a figure differs
// from the paper's by more than 10 %.
#include <string>

#include "sim/reproduce_table.h"

namespace edrnr::sim {

// The figures that describe a variant's runs, averaged as every figure is
// (over views, then scenes).
struct RunProfile {
  double cycles = 0;
  double samples_per_pixel = 0;
  double samples_per_cycle = 0;
  double peak_samples_per_cycle = 0;
  double dram_bytes_per_pixel = 0;  // read + written
  std::string top_memory_unit;      // the unit waiting for memory the largest share of the cycles
  double top_memory_unit_share = 0;
  std::string top_data_type;  // the data type with the most DRAM bytes read
  double top_data_type_share = 0;
  double mlp_switches = 0;
  double mlp_bytes = 0;  // one MLP as the MLP cache holds it
};
RunProfile profile_runs(const RunTable& table, const std::string& variant);

// "a frame takes 7.65 M cycles for 2.76 samples per pixel (0.231 samples per
// cycle, peak 1); the tme waits for memory 32.7 % of the cycles
// (sim.unit.tme.stall_memory_cycles) and the DRAM moves 51.8 B per pixel
// (dram.read_bytes + dram.write_bytes), 66 % of the reads mlp_weights
// (mem.mlp_weights.read_bytes)".
std::string describe_cycles(const RunProfile& p);

// The energy per pixel of a variant at its Table I point, split into core
// dynamic, off-chip (DRAM) and static (energy_table1 of the runs).
std::string describe_energy(const RunTable& table, const std::string& variant);

// Formats a number for people: 3 significant digits, or fewer decimals when large.
std::string format_number(double v);

}  // namespace edrnr::sim
