#include "sim/energy.h"

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <unordered_map>
#include <utility>

#include "core/error.h"
#include "core/file_io.h"

namespace edrnr::sim {

namespace {

struct CsvRow {
  int line = 0;
  std::vector<std::string> fields;
};

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

// Splits one CSV line into fields. A field that starts with '"' runs to the
// matching quote; "" inside it is one quote. Unquoted fields are trimmed.
std::vector<std::string> split_csv_line(std::string_view line, std::string_view origin, int line_no) {
  std::vector<std::string> fields;
  size_t i = 0;
  while (true) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    std::string field;
    if (i < line.size() && line[i] == '"') {
      ++i;
      bool closed = false;
      while (i < line.size()) {
        if (line[i] == '"') {
          if (i + 1 < line.size() && line[i + 1] == '"') {
            field += '"';
            i += 2;
            continue;
          }
          ++i;
          closed = true;
          break;
        }
        field += line[i++];
      }
      if (!closed) fail("{} line {}: a quoted field has no closing quote", origin, line_no);
      while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
      if (i < line.size() && line[i] != ',')
        fail("{} line {}: unexpected text after a quoted field (a field with quotes must be quoted whole)", origin,
             line_no);
    } else {
      size_t end = line.find(',', i);
      if (end == std::string_view::npos) end = line.size();
      std::string_view raw = line.substr(i, end - i);
      if (raw.find('"') != std::string_view::npos)
        fail("{} line {}: a quote inside an unquoted field (quote the whole field)", origin, line_no);
      field = std::string(trim(raw));
      i = end;
    }
    fields.push_back(std::move(field));
    if (i >= line.size()) break;
    ++i;  // the comma
  }
  return fields;
}

// Rows of a CSV text whose first data line must be exactly `header`.
std::vector<CsvRow> read_csv(std::string_view text, std::string_view origin, const std::vector<std::string>& header) {
  std::vector<CsvRow> rows;
  bool have_header = false;
  int line_no = 0;
  size_t pos = 0;
  auto header_text = [&] {
    std::string h;
    for (const std::string& name : header) h += (h.empty() ? "" : ",") + name;
    return h;
  };
  while (pos <= text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(pos, end - pos);
    pos = end + 1;
    ++line_no;
    std::string_view body = trim(line);
    if (body.empty() || body.front() == '#') {
      if (end == text.size()) break;
      continue;
    }
    std::vector<std::string> fields = split_csv_line(body, origin, line_no);
    if (!have_header) {
      if (fields != header)
        fail("{} line {}: the header must be '{}', found '{}'", origin, line_no, header_text(), body);
      have_header = true;
    } else {
      if (fields.size() != header.size())
        fail("{} line {}: expected {} fields ({}), found {}", origin, line_no, header.size(), header_text(),
             fields.size());
      rows.push_back(CsvRow{line_no, std::move(fields)});
    }
    if (end == text.size()) break;
  }
  if (!have_header) fail("{}: no header line (expected '{}')", origin, header_text());
  return rows;
}

double parse_number(const std::string& field, std::string_view column, std::string_view origin, int line_no) {
  double value = 0;
  const char* first = field.data();
  const char* last = field.data() + field.size();
  auto [ptr, ec] = std::from_chars(first, last, value);
  if (field.empty() || ec != std::errc() || ptr != last || !std::isfinite(value))
    fail("{} line {}: {} '{}' is not a number", origin, line_no, column, field);
  return value;
}

void check_name_and_source(const CsvRow& row, std::string_view what, std::string_view origin,
                           std::unordered_map<std::string, int>& seen) {
  const std::string& name = row.fields[0];
  if (name.empty()) fail("{} line {}: the {} name is empty", origin, row.line, what);
  if (row.fields[3].empty()) fail("{} line {}: {} '{}' has no source", origin, row.line, what, name);
  auto [it, inserted] = seen.emplace(name, row.line);
  if (!inserted) fail("{} line {}: {} '{}' is already defined on line {}", origin, row.line, what, name, it->second);
}

}  // namespace

EnergyTable EnergyTable::load(const std::filesystem::path& csv_path) {
  return parse(read_file_text(csv_path), csv_path.string());
}

EnergyTable EnergyTable::parse(std::string_view csv_text, std::string_view origin) {
  EnergyTable table;
  table.origin_ = std::string(origin);
  std::string where = fmt::format("energy table '{}'", origin);
  std::unordered_map<std::string, int> seen;
  for (CsvRow& row : read_csv(csv_text, where, {"event", "energy_pJ", "reference_voltage_V", "source"})) {
    check_name_and_source(row, "event", where, seen);
    EnergyEvent e;
    e.event = row.fields[0];
    e.energy_pJ = parse_number(row.fields[1], "energy_pJ", where, row.line);
    if (e.energy_pJ < 0) fail("{} line {}: energy_pJ {} is negative", where, row.line, row.fields[1]);
    if (row.fields[2] != "-") {
      e.reference_voltage_V = parse_number(row.fields[2], "reference_voltage_V", where, row.line);
      if (e.reference_voltage_V <= 0)
        fail("{} line {}: reference_voltage_V {} must be > 0 (or '-' for an off-chip event)", where, row.line,
             row.fields[2]);
    }
    e.source = std::move(row.fields[3]);
    table.rows_.push_back(std::move(e));
  }
  return table;
}

bool EnergyTable::contains(std::string_view event) const {
  for (const EnergyEvent& e : rows_)
    if (e.event == event) return true;
  return false;
}

const EnergyEvent& EnergyTable::at(std::string_view event) const {
  for (const EnergyEvent& e : rows_)
    if (e.event == event) return e;
  fail("energy table '{}': unknown event '{}'", origin_, event);
}

LeakageTable LeakageTable::load(const std::filesystem::path& csv_path) {
  return parse(read_file_text(csv_path), csv_path.string());
}

LeakageTable LeakageTable::parse(std::string_view csv_text, std::string_view origin) {
  LeakageTable table;
  table.origin_ = std::string(origin);
  std::string where = fmt::format("leakage table '{}'", origin);
  std::unordered_map<std::string, int> seen;
  for (CsvRow& row : read_csv(csv_text, where, {"block", "leakage_mW", "reference_voltage_V", "source"})) {
    check_name_and_source(row, "block", where, seen);
    LeakageBlock b;
    b.block = row.fields[0];
    b.leakage_mW = parse_number(row.fields[1], "leakage_mW", where, row.line);
    if (b.leakage_mW < 0) fail("{} line {}: leakage_mW {} is negative", where, row.line, row.fields[1]);
    b.reference_voltage_V = parse_number(row.fields[2], "reference_voltage_V", where, row.line);
    if (b.reference_voltage_V <= 0)
      fail("{} line {}: reference_voltage_V {} must be > 0", where, row.line, row.fields[2]);
    b.source = std::move(row.fields[3]);
    table.rows_.push_back(std::move(b));
  }
  return table;
}

const std::array<PaperOperatingPoint, 5>& table1_operating_points() {
  static const std::array<PaperOperatingPoint, 5> points = {{
      {{50, 0.79}, 50.3, 13.2, 6.0},
      {{150, 0.98}, 205.6, 38.8, 8.3},
      {{250, 1.06}, 364.0, 61.2, 9.3},
      {{350, 1.16}, 569.8, 81.3, 11.0},
      {{380, 1.21}, 643.5, 85.9, 11.7},
  }};
  return points;
}

EnergyModel::EnergyModel(EnergyTable events, LeakageTable leakage, double leakage_voltage_exponent)
    : events_(std::move(events)), leakage_(std::move(leakage)), leakage_exponent_(leakage_voltage_exponent) {
  if (!std::isfinite(leakage_voltage_exponent) || leakage_voltage_exponent < 0)
    fail("energy model: leakage_voltage_exponent {} must be a finite number >= 0", leakage_voltage_exponent);
}

EnergyReport EnergyModel::evaluate(const EnergyRun& run, const OperatingPoint& point) const {
  if (!(point.frequency_MHz > 0) || !std::isfinite(point.frequency_MHz))
    fail("energy model: frequency_MHz {} must be > 0", point.frequency_MHz);
  if (!(point.voltage_V > 0) || !std::isfinite(point.voltage_V))
    fail("energy model: voltage_V {} must be > 0", point.voltage_V);
  if (!(run.dram_model_energy_pJ >= 0) || !std::isfinite(run.dram_model_energy_pJ))
    fail("energy model: dram_model_energy_pJ {} must be a finite number >= 0", run.dram_model_energy_pJ);

  EnergyReport r;
  r.point = point;
  r.cycles = run.cycles;
  r.pixels = run.pixels;
  r.time_s = double(run.cycles) / (point.frequency_MHz * 1e6);

  for (const auto& [name, count] : run.event_counts) {
    const EnergyEvent& e = events_.at(name);
    if (count == 0) continue;
    double energy_pJ = double(count) * e.energy_pJ;
    if (e.scales_with_core_voltage()) {
      double ratio = point.voltage_V / e.reference_voltage_V;
      energy_pJ *= ratio * ratio;
      r.core_dynamic_pJ += energy_pJ;
    } else {
      r.offchip_pJ += energy_pJ;
    }
    r.by_event.push_back({name, count, energy_pJ});
  }
  r.offchip_pJ += run.dram_model_energy_pJ;

  for (const LeakageBlock& b : leakage_.rows()) {
    double power_mW = b.leakage_mW * std::pow(point.voltage_V / b.reference_voltage_V, leakage_exponent_);
    double energy_pJ = power_mW * r.time_s * 1e9;  // mW x s = mJ = 1e9 pJ
    r.static_pJ += energy_pJ;
    r.by_block.push_back({b.block, power_mW, energy_pJ});
  }

  r.total_pJ = r.core_dynamic_pJ + r.offchip_pJ + r.static_pJ;
  r.nJ_per_pixel = run.pixels ? r.total_pJ * 1e-3 / double(run.pixels) : 0.0;
  r.average_power_W = r.time_s > 0 ? r.total_pJ * 1e-12 / r.time_s : 0.0;
  return r;
}

nlohmann::json energy_report_json(const EnergyReport& r) {
  nlohmann::json j;
  j["frequency_MHz"] = r.point.frequency_MHz;
  j["voltage_V"] = r.point.voltage_V;
  j["cycles"] = r.cycles;
  j["pixels"] = r.pixels;
  j["time_s"] = r.time_s;
  j["core_dynamic_pJ"] = r.core_dynamic_pJ;
  j["offchip_pJ"] = r.offchip_pJ;
  j["static_pJ"] = r.static_pJ;
  j["total_pJ"] = r.total_pJ;
  j["nJ_per_pixel"] = r.nJ_per_pixel;
  j["average_power_W"] = r.average_power_W;
  nlohmann::json events = nlohmann::json::array();
  for (const auto& e : r.by_event)
    events.push_back({{"event", e.event}, {"count", e.count}, {"energy_pJ", e.energy_pJ}});
  j["by_event"] = std::move(events);
  nlohmann::json blocks = nlohmann::json::array();
  for (const auto& b : r.by_block)
    blocks.push_back({{"block", b.block}, {"leakage_power_mW", b.power_mW}, {"energy_pJ", b.energy_pJ}});
  j["by_block"] = std::move(blocks);
  return j;
}

std::string format_energy_report(const EnergyReport& r) {
  auto share = [&](double pJ) { return r.total_pJ > 0 ? 100.0 * pJ / r.total_pJ : 0.0; };
  std::string out = fmt::format("energy at {:g} MHz, {:.3f} V: {} cycles ({:.6g} s), {} pixels\n",
                                r.point.frequency_MHz, r.point.voltage_V, r.cycles, r.time_s, r.pixels);
  out += fmt::format("  {:<28} {:>16.6g} pJ {:6.2f} %\n", "core dynamic", r.core_dynamic_pJ, share(r.core_dynamic_pJ));
  out += fmt::format("  {:<28} {:>16.6g} pJ {:6.2f} %\n", "off-chip (DRAM)", r.offchip_pJ, share(r.offchip_pJ));
  out += fmt::format("  {:<28} {:>16.6g} pJ {:6.2f} %\n", "static (leakage)", r.static_pJ, share(r.static_pJ));
  out += fmt::format("  {:<28} {:>16.6g} pJ\n", "total", r.total_pJ);
  out += fmt::format("  {:<28} {:>16.4f} nJ/pixel\n", "energy per pixel", r.nJ_per_pixel);
  out += fmt::format("  {:<28} {:>16.4f} W\n", "average power", r.average_power_W);
  out += fmt::format("  {:<28} {:>16} {:>19} {:>8}\n", "event", "count", "energy_pJ", "share");
  for (const auto& e : r.by_event)
    out += fmt::format("  {:<28} {:>16} {:>19.6g} {:6.2f} %\n", e.event, e.count, e.energy_pJ, share(e.energy_pJ));
  out += fmt::format("  {:<28} {:>16} {:>19} {:>8}\n", "leakage block", "power_mW", "energy_pJ", "share");
  for (const auto& b : r.by_block)
    out +=
        fmt::format("  {:<28} {:>16.4f} {:>19.6g} {:6.2f} %\n", b.block, b.power_mW, b.energy_pJ, share(b.energy_pJ));
  return out;
}

void export_stats(const EnergyReport& r, StatsRegistry& registry, const std::string& prefix) {
  registry.value(prefix + ".core_dynamic_pJ", "pJ", "core dynamic energy, scaled to the core voltage")
      .set(r.core_dynamic_pJ);
  registry.value(prefix + ".offchip_pJ", "pJ", "off-chip (DRAM) energy").set(r.offchip_pJ);
  registry.value(prefix + ".static_pJ", "pJ", "leakage energy over the run").set(r.static_pJ);
  registry.value(prefix + ".total_pJ", "pJ", "total energy").set(r.total_pJ);
  registry.value(prefix + ".nJ_per_pixel", "nJ/pixel", "total energy per rendered pixel").set(r.nJ_per_pixel);
  registry.value(prefix + ".power_W", "W", "average power over the run").set(r.average_power_W);
  for (const auto& e : r.by_event)
    registry.value(prefix + ".event." + e.event + "_pJ", "pJ", fmt::format("energy of {} {} events", e.count, e.event))
        .set(e.energy_pJ);
}

}  // namespace edrnr::sim
