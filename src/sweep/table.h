#pragma once
// The results table of a sweep: rows as JSON Lines (results.jsonl, one row a
// job, plan order) and as CSV (results.csv, the columns of table_columns),
// the reading back of earlier rows (resume), and the sweep folder's layout.
//
//   DIR/results.jsonl, DIR/results.csv   the table
//   DIR/pareto.csv, DIR/pareto.png       the front (sweep/pareto.h, scripts/pareto.py)
//   DIR/configs/<config_hash>.yaml       each point's fully resolved config
//   DIR/shards/shard-<i>-of-<n>.jsonl    rows of a Slurm shard, until merged
//   DIR/spec.yaml                        the SPEC the table was made from
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "sweep/evaluate.h"
#include "sweep/plan.h"

namespace edrnr::sweep {

std::filesystem::path results_jsonl_path(const std::filesystem::path& dir);
std::filesystem::path results_csv_path(const std::filesystem::path& dir);
std::filesystem::path shard_path(const std::filesystem::path& dir, int shard, int shards);

// Rows by key from a JSON Lines file; a missing file is empty. Lines that do
// not parse as a row (a write cut short) are skipped: their jobs run again.
std::map<std::string, Row> read_rows(const std::filesystem::path& path);
// Rows of every shard file in DIR/shards.
std::map<std::string, Row> read_shard_rows(const std::filesystem::path& dir);

// The JSON Lines text of the plan's rows (plan order) followed by rows of
// other plans found in the folder (key order), so that no result is lost.
std::string rows_jsonl(const SweepPlan& plan, const std::map<std::string, Row>& rows);
// The CSV text of the plan's rows, plan order; a missing metric is an empty
// cell, text with a comma, quote or line break is quoted.
// One CSV cell for a JSON value (RFC 4180 quoting when needed; null is empty).
std::string csv_cell(const nlohmann::ordered_json& v);

std::string rows_csv(const SweepPlan& plan, const std::map<std::string, Row>& rows);

// Writes results.jsonl and results.csv atomically.
void write_results(const std::filesystem::path& dir, const SweepPlan& plan, const std::map<std::string, Row>& rows);
// Writes DIR/configs/<hash>.yaml for each valid point and DIR/spec.yaml.
void write_plan_files(const std::filesystem::path& dir, const SweepPlan& plan);

}  // namespace edrnr::sweep
