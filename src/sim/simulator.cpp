#include "sim/simulator.h"

#include <fmt/format.h>

#include <cmath>
#include <sstream>

#include "core/error.h"
#include "sim/engine.h"

namespace edrnr::sim {

using engine::kUnitNames;
using engine::kUnits;
using engine::ratio;

EnergyReport evaluate_energy(const SimConfig& config, const EnergyRun& run, const OperatingPoint& point) {
  if (config.energy.events_csv.empty()) fail("simulator.energy.events: no energy table configured");
  EnergyModel model(EnergyTable::load(config.energy.events_csv),
                    config.energy.leakage_csv.empty() ? LeakageTable{} : LeakageTable::load(config.energy.leakage_csv),
                    config.energy.leakage_voltage_exponent);
  return model.evaluate(run, point);
}

SramBudget sram_budget_for(const SceneModel& model, const SimConfig& config) {
  check_chip_model(model);
  uint64_t mlp_bytes = 0;
  if (model.mlp_count()) {
    const double delta = double(config.chip.step_micro) * double(model.scene_box.size().x) / double(model.micro_res);
    chip::Tme tme(model, config.chip.numerics, delta, size_t(config.chip.mlp_cache_bytes));
    mlp_bytes = tme.mlp(0).stored_bytes;
  }
  return compute_sram_budget(config, {model.micro_res, model.feature_channels, mlp_bytes});
}

SimResult simulate_chip(const SceneModel& model, const Camera& camera, const SimConfig& config,
                        const SimOptions& options) {
  validate(config);
  check_chip_model(model);
  if (camera.width < 1 || camera.height < 1) fail("camera image size {}x{} is empty", camera.width, camera.height);
  if (options.threads < 1 || options.threads > 2) fail("simulator threads {} must be 1 or 2", options.threads);
  SimResult result;
  result.stats = std::make_unique<StatsRegistry>();
  engine::Engine engine(model, camera, config, options, result);
  engine.run();
  return result;
}

std::string format_sim_report(const SimResult& r) {
  const SimSummary& s = r.summary;
  const StatsRegistry& st = *r.stats;
  std::ostringstream o;
  o << fmt::format("frame       {}x{}: {} cycles at {:.0f} MHz = {:.3f} ms, {:.2f} FPS\n", r.image.width,
                   r.image.height, s.cycles, s.clock_MHz, s.frame_time_s * 1e3, s.fps);
  // The paper's figures are for 800x800 frames of the Synthetic NeRF scenes.
  const bool paper_frame = r.image.width == 800 && r.image.height == 800;
  for (const PaperOperatingPoint& p : table1_operating_points())
    if (paper_frame && std::abs(p.point.frequency_MHz - s.clock_MHz) < 1e-9)
      o << fmt::format("            paper (800x800, Synthetic NeRF) at {:.0f} MHz: {:.1f} FPS; ratio {:.3f}\n",
                       p.point.frequency_MHz, p.fps, s.fps / p.fps);
  o << fmt::format("samples     {} ({:.3f} per cycle, peak {:.3f}); {:.2f} per pixel\n", s.samples, s.samples_per_cycle,
                   s.peak_samples_per_cycle, ratio(double(s.samples), double(s.pixels)));
  o << fmt::format("rays/RP     coarse {:.2f} (paper 3.89), fine {:.2f} (paper 3.48); CCRPs per CV tag switch {:.1f}\n",
                   s.coarse_rays_per_iteration, s.fine_rays_per_iteration, s.rps_per_tag_switch);
  o << "units       busy  stall_out  stall_mem   idle   (% of cycles)\n";
  for (uint32_t u = 0; u < kUnits; ++u) {
    double v[kUnitStates];
    for (int k = 0; k < kUnitStates; ++k)
      v[k] = 100.0 *
             ratio(st.get(std::string("sim.unit.") + kUnitNames[u] + "." + unit_state_name(UnitState(k)) + "_cycles"),
                   double(s.cycles));
    o << fmt::format("  {:<9} {:5.1f}  {:9.1f}  {:9.1f}  {:5.1f}\n", kUnitNames[u], v[0], v[1], v[2], v[3]);
  }
  o << fmt::format(
      "caches      micro grid {:.2f} % (paper 96.27), features {:.2f} % (paper 98.65), MLP {:.2f} % "
      "(paper 96.38); bank conflict cycles {}\n",
      100 * s.micro_grid_hit_rate, 100 * s.feature_hit_rate, 100 * s.mlp_hit_rate,
      uint64_t(st.get("cache.features.bank_conflict_cycles")));
  o << fmt::format("            per access (sample): features {:.2f} %, MLP {:.2f} %\n",
                   100 * s.feature_hit_rate_per_access, 100 * s.mlp_hit_rate_per_access);
  {
    const SramBudget& b = r.sram_budget;
    o << "SRAM        ";
    for (int k = 0; k < kSramClasses; ++k)
      o << fmt::format("{}{} {:.1f} of {:.1f} KB{}", k ? ", " : "", sram_class_name(SramClass(k)),
                       double(b.class_bytes[k]) / 1024, double(b.class_budget[k]) / 1024,
                       b.class_bytes[k] > b.class_budget[k] ? " (OVER)" : "");
    o << "\n";
  }
  o << "memory      read bytes   writes bytes  (as requested, by data type)\n";
  for (int t = 0; t < kDataTypes; ++t) {
    const std::string p = std::string("mem.") + data_type_name(DataType(t));
    o << fmt::format("  {:<11} {:>11.0f}  {:>11.0f}\n", data_type_name(DataType(t)), st.get(p + ".read_bytes"),
                     st.get(p + ".write_bytes"));
  }
  o << fmt::format(
      "  DRAM        {:.1f} MB read, {:.1f} MB written ({:.1f} B/pixel); {:.2f} GB/s of {:.2f}; row hits "
      "{:.1f} %\n",
      double(s.dram_read_bytes) / 1e6, double(s.dram_write_bytes) / 1e6,
      ratio(double(s.dram_read_bytes + s.dram_write_bytes), double(s.pixels)), st.get("dram.bandwidth_GBps"),
      st.get("dram.peak_bandwidth_GBps"), 100 * st.get("dram.row_hit_rate"));
  if (r.energy) {
    const EnergyReport& e = *r.energy;
    o << fmt::format(
        "energy      {:.2f} nJ/pixel, {:.1f} mW at {:.0f} MHz / {:.2f} V{} (core {:.1f}, off-chip {:.1f}, "
        "leakage {:.1f} nJ/pixel)\n",
        e.nJ_per_pixel, e.average_power_W * 1e3, e.point.frequency_MHz, e.point.voltage_V,
        r.voltage_extrapolated ? " (voltage of the highest operating point)" : "",
        e.core_dynamic_pJ / 1e3 / double(e.pixels), e.offchip_pJ / 1e3 / double(e.pixels),
        e.static_pJ / 1e3 / double(e.pixels));
    for (const PaperOperatingPoint& p : table1_operating_points())
      if (paper_frame && std::abs(p.point.frequency_MHz - e.point.frequency_MHz) < 1e-9)
        o << fmt::format("            paper: {:.1f} nJ/pixel, {:.1f} mW; ratio {:.2f} / {:.2f}\n", p.nJ_per_pixel,
                         p.power_mW, e.nJ_per_pixel / p.nJ_per_pixel, e.average_power_W * 1e3 / p.power_mW);
  }
  return o.str();
}

}  // namespace edrnr::sim
