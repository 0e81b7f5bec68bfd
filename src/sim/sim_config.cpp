#include "sim/sim_config.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"
#include "core/yaml_read.h"

namespace edrnr::sim {

namespace {

namespace fs = std::filesystem;

constexpr const char* kDefaultDramPreset = "ddr3-1600-4gb-x16-16bit";

int integer(const YAML::Node& v, const std::string& where) { return yaml_scalar<int>(v, where, "an integer"); }
uint64_t count(const YAML::Node& v, const std::string& where) {
  const int64_t x = yaml_scalar<int64_t>(v, where, "an integer");
  if (x < 0) fail("{}: {} must not be negative", where, x);
  return uint64_t(x);
}
double number(const YAML::Node& v, const std::string& where) { return yaml_scalar<double>(v, where, "a number"); }
bool boolean(const YAML::Node& v, const std::string& where) { return yaml_scalar<bool>(v, where, "true or false"); }

void read_timing(const YAML::Node& node, const std::string& where, SimTiming& t) {
  yaml_for_each_key(
      node, where, {"front_end", "ctu", "ftu", "cfiu", "tme", "vru"},
      [&](const std::string& key, const YAML::Node& v, const std::string& at) {
        if (key == "ctu")
          yaml_for_each_key(v, at, {"cycles_per_iteration"},
                            [&](const std::string&, const YAML::Node& x, const std::string& a) {
                              t.ctu_cycles_per_iteration = integer(x, a);
                            });
        if (key == "ftu")
          yaml_for_each_key(v, at, {"cycles_per_iteration", "lanes"},
                            [&](const std::string& k, const YAML::Node& x, const std::string& a) {
                              if (k == "cycles_per_iteration") t.ftu_cycles_per_iteration = integer(x, a);
                              if (k == "lanes") t.ftu_lanes = integer(x, a);
                            });
        if (key == "front_end")
          yaml_for_each_key(v, at, {"zorg_cycles_per_rp", "tsps_position_evals_per_cycle", "latency_cycles"},
                            [&](const std::string& k, const YAML::Node& x, const std::string& a) {
                              if (k == "zorg_cycles_per_rp") t.zorg_cycles_per_rp = integer(x, a);
                              if (k == "tsps_position_evals_per_cycle") t.tsps_position_evals_per_cycle = integer(x, a);
                              if (k == "latency_cycles") t.front_end_latency_cycles = integer(x, a);
                            });
        if (key == "cfiu")
          yaml_for_each_key(v, at, {"cycles_per_sample", "latency_cycles", "fifo_slots"},
                            [&](const std::string& k, const YAML::Node& x, const std::string& a) {
                              if (k == "cycles_per_sample") t.cfiu_cycles_per_sample = integer(x, a);
                              if (k == "latency_cycles") t.cfiu_latency_cycles = integer(x, a);
                              if (k == "fifo_slots") t.cfiu_fifo_slots = integer(x, a);
                            });
        if (key == "tme")
          yaml_for_each_key(
              v, at,
              {"macs_per_cycle", "latency_cycles", "fifo_slots", "weight_load_bytes_per_cycle", "weight_buffers"},
              [&](const std::string& k, const YAML::Node& x, const std::string& a) {
                if (k == "macs_per_cycle") t.tme_macs_per_cycle = integer(x, a);
                if (k == "latency_cycles") t.tme_latency_cycles = integer(x, a);
                if (k == "fifo_slots") t.tme_fifo_slots = integer(x, a);
                if (k == "weight_buffers") t.tme_weight_buffers = integer(x, a);
                if (k == "weight_load_bytes_per_cycle") t.tme_weight_load_bytes_per_cycle = integer(x, a);
              });
        if (key == "vru")
          yaml_for_each_key(v, at, {"cycles_per_sample", "latency_cycles"},
                            [&](const std::string& k, const YAML::Node& x, const std::string& a) {
                              if (k == "cycles_per_sample") t.vru_cycles_per_sample = integer(x, a);
                              if (k == "latency_cycles") t.vru_latency_cycles = integer(x, a);
                            });
      });
}

void read_cache(const YAML::Node& node, const std::string& where, SimCacheConfig& c) {
  yaml_for_each_key(node, where,
                    {"line_bytes", "ways", "replacement", "random_seed", "mshr_entries", "hit_latency_cycles"},
                    [&](const std::string& k, const YAML::Node& v, const std::string& at) {
                      if (k == "line_bytes") c.line_bytes = count(v, at);
                      if (k == "ways") c.ways = count(v, at);
                      if (k == "replacement")
                        c.replacement = parse_replacement(yaml_scalar<std::string>(v, at, "a name"), at);
                      if (k == "random_seed") c.random_seed = count(v, at);
                      if (k == "mshr_entries") c.mshr_entries = size_t(count(v, at));
                      if (k == "hit_latency_cycles") c.hit_latency_cycles = count(v, at);
                    });
}

fs::path resolve(const fs::path& p, const fs::path& base_dir) {
  if (p.is_absolute() || base_dir.empty()) return p;
  return (base_dir / p).lexically_normal();
}

void read_dram(const YAML::Node& v, const std::string& at, const fs::path& base_dir,
               const std::vector<fs::path>& search_dirs, SimMemory& m) {
  if (v.IsMap()) {
    YAML::Emitter e;
    e << v;
    m.dram = parse_dram_config(e.c_str(), at);
    m.dram_source = "inline";
    return;
  }
  const std::string name = yaml_scalar<std::string>(v, at, "a DRAM preset name, a path or a map");
  std::vector<fs::path> dirs;
  if (!base_dir.empty()) dirs.push_back(base_dir / ".." / "dram");
  dirs.insert(dirs.end(), search_dirs.begin(), search_dirs.end());
  const fs::path candidate = resolve(name, base_dir);
  try {
    const fs::path path =
        fs::exists(candidate) && fs::is_regular_file(candidate) ? candidate : find_dram_preset(name, dirs);
    m.dram = load_dram_config(path);
  } catch (const Error& e) {
    fail("{}: {}", at, e.what());
  }
  m.dram_source = name;
}

void read_memory(const YAML::Node& node, const std::string& where, const fs::path& base_dir,
                 const std::vector<fs::path>& search_dirs, SimMemory& m) {
  yaml_for_each_key(node, where,
                    {"dram", "max_request_bytes", "preload_bitmaps", "write_output", "output_record_bytes",
                     "micro_grid_cache", "mlp_cache", "mlp_prefetch"},
                    [&](const std::string& k, const YAML::Node& v, const std::string& at) {
                      if (k == "dram") read_dram(v, at, base_dir, search_dirs, m);
                      if (k == "max_request_bytes") m.max_request_bytes = uint32_t(count(v, at));
                      if (k == "preload_bitmaps") m.preload_bitmaps = boolean(v, at);
                      if (k == "write_output") m.write_output = boolean(v, at);
                      if (k == "mlp_prefetch") m.mlp_prefetch = boolean(v, at);
                      if (k == "output_record_bytes") m.output_record_bytes = uint32_t(count(v, at));
                      if (k == "micro_grid_cache") read_cache(v, at, m.micro_grid_cache);
                      if (k == "mlp_cache") read_cache(v, at, m.mlp_cache);
                    });
}

void read_energy(const YAML::Node& node, const std::string& where, const fs::path& base_dir, SimEnergy& e) {
  yaml_for_each_key(node, where, {"events", "leakage", "leakage_voltage_exponent", "dram"},
                    [&](const std::string& k, const YAML::Node& v, const std::string& at) {
                      if (k == "events") e.events_csv = resolve(yaml_scalar<std::string>(v, at, "a path"), base_dir);
                      if (k == "leakage") e.leakage_csv = resolve(yaml_scalar<std::string>(v, at, "a path"), base_dir);
                      if (k == "leakage_voltage_exponent") e.leakage_voltage_exponent = number(v, at);
                      if (k == "dram") {
                        const std::string s = yaml_scalar<std::string>(v, at, "events, model or access");
                        if (s == "events")
                          e.dram = DramEnergySource::Events;
                        else if (s == "model")
                          e.dram = DramEnergySource::Model;
                        else if (s == "access")
                          e.dram = DramEnergySource::Access;
                        else
                          fail("{}: '{}' is not events, model or access", at, s);
                      }
                    });
}

void read_sram_budget(const YAML::Node& node, const std::string& where, SramBudgetLimits& b) {
  yaml_for_each_key(node, where, {"micro_grid", "feature", "mlp", "others"},
                    [&](const std::string& k, const YAML::Node& v, const std::string& at) {
                      const uint64_t n = uint64_t(count(v, at));
                      if (k == "micro_grid") b.micro_grid_bytes = n;
                      if (k == "feature") b.feature_bytes = n;
                      if (k == "mlp") b.mlp_bytes = n;
                      if (k == "others") b.others_bytes = n;
                    });
}

void read_operating_points(const YAML::Node& node, const std::string& where, std::vector<OperatingPoint>& points) {
  if (!node.IsSequence()) fail("{}: expected a list of {{clock_MHz, voltage_V}}", where);
  points.clear();
  for (size_t i = 0; i < node.size(); ++i) {
    const std::string at = fmt::format("{}[{}]", where, i);
    OperatingPoint p;
    bool has_clock = false, has_voltage = false;
    yaml_for_each_key(node[i], at, {"clock_MHz", "voltage_V"},
                      [&](const std::string& k, const YAML::Node& v, const std::string& a) {
                        if (k == "clock_MHz") p.frequency_MHz = number(v, a), has_clock = true;
                        if (k == "voltage_V") p.voltage_V = number(v, a), has_voltage = true;
                      });
    if (!has_clock || !has_voltage) fail("{}: needs clock_MHz and voltage_V", at);
    points.push_back(p);
  }
}

std::vector<OperatingPoint> table1_points() {
  std::vector<OperatingPoint> out;
  for (const PaperOperatingPoint& p : table1_operating_points()) out.push_back(p.point);
  return out;
}

}  // namespace

void check_chip_limits(const ChipConfig& c) {
  using namespace limits;
  auto in = [](int64_t v, int64_t lo, int64_t hi, const char* field, const char* unit) {
    if (v < lo || v > hi) fail("chip config {} {}: must be between {} and {} {} (limit)", field, v, lo, hi, unit);
  };
  in(c.rp_buffer_capacity, 1, kMaxRpBufferCapacity, "rp_buffer_capacity", "RPs");
  in(c.rp_rob.entries, 1, kMaxQueueEntries, "rp_rob.entries", "entries");
  in(c.rp_rob.entry_depth, 1, kMaxQueueEntries, "rp_rob.entry_depth", "RPs");
  in(c.rp_rob.recent_tags, 0, kMaxQueueEntries, "rp_rob.recent_tags", "tags");
  in(c.ooo_queue_depth, 1, kMaxQueueEntries, "ooo_queue_depth", "entries");
  in(c.feature_cache_bytes, 1, kMaxCacheBytes, "feature_cache.bytes", "bytes");
  in(c.mshr_entries, 1, kMaxQueueEntries, "feature_cache.mshr_entries", "entries");
  in(c.mlp_cache_bytes, 1, kMaxCacheBytes, "mlp_cache_bytes", "bytes");
  in(c.micro_grid_cache_bytes, 0, kMaxCacheBytes, "micro_grid_cache_bytes", "bytes");
  in(c.functional_fill_latency_issues, 0, kMaxLatencyCycles, "functional_fill_latency_issues", "issues");
  if (!(c.step_micro > 0.f) || !std::isfinite(c.step_micro) || c.step_micro > float(kMaxStepMicro))
    fail("chip config render.step_micro {}: must be positive and at most {} micro voxels (limit)", c.step_micro,
         kMaxStepMicro);
}

CacheConfig make_cache_config(const SimCacheConfig& s, const char* name, int64_t size_bytes, uint64_t window_cycles) {
  CacheConfig c;
  c.name = name;
  c.size_bytes = uint64_t(size_bytes);
  c.line_bytes = s.line_bytes;
  c.ways = s.ways;
  c.replacement = s.replacement;
  c.random_seed = s.random_seed;
  c.mshr_entries = s.mshr_entries;
  c.hit_latency_cycles = s.hit_latency_cycles;
  c.hit_rate_window_cycles = window_cycles;
  return c;
}

void validate(const SimConfig& c) {
  edrnr::validate(c.chip);
  check_chip_limits(c.chip);
  if (!(c.clock_MHz >= limits::kMinClockMHz && c.clock_MHz <= limits::kMaxClockMHz))
    fail("simulator.clock_MHz {}: must be between {} and {} MHz (limit)", c.clock_MHz, limits::kMinClockMHz,
         limits::kMaxClockMHz);
  const SimTiming& t = c.timing;
  auto at_least = [](int v, int lo, const char* field) {
    if (v < lo) fail("simulator.timing.{} {} must be at least {}", field, v, lo);
    if (v > limits::kMaxLatencyCycles)
      fail("simulator.timing.{} {}: over the limit of {}", field, v, limits::kMaxLatencyCycles);
  };
  at_least(t.zorg_cycles_per_rp, 1, "front_end.zorg_cycles_per_rp");
  at_least(t.tsps_position_evals_per_cycle, 1, "front_end.tsps_position_evals_per_cycle");
  at_least(t.front_end_latency_cycles, 1, "front_end.latency_cycles");
  at_least(t.ctu_cycles_per_iteration, 1, "ctu.cycles_per_iteration");
  at_least(t.ftu_cycles_per_iteration, 1, "ftu.cycles_per_iteration");
  at_least(t.ftu_lanes, 1, "ftu.lanes");
  at_least(t.cfiu_cycles_per_sample, 1, "cfiu.cycles_per_sample");
  at_least(t.cfiu_latency_cycles, 1, "cfiu.latency_cycles");
  at_least(t.cfiu_fifo_slots, 1, "cfiu.fifo_slots");
  at_least(t.tme_macs_per_cycle, 1, "tme.macs_per_cycle");
  at_least(t.tme_latency_cycles, 1, "tme.latency_cycles");
  at_least(t.tme_fifo_slots, 1, "tme.fifo_slots");
  at_least(t.tme_weight_load_bytes_per_cycle, 1, "tme.weight_load_bytes_per_cycle");
  if (t.tme_weight_buffers < 1 || t.tme_weight_buffers > 2)
    fail("simulator.timing.tme.weight_buffers {} must be 1 or 2", t.tme_weight_buffers);
  at_least(t.vru_cycles_per_sample, 1, "vru.cycles_per_sample");
  at_least(t.vru_latency_cycles, 1, "vru.latency_cycles");
  const SimMemory& m = c.memory;
  if (m.dram.rows == 0) fail("simulator.memory.dram: no DRAM configured (give a preset name, a path or a map)");
  m.dram.validate();
  if (m.max_request_bytes < 1) fail("simulator.memory.max_request_bytes must be at least 1");
  if (m.output_record_bytes < 1) fail("simulator.memory.output_record_bytes must be at least 1");
  if (m.max_request_bytes > (1u << 20) || m.output_record_bytes > (1u << 20))
    fail("simulator.memory.max_request_bytes {} and output_record_bytes {}: each must be at most {} bytes (limit)",
         m.max_request_bytes, m.output_record_bytes, 1u << 20);
  auto check_cache = [](const SimCacheConfig& s, const char* name, int64_t size_bytes) {
    if (s.line_bytes > uint64_t(limits::kMaxCacheBytes) || s.ways > uint64_t(limits::kMaxCacheWays) ||
        s.mshr_entries > size_t(limits::kMaxQueueEntries) || s.hit_latency_cycles > uint64_t(limits::kMaxLatencyCycles))
      fail(
          "simulator.memory.{}: line_bytes {}, ways {}, mshr_entries {}, hit_latency_cycles {}: over the limits "
          "({} bytes, {} ways, {} entries, {} cycles)",
          name, s.line_bytes, s.ways, s.mshr_entries, s.hit_latency_cycles, limits::kMaxCacheBytes,
          limits::kMaxCacheWays, limits::kMaxQueueEntries, limits::kMaxLatencyCycles);
    try {
      validate(make_cache_config(s, name, size_bytes, 0));
    } catch (const Error& e) {
      fail("simulator.memory.{}: {}", name, e.what());
    }
  };
  if (c.chip.micro_grid_cache_bytes < 1)
    fail("micro_grid_cache_bytes {} must be positive for the cycle simulator", c.chip.micro_grid_cache_bytes);
  check_cache(m.micro_grid_cache, "micro_grid_cache", c.chip.micro_grid_cache_bytes);
  check_cache(m.mlp_cache, "mlp_cache", c.chip.mlp_cache_bytes);
  if (!(c.energy.leakage_voltage_exponent >= 0.0) || !std::isfinite(c.energy.leakage_voltage_exponent))
    fail("simulator.energy.leakage_voltage_exponent {} must be a finite number >= 0",
         c.energy.leakage_voltage_exponent);
  double last = 0.0;
  for (size_t i = 0; i < c.operating_points.size(); ++i) {
    const OperatingPoint& p = c.operating_points[i];
    if (!(p.frequency_MHz > last) || !std::isfinite(p.frequency_MHz))
      fail("simulator.operating_points[{}].clock_MHz {} must be positive and above the previous point's", i,
           p.frequency_MHz);
    if (!(p.frequency_MHz >= limits::kMinClockMHz && p.frequency_MHz <= limits::kMaxClockMHz))
      fail("simulator.operating_points[{}].clock_MHz {}: must be between {} and {} MHz (limit)", i, p.frequency_MHz,
           limits::kMinClockMHz, limits::kMaxClockMHz);
    if (!(p.voltage_V > 0.0) || !std::isfinite(p.voltage_V))
      fail("simulator.operating_points[{}].voltage_V {} must be positive", i, p.voltage_V);
    last = p.frequency_MHz;
  }
  if (c.hit_rate_window_cycles < 1) fail("simulator.statistics.hit_rate_window_cycles must be at least 1");
}

SimConfig sim_config_from_yaml(const YAML::Node& node, std::string_view where_view, const fs::path& base_dir,
                               const std::vector<fs::path>& dram_search_dirs) {
  const std::string where(where_view);
  SimConfig c;
  c.operating_points = table1_points();
  c.chip = chip_config_from_yaml(node, where);
  const bool has_simulator = node && node.IsMap() && node["simulator"];
  const YAML::Node s = has_simulator ? node["simulator"] : YAML::Node();
  if (has_simulator && s.IsNull())
    fail("{}.simulator: the section is empty; give a map of simulator settings or leave it out", where);
  if (has_simulator) {
    yaml_for_each_key(
        s, where + ".simulator",
        {"clock_MHz", "timing", "memory", "energy", "operating_points", "statistics", "sram_budget_bytes"},
        [&](const std::string& k, const YAML::Node& v, const std::string& at) {
          if (k == "clock_MHz") c.clock_MHz = number(v, at);
          if (k == "timing") read_timing(v, at, c.timing);
          if (k == "memory") read_memory(v, at, base_dir, dram_search_dirs, c.memory);
          if (k == "energy") read_energy(v, at, base_dir, c.energy);
          if (k == "operating_points") read_operating_points(v, at, c.operating_points);
          if (k == "sram_budget_bytes") read_sram_budget(v, at, c.sram_budget);
          if (k == "statistics")
            yaml_for_each_key(v, at, {"hit_rate_window_cycles"},
                              [&](const std::string&, const YAML::Node& x, const std::string& a) {
                                c.hit_rate_window_cycles = count(x, a);
                              });
        });
  }
  // Defaults for what the preset leaves out: the DRAM part and the energy
  // tables of configs/edr_nr_40nm.yaml, looked up beside the preset.
  if (c.memory.dram.rows == 0)
    read_dram(YAML::Node(std::string(kDefaultDramPreset)), where + ".simulator.memory.dram (default)", base_dir,
              dram_search_dirs, c.memory);
  if (!base_dir.empty()) {
    const bool has_energy = has_simulator && s["energy"];
    const fs::path events = base_dir / ".." / "energy" / "events.csv",
                   leakage = base_dir / ".." / "energy" / "leakage.csv";
    if (!has_energy && fs::is_regular_file(events)) c.energy.events_csv = events.lexically_normal();
    if (!has_energy && fs::is_regular_file(leakage)) c.energy.leakage_csv = leakage.lexically_normal();
  }
  try {
    validate(c);
  } catch (const Error& e) {
    fail("{}: {}", where, e.what());
  }
  return c;
}

SimConfig load_sim_config(const fs::path& path, const std::vector<fs::path>& dram_search_dirs) {
  const std::string text = read_file_text(path);
  YAML::Node node;
  try {
    node = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    fail("{}: not valid YAML: {}", path.string(), e.what());
  }
  if (!node.IsMap())
    fail("{}: {}; a chip preset is a YAML map of settings (see configs/chip/edr_nr_40nm.yaml)", path.string(),
         node.IsNull()       ? "the file is empty"
         : node.IsSequence() ? "the file holds a list"
                             : "the file holds a single value");
  return sim_config_from_yaml(node, path.string(), path.parent_path(), dram_search_dirs);
}

YAML::Node sim_config_to_yaml(const SimConfig& c) {
  YAML::Node root = chip_config_to_yaml(c.chip);
  YAML::Node s;
  s["clock_MHz"] = c.clock_MHz;
  const SimTiming& t = c.timing;
  YAML::Node timing;
  timing["front_end"]["zorg_cycles_per_rp"] = t.zorg_cycles_per_rp;
  timing["front_end"]["tsps_position_evals_per_cycle"] = t.tsps_position_evals_per_cycle;
  timing["front_end"]["latency_cycles"] = t.front_end_latency_cycles;
  timing["ctu"]["cycles_per_iteration"] = t.ctu_cycles_per_iteration;
  timing["ftu"]["cycles_per_iteration"] = t.ftu_cycles_per_iteration;
  timing["ftu"]["lanes"] = t.ftu_lanes;
  timing["cfiu"]["cycles_per_sample"] = t.cfiu_cycles_per_sample;
  timing["cfiu"]["latency_cycles"] = t.cfiu_latency_cycles;
  timing["cfiu"]["fifo_slots"] = t.cfiu_fifo_slots;
  timing["tme"]["macs_per_cycle"] = t.tme_macs_per_cycle;
  timing["tme"]["latency_cycles"] = t.tme_latency_cycles;
  timing["tme"]["fifo_slots"] = t.tme_fifo_slots;
  timing["tme"]["weight_load_bytes_per_cycle"] = t.tme_weight_load_bytes_per_cycle;
  timing["tme"]["weight_buffers"] = t.tme_weight_buffers;
  timing["vru"]["cycles_per_sample"] = t.vru_cycles_per_sample;
  timing["vru"]["latency_cycles"] = t.vru_latency_cycles;
  s["timing"] = timing;

  const SimMemory& m = c.memory;
  YAML::Node memory;
  memory["dram"] = YAML::Load(dram_config_to_yaml(m.dram));
  memory["max_request_bytes"] = m.max_request_bytes;
  memory["preload_bitmaps"] = m.preload_bitmaps;
  memory["write_output"] = m.write_output;
  memory["mlp_prefetch"] = m.mlp_prefetch;
  memory["output_record_bytes"] = m.output_record_bytes;
  auto cache = [](const SimCacheConfig& x) {
    YAML::Node n;
    n["line_bytes"] = x.line_bytes;
    n["ways"] = x.ways;
    n["replacement"] = std::string(replacement_name(x.replacement));
    n["random_seed"] = x.random_seed;
    n["mshr_entries"] = x.mshr_entries;
    n["hit_latency_cycles"] = x.hit_latency_cycles;
    return n;
  };
  memory["micro_grid_cache"] = cache(m.micro_grid_cache);
  memory["mlp_cache"] = cache(m.mlp_cache);
  s["memory"] = memory;

  YAML::Node energy;
  if (!c.energy.events_csv.empty()) energy["events"] = fs::absolute(c.energy.events_csv).lexically_normal().string();
  if (!c.energy.leakage_csv.empty()) energy["leakage"] = fs::absolute(c.energy.leakage_csv).lexically_normal().string();
  energy["leakage_voltage_exponent"] = c.energy.leakage_voltage_exponent;
  energy["dram"] = dram_energy_source_name(c.energy.dram);
  s["energy"] = energy;

  YAML::Node points(YAML::NodeType::Sequence);
  for (const OperatingPoint& p : c.operating_points) {
    YAML::Node n;
    n["clock_MHz"] = p.frequency_MHz;
    n["voltage_V"] = p.voltage_V;
    points.push_back(n);
  }
  s["operating_points"] = points;
  s["statistics"]["hit_rate_window_cycles"] = c.hit_rate_window_cycles;
  s["sram_budget_bytes"]["micro_grid"] = c.sram_budget.micro_grid_bytes;
  s["sram_budget_bytes"]["feature"] = c.sram_budget.feature_bytes;
  s["sram_budget_bytes"]["mlp"] = c.sram_budget.mlp_bytes;
  s["sram_budget_bytes"]["others"] = c.sram_budget.others_bytes;
  root["simulator"] = s;
  return root;
}

const char* dram_energy_source_name(DramEnergySource s) {
  switch (s) {
    case DramEnergySource::Events:
      return "events";
    case DramEnergySource::Model:
      return "model";
    case DramEnergySource::Access:
      return "access";
  }
  return "?";
}

OperatingPoint operating_point_at(const SimConfig& c, double clock_MHz, bool* extrapolated) {
  if (c.operating_points.empty())
    fail("simulator.operating_points: none configured, so no voltage for {} MHz", clock_MHz);
  if (extrapolated) *extrapolated = false;
  for (const OperatingPoint& p : c.operating_points)
    if (p.frequency_MHz >= clock_MHz) return {clock_MHz, p.voltage_V};
  if (extrapolated) *extrapolated = true;
  return {clock_MHz, c.operating_points.back().voltage_V};
}

}  // namespace edrnr::sim
