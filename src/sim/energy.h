#pragma once
// Energy model, kept apart from timing (docs/energy.md): the simulator counts
// events; a per-event energy table turns the counts into energy at an
// operating point (core clock, core supply), plus leakage over the run time.
//
//   core dynamic = sum over core events of count x E x (V / V_ref)^2
//   off-chip     = sum over off-chip events of count x E   (not scaled: DRAM
//                  and its I/O run from their own supply)
//                + the DRAM model's own energy, when it computes one
//   static       = sum over blocks of P_leak x (V / V_ref)^n x time,
//                  n = leakage_voltage_exponent (1 by default: constant
//                  leakage current, power linear in V)
//   time         = cycles / frequency
#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "core/stats.h"

namespace edrnr::sim {

// One row of the energy table. reference_voltage_V is 0 for an off-chip event
// (written "-" in the CSV), whose energy does not scale with the core supply.
struct EnergyEvent {
  std::string event;
  double energy_pJ = 0;
  double reference_voltage_V = 0;
  std::string source;

  bool scales_with_core_voltage() const { return reference_voltage_V > 0; }
};

// Per-event energies, loaded from a CSV file with the header
//   event,energy_pJ,reference_voltage_V,source
// (columns in that order). Fields may be double-quoted (a quote inside a quoted
// field is written ""); blank lines and lines starting with '#' are skipped.
// Every row needs a unique event name, a finite energy >= 0, a voltage > 0 or
// "-", and a non-empty source. Errors name the file and line.
class EnergyTable {
 public:
  EnergyTable() = default;
  static EnergyTable load(const std::filesystem::path& csv_path);
  // `origin` names the text in error messages (a path or "<memory>").
  static EnergyTable parse(std::string_view csv_text, std::string_view origin);

  bool contains(std::string_view event) const;
  // Throws Error naming the table and the event if it is not in the table.
  const EnergyEvent& at(std::string_view event) const;
  const std::vector<EnergyEvent>& rows() const { return rows_; }
  const std::string& origin() const { return origin_; }

 private:
  std::string origin_;
  std::vector<EnergyEvent> rows_;  // file order
};

// Leakage power of one block at a reference core voltage.
struct LeakageBlock {
  std::string block;
  double leakage_mW = 0;
  double reference_voltage_V = 0;
  std::string source;
};

// Leakage per block, loaded from a CSV file with the header
//   block,leakage_mW,reference_voltage_V,source
// under the same rules as EnergyTable (the voltage must be a number > 0).
class LeakageTable {
 public:
  LeakageTable() = default;
  static LeakageTable load(const std::filesystem::path& csv_path);
  static LeakageTable parse(std::string_view csv_text, std::string_view origin);

  const std::vector<LeakageBlock>& rows() const { return rows_; }
  const std::string& origin() const { return origin_; }

 private:
  std::string origin_;
  std::vector<LeakageBlock> rows_;
};

struct OperatingPoint {
  double frequency_MHz = 0;
  double voltage_V = 0;
};

// One row of Table I of the paper: an operating point and what the chip did there.
struct PaperOperatingPoint {
  OperatingPoint point;
  double power_mW = 0;
  double fps = 0;  // 800 x 800 frames per second
  double nJ_per_pixel = 0;
};

// The five operating points of Table I, 50 MHz / 0.79 V ... 380 MHz / 1.21 V.
const std::array<PaperOperatingPoint, 5>& table1_operating_points();

// What one simulated run produced.
struct EnergyRun {
  std::map<std::string, uint64_t> event_counts;  // event name -> count
  uint64_t cycles = 0;                           // core cycles
  uint64_t pixels = 0;                           // pixels rendered
  double dram_model_energy_pJ = 0;  // energy the DRAM model computed itself (0 if DRAM is counted as events)
};

struct EnergyReport {
  struct EventEnergy {
    std::string event;
    uint64_t count = 0;
    double energy_pJ = 0;
  };
  struct BlockEnergy {
    std::string block;
    double power_mW = 0;
    double energy_pJ = 0;
  };

  OperatingPoint point;
  uint64_t cycles = 0;
  uint64_t pixels = 0;
  double time_s = 0;
  double core_dynamic_pJ = 0;
  double offchip_pJ = 0;  // off-chip events plus the DRAM model's energy
  double static_pJ = 0;
  double total_pJ = 0;
  double nJ_per_pixel = 0;            // 0 when pixels is 0
  double average_power_W = 0;         // 0 when cycles is 0
  std::vector<EventEnergy> by_event;  // event name order; events with a zero count are left out
  std::vector<BlockEnergy> by_block;  // leakage table order
};

class EnergyModel {
 public:
  // Throws Error if leakage_voltage_exponent is negative or not finite.
  EnergyModel(EnergyTable events, LeakageTable leakage, double leakage_voltage_exponent = 1.0);

  // Throws Error for an event not in the table, or a frequency or voltage that is not > 0.
  EnergyReport evaluate(const EnergyRun& run, const OperatingPoint& point) const;

  const EnergyTable& events() const { return events_; }
  const LeakageTable& leakage() const { return leakage_; }
  double leakage_voltage_exponent() const { return leakage_exponent_; }

 private:
  EnergyTable events_;
  LeakageTable leakage_;
  double leakage_exponent_ = 1.0;
};

// The report as JSON (fields named as in EnergyReport, with units in the names).
nlohmann::json energy_report_json(const EnergyReport& report);
// Registers the report's totals as "<prefix>.*" values in `registry`
// (core_dynamic_pJ, offchip_pJ, static_pJ, total_pJ, nJ_per_pixel, power_W)
// and one "<prefix>.event.<name>_pJ" value per event.
void export_stats(const EnergyReport& report, StatsRegistry& registry, const std::string& prefix);
// The report as a plain-text table for people.
std::string format_energy_report(const EnergyReport& report);

}  // namespace edrnr::sim
