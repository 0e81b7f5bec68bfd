#include "sim/reproduce_explain.h"

#include <fmt/format.h>

#include <cmath>
#include <map>

namespace edrnr::sim {

namespace {

bool starts_with(const std::string& s, const std::string& p) { return s.compare(0, p.size(), p) == 0; }
bool ends_with(const std::string& s, const std::string& e) {
  return s.size() >= e.size() && s.compare(s.size() - e.size(), e.size(), e) == 0;
}

// Names between a prefix and a suffix among the run's statistics
// ("sim.unit.", ".stall_memory_cycles" -> "ctu", "tme", ...).
std::vector<std::string> stat_names_between(const nlohmann::json& run, const std::string& prefix,
                                            const std::string& suffix) {
  std::vector<std::string> out;
  for (auto it = run.at("stats").begin(); it != run.at("stats").end(); ++it) {
    const std::string& k = it.key();
    if (starts_with(k, prefix) && ends_with(k, suffix) && k.size() > prefix.size() + suffix.size())
      out.push_back(k.substr(prefix.size(), k.size() - prefix.size() - suffix.size()));
  }
  return out;
}

double energy_field(const nlohmann::json& run, const char* field) {
  auto it = run.find("energy_table1");
  if (it == run.end() || !it->contains(field)) return std::nan("");
  return (*it)[field].get<double>();
}

}  // namespace

std::string format_number(double v) {
  if (!std::isfinite(v)) return "n/a";
  const double a = std::abs(v);
  if (a >= 1000 || (a < 1e15 && v == std::floor(v))) return fmt::format("{:.0f}", v);
  if (a >= 100) return fmt::format("{:.1f}", v);
  if (a >= 10) return fmt::format("{:.2f}", v);
  if (a >= 0.01 || a == 0) return fmt::format("{:.3f}", v);
  return fmt::format("{:.3g}", v);
}

RunProfile profile_runs(const RunTable& table, const std::string& variant) {
  RunProfile p;
  auto avg = [&](auto f) {
    return average_over_views(table,
                              [&](const std::string& s, int v) {
                                return table.has(s, v, variant) ? f(table.run(s, v, variant)) : std::nan("");
                              })
        .mean;
  };
  p.cycles = avg([](const nlohmann::json& r) { return run_stat(r, "sim.cycles"); });
  p.samples_per_pixel =
      avg([](const nlohmann::json& r) { return run_stat(r, "sim.samples") / run_stat(r, "sim.pixels"); });
  p.samples_per_cycle = avg([](const nlohmann::json& r) { return run_stat(r, "sim.samples_per_cycle"); });
  p.peak_samples_per_cycle =
      avg([](const nlohmann::json& r) { return run_stat_or_nan(r, "sim.peak_samples_per_cycle"); });
  p.dram_bytes_per_pixel = avg([](const nlohmann::json& r) {
    return (run_stat(r, "dram.read_bytes") + run_stat(r, "dram.write_bytes")) / run_stat(r, "sim.pixels");
  });
  p.mlp_switches = avg([](const nlohmann::json& r) { return run_stat_or_nan(r, "sim.mlp_switches"); });
  p.mlp_bytes = avg([](const nlohmann::json& r) { return run_stat_or_nan(r, "chip.tme.mlp_bytes"); });

  // Units and data types, named as the first run names them.
  const std::string& s0 = table.scenes().front();
  const int v0 = table.views(s0).front();
  if (!table.has(s0, v0, variant)) return p;
  const nlohmann::json& first = table.run(s0, v0, variant);
  for (const std::string& unit : stat_names_between(first, "sim.unit.", ".stall_memory_cycles")) {
    const double share = avg([&](const nlohmann::json& r) {
      return run_stat_or_nan(r, "sim.unit." + unit + ".stall_memory_cycles") / run_stat(r, "sim.cycles");
    });
    if (share > p.top_memory_unit_share) p.top_memory_unit = unit, p.top_memory_unit_share = share;
  }
  for (const std::string& type : stat_names_between(first, "mem.", ".read_bytes")) {
    const double share = avg([&](const nlohmann::json& r) {
      const double total = run_stat(r, "dram.read_bytes");
      return total > 0 ? run_stat_or_nan(r, "mem." + type + ".read_bytes") / total : std::nan("");
    });
    if (share > p.top_data_type_share) p.top_data_type = type, p.top_data_type_share = share;
  }
  return p;
}

std::string describe_cycles(const RunProfile& p) {
  std::string s = fmt::format(
      "a frame takes {} M cycles (sim.cycles) for {} samples per pixel ({} samples per cycle, peak {}: "
      "sim.samples_per_cycle)",
      format_number(p.cycles / 1e6), format_number(p.samples_per_pixel), format_number(p.samples_per_cycle),
      format_number(p.peak_samples_per_cycle));
  if (!p.top_memory_unit.empty())
    s += fmt::format("; the {} waits for memory {:.1f} % of the cycles (sim.unit.{}.stall_memory_cycles)",
                     p.top_memory_unit, 100 * p.top_memory_unit_share, p.top_memory_unit);
  s += fmt::format("; the DRAM moves {} B per pixel (dram.read_bytes + dram.write_bytes)",
                   format_number(p.dram_bytes_per_pixel));
  if (!p.top_data_type.empty())
    s += fmt::format(", {:.0f} % of the bytes read being {} (mem.{}.read_bytes)", 100 * p.top_data_type_share,
                     p.top_data_type, p.top_data_type);
  if (std::isfinite(p.mlp_switches) && p.mlp_switches > 0)
    s += fmt::format("; the TME switches MLP {} times per frame (sim.mlp_switches), {} bytes each (chip.tme.mlp_bytes)",
                     format_number(p.mlp_switches), format_number(p.mlp_bytes));
  return s;
}

std::string describe_energy(const RunTable& table, const std::string& variant) {
  auto avg = [&](const char* field) {
    return average_over_views(table,
                              [&](const std::string& s, int v) {
                                if (!table.has(s, v, variant)) return std::nan("");
                                const nlohmann::json& r = table.run(s, v, variant);
                                return energy_field(r, field) / energy_field(r, "pixels") / 1e3;  // pJ -> nJ per pixel
                              })
        .mean;
  };
  const double total = avg("total_pJ"), core = avg("core_dynamic_pJ"), off = avg("offchip_pJ"), leak = avg("static_pJ");
  if (!std::isfinite(total) || total <= 0) return "the runs have no energy (the preset has no energy table)";
  return fmt::format(
      "of our {} nJ per pixel, {} ({:.0f} %) are off-chip (DRAM and its I/O, energy_table1.offchip_pJ, which does "
      "not scale with the core supply), {} core dynamic and {} static",
      format_number(total), format_number(off), 100 * off / total, format_number(core), format_number(leak));
}

}  // namespace edrnr::sim
