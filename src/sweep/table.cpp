#include "sweep/table.h"

#include <fmt/format.h>

#include <set>

#include "core/error.h"
#include "core/file_io.h"

namespace edrnr::sweep {

namespace fs = std::filesystem;

namespace {

const nlohmann::ordered_json& cell(const Row& row, const std::string& column, const SweepPlan& plan) {
  static const nlohmann::ordered_json null;
  for (const std::string& k : plan.varied)
    if (k == column) return row.contains("values") && row["values"].contains(k) ? row["values"][k] : null;
  if (row.contains(column)) return row[column];
  if (row.contains("metrics") && row["metrics"].contains(column)) return row["metrics"][column];
  return null;
}

}  // namespace

std::string csv_cell(const nlohmann::ordered_json& v) {
  if (v.is_null()) return "";
  std::string s = v.is_string() ? v.get<std::string>() : v.dump();
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

fs::path results_jsonl_path(const fs::path& dir) { return dir / "results.jsonl"; }
fs::path results_csv_path(const fs::path& dir) { return dir / "results.csv"; }
fs::path shard_path(const fs::path& dir, int shard, int shards) {
  return dir / "shards" / fmt::format("shard-{}-of-{}.jsonl", shard, shards);
}

std::map<std::string, Row> read_rows(const fs::path& path) {
  std::map<std::string, Row> rows;
  std::error_code ec;
  if (!fs::exists(path, ec)) return rows;
  const std::string text = read_file_text(path, uint64_t(1) << 32);
  size_t start = 0;
  while (start < text.size()) {
    size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    const std::string line = text.substr(start, end - start);
    start = end + 1;
    if (line.empty()) continue;
    try {
      Row r = Row::parse(line);
      if (r.is_object() && r.contains("key") && r["key"].is_string() && r.contains("status")) {
        const std::string key = r["key"].get<std::string>();
        rows[key] = std::move(r);
      }
    } catch (const std::exception&) {
      // cut short: the job runs again
    }
  }
  return rows;
}

std::map<std::string, Row> read_shard_rows(const fs::path& dir) {
  std::map<std::string, Row> rows;
  std::error_code ec;
  const fs::path shards = dir / "shards";
  if (!fs::is_directory(shards, ec)) return rows;
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(shards, ec))
    if (e.path().extension() == ".jsonl") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  for (const fs::path& f : files)
    for (auto& [k, r] : read_rows(f)) rows[k] = std::move(r);
  return rows;
}

std::string rows_jsonl(const SweepPlan& plan, const std::map<std::string, Row>& rows) {
  std::string out;
  std::set<std::string> in_plan;
  for (const Job& j : plan.jobs) {
    in_plan.insert(j.key);
    if (auto it = rows.find(j.key); it != rows.end()) out += it->second.dump() + "\n";
  }
  for (const auto& [k, r] : rows)
    if (!in_plan.count(k)) out += r.dump() + "\n";
  return out;
}

std::string rows_csv(const SweepPlan& plan, const std::map<std::string, Row>& rows) {
  const std::vector<std::string> columns = table_columns(plan);
  std::string out;
  for (size_t i = 0; i < columns.size(); ++i) out.append(i ? "," : "").append(csv_cell(columns[i]));
  out += "\n";
  for (const Job& j : plan.jobs) {
    auto it = rows.find(j.key);
    if (it == rows.end()) continue;
    for (size_t i = 0; i < columns.size(); ++i)
      out.append(i ? "," : "").append(csv_cell(cell(it->second, columns[i], plan)));
    out += "\n";
  }
  return out;
}

void write_results(const fs::path& dir, const SweepPlan& plan, const std::map<std::string, Row>& rows) {
  write_file_atomic(results_jsonl_path(dir), rows_jsonl(plan, rows));
  write_file_atomic(results_csv_path(dir), rows_csv(plan, rows));
}

void write_plan_files(const fs::path& dir, const SweepPlan& plan) {
  std::error_code ec;
  fs::create_directories(dir / "configs", ec);
  if (ec) fail("--out '{}': cannot create the folder: {}", (dir / "configs").string(), ec.message());
  for (const Point& p : plan.points) {
    if (!p.config) continue;
    const fs::path f = dir / "configs" / (p.config_hash + ".yaml");
    if (fs::exists(f, ec)) continue;
    write_file_atomic(f, "# Fully resolved chip config of sweep point " + std::to_string(p.index) + " (" +
                             plan.spec.path.string() + ")\n" + p.config_yaml + "\n");
  }
  write_file_atomic(dir / "spec.yaml", plan.spec.text);
}

}  // namespace edrnr::sweep
