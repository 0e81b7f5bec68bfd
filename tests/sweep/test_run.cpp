// Running sweeps: rows, resume, failing points, and the same table from one
// process, two worker processes and two MPI ranks.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>

#include "model/procedural.h"
#include "render/cameras.h"
#include "sim/simulator.h"
#include "sweep/pareto.h"
#include "sweep/runner.h"
#include "sweep/table.h"
#include "sweep_fixture.h"

namespace edrnr::sweep {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using testing::kTinySpec;
using testing::read_text;
using testing::source_dirs;
using testing::TempDir;

SweepPlan tiny_plan(const TempDir& t, const std::string& text = kTinySpec) {
  return make_plan(load_sweep_spec(t.write("spec.yaml", text)), source_dirs());
}

TEST(SweepRun, RowsMatchADirectSimulation) {
  TempDir t("direct");
  const SweepPlan plan = tiny_plan(t);
  ASSERT_EQ(plan.jobs.size(), 5u);  // 2 x 2 points and the base design
  const RunSummary s = run_local(plan, t.path / "out", {});
  EXPECT_EQ(s.ran, 5u);
  EXPECT_EQ(s.failed, 0u);
  const auto rows = read_rows(results_jsonl_path(t.path / "out"));
  ASSERT_EQ(rows.size(), 5u);
  // Point 1 (8 entries, 200 MHz), simulated here directly.
  ProceduralOptions po;
  po.micro_res = 64;
  po.feature_channels = 8;
  const SceneModel m = make_procedural_model("sphere", procedural_shapes("sphere"), po);
  sim::SimConfig c =
      sim::load_sim_config(fs::path(EDRNR_SOURCE_DIR) / "configs/chip/edr_nr_40nm.yaml", source_dirs().dram);
  c.chip.rp_rob.entries = 8;
  c.clock_MHz = 200;
  const sim::SimResult r = sim::simulate_chip(m, orbit_camera(32, 32, 30, 30, 4, 40), c);
  const Row& row = rows.at(plan.jobs[1].key);
  EXPECT_EQ(row["status"], "ok");
  EXPECT_EQ(row["values"]["rp_rob.entries"], 8);
  EXPECT_EQ(row["values"]["simulator.clock_MHz"], 200);
  EXPECT_EQ(row["metrics"]["cycles"].get<uint64_t>(), r.summary.cycles);
  EXPECT_DOUBLE_EQ(row["metrics"]["fps"].get<double>(), r.summary.fps);
  EXPECT_DOUBLE_EQ(row["metrics"]["nJ_per_pixel"].get<double>(), r.energy->nJ_per_pixel);
  EXPECT_EQ(row["metrics"]["dram_read_bytes"].get<uint64_t>(), r.summary.dram_read_bytes);
  EXPECT_EQ(row["metrics"]["sram_total_bytes"].get<uint64_t>(), r.sram_budget.total_bytes());
  // The CSV has a header and one line per row.
  const std::string csv = read_text(results_csv_path(t.path / "out"));
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 6);
  EXPECT_THAT(csv, HasSubstr("point,model,view,rp_rob.entries,simulator.clock_MHz,config_hash,status,fps"));
}

TEST(SweepRun, ResumeSkipsFinishedJobsAndRerunsLostOnes) {
  TempDir t("resume");
  const SweepPlan plan = tiny_plan(t);
  const fs::path out = t.path / "out";
  run_local(plan, out, {});
  const std::string first = read_text(results_jsonl_path(out));
  RunSummary again = run_local(plan, out, {});
  EXPECT_EQ(again.done_before, 5u);
  EXPECT_EQ(again.ran, 0u);
  EXPECT_EQ(read_text(results_jsonl_path(out)), first);
  // Lose the last two rows, the second cut in the middle of its line.
  std::vector<std::string> lines;
  for (size_t a = 0, b; (b = first.find('\n', a)) != std::string::npos; a = b + 1)
    lines.push_back(first.substr(a, b - a));
  ASSERT_EQ(lines.size(), 5u);
  std::ofstream(results_jsonl_path(out), std::ios::binary) << lines[0] << "\n"
                                                           << lines[1] << "\n"
                                                           << lines[2] << "\n"
                                                           << lines[3].substr(0, 40);
  again = run_local(plan, out, {});
  EXPECT_EQ(again.done_before, 3u);
  EXPECT_EQ(again.ran, 2u);
  EXPECT_EQ(read_text(results_jsonl_path(out)), first);
}

TEST(SweepRun, FailingPointsAreRowsAndTheSweepGoesOn) {
  TempDir t("bad");
  const SweepPlan plan = tiny_plan(t, R"(include_base: false
vary:
  feature_cache.bytes: [262144, 1048576]
  rp_rob.entries: [0, 16]
models: [{procedural: sphere, res: 64, channels: 8}]
views: {width: 32}
)");
  ASSERT_EQ(plan.jobs.size(), 4u);
  const RunSummary s = run_local(plan, t.path / "out", {});
  EXPECT_EQ(s.ran, 4u);
  EXPECT_EQ(s.failed, 3u);
  const auto rows = read_rows(results_jsonl_path(t.path / "out"));
  // 256 KB, 0 entries: not a valid config.
  EXPECT_EQ(rows.at(plan.jobs[0].key)["status"], "error");
  EXPECT_THAT(rows.at(plan.jobs[0].key)["error"].get<std::string>(), HasSubstr("entries"));
  // 256 KB, 16 entries: fine.
  EXPECT_EQ(rows.at(plan.jobs[1].key)["status"], "ok");
  // 1 MB feature cache: over Table I's 256 KB feature SRAM, with its SRAM sizes.
  const Row& over = rows.at(plan.jobs[3].key);
  EXPECT_EQ(over["status"], "error");
  EXPECT_THAT(over["error"].get<std::string>(), HasSubstr("SRAM"));
  EXPECT_EQ(over["metrics"]["over_budget"], true);
  EXPECT_TRUE(over["metrics"]["fps"].is_null());
  // A resumed sweep does not run failed points again, unless asked to.
  RunOptions o;
  EXPECT_EQ(run_local(plan, t.path / "out", o).ran, 0u);
  o.retry_failed = true;
  EXPECT_EQ(run_local(plan, t.path / "out", o).ran, 3u);
}

TEST(SweepRun, AWorkerThatDiesLeavesAnErrorRowAndTheSweepGoesOn) {
  TempDir t("dies");
  const SweepPlan plan = tiny_plan(t);
  // A stand-in worker: says hello for this plan, takes a job and is killed.
  const std::string hello = nlohmann::json{{"hello", plan_hash(plan)}}.dump();
  RunOptions o;
  o.workers = 2;
  o.worker_command = {"/bin/sh", "-c", "printf '%s\\n' '" + hello + "'; read job; kill -9 $$"};
  const RunSummary s = run_local(plan, t.path / "out", o);
  EXPECT_EQ(s.ran, 5u);
  EXPECT_EQ(s.failed, 5u);
  const auto rows = read_rows(results_jsonl_path(t.path / "out"));
  ASSERT_EQ(rows.size(), 5u);
  for (const auto& [key, row] : rows) {
    EXPECT_EQ(row["status"], "error");
    EXPECT_THAT(row["error"].get<std::string>(), HasSubstr("killed by signal 9"));
  }
}

TEST(SweepRun, ShardsMergeIntoTheSameTable) {
  TempDir t("shards");
  const SweepPlan plan = tiny_plan(t);
  run_local(plan, t.path / "whole", {});
  for (int i = 0; i < 2; ++i) {
    RunOptions o;
    o.shard = Shard{i, 2};
    const RunSummary s = run_local(plan, t.path / "sharded", o);
    EXPECT_EQ(s.ran, i == 0 ? 3u : 2u);
  }
  EXPECT_FALSE(fs::exists(results_jsonl_path(t.path / "sharded")));
  EXPECT_EQ(merge_shards(plan, t.path / "sharded"), 5u);
  EXPECT_EQ(read_text(results_jsonl_path(t.path / "sharded")), read_text(results_jsonl_path(t.path / "whole")));
}

TEST(SweepPareto, DominatedPointsAreOffTheFront) {
  TempDir t("pareto");
  const SweepPlan plan = tiny_plan(t);
  std::map<std::string, Row> rows;
  // fps, nJ/px, SRAM per point: point 1 is dominated by point 0; 2 and 3 trade off.
  const double fps[] = {100, 90, 120, 80, 60}, nj[] = {10, 11, 12, 9, 20};
  const uint64_t sram[] = {1000, 1000, 1000, 1000, 900};
  for (size_t j = 0; j < plan.jobs.size(); ++j) {
    Row r = error_row(plan, j, "");
    r["status"] = "ok";
    r["metrics"]["fps"] = fps[j];
    r["metrics"]["nJ_per_pixel"] = nj[j];
    r["metrics"]["sram_total_bytes"] = sram[j];
    rows[plan.jobs[j].key] = r;
  }
  const std::vector<ParetoPoint> p = pareto_points(plan, rows);
  ASSERT_EQ(p.size(), 5u);
  EXPECT_TRUE(p[0].on_front);
  EXPECT_FALSE(p[1].on_front);
  EXPECT_TRUE(p[2].on_front);
  EXPECT_TRUE(p[3].on_front);
  EXPECT_TRUE(p[4].on_front);  // least SRAM
  EXPECT_TRUE(p[4].base);
  const std::string csv = pareto_csv(plan, p);
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 5);  // header and the 4 front points (the base is one)
  EXPECT_THAT(csv, HasSubstr(",base\n"));
}

// The CLI: one process, two worker processes and two MPI ranks write the same table.
// Runs a command with its output in `log`; "" if it succeeded, else what failed.
std::string run(const std::string& command, const fs::path& log) {
  const int rc = std::system((command + " > " + log.string() + " 2>&1").c_str());
  return rc == 0 ? "" : "'" + command + "' failed with status " + std::to_string(rc) + ":\n" + read_text(log);
}

TEST(SweepCli, OneProcessTwoWorkersAndTwoRanksGiveTheSameTable) {
  TempDir t("cli");
  t.write("spec.yaml", kTinySpec);
  const std::string edrnr = (fs::path(EDRNR_BINARY_DIR) / "edrnr").string();
  const std::string spec = (t.path / "spec.yaml").string();
  const fs::path log = t.path / "log.txt";
  ASSERT_EQ(run(edrnr + " sweep " + spec + " --no-plot --workers 1 --out " + (t.path / "one").string(), log), "");
  ASSERT_EQ(run(edrnr + " sweep " + spec + " --no-plot --workers 2 --out " + (t.path / "two").string(), log), "");
  const std::string one = read_text(t.path / "one" / "results.jsonl");
  EXPECT_EQ(std::count(one.begin(), one.end(), '\n'), 5);
  EXPECT_EQ(read_text(t.path / "two" / "results.jsonl"), one);
  EXPECT_EQ(read_text(t.path / "two" / "results.csv"), read_text(t.path / "one" / "results.csv"));
  EXPECT_EQ(read_text(t.path / "two" / "pareto.csv"), read_text(t.path / "one" / "pareto.csv"));
  if (std::system(("command -v mpirun > " + log.string() + " 2>&1").c_str()) != 0)
    GTEST_SKIP() << "mpirun is not installed";
  // OpenMPI refuses root unless told (CI runs as root).
  ASSERT_EQ(run("OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 mpirun --oversubscribe -np 2 " + edrnr +
                    " sweep " + spec + " --no-plot --out " + (t.path / "mpi").string(),
                log),
            "");
  EXPECT_EQ(read_text(t.path / "mpi" / "results.jsonl"), one);
  EXPECT_EQ(read_text(t.path / "mpi" / "results.csv"), read_text(t.path / "one" / "results.csv"));
}

TEST(SweepCli, BadSpecIsANamedErrorAndANonZeroExit) {
  TempDir t("clibad");
  t.write("spec.yaml", "vary:\n  rp_rob.entries: [8, many]\nmodels: [{procedural: sphere, res: 64}]\n");
  const std::string edrnr = (fs::path(EDRNR_BINARY_DIR) / "edrnr").string();
  const std::string err = (t.path / "err.txt").string();
  const int rc = std::system(
      (edrnr + " sweep " + (t.path / "spec.yaml").string() + " --out " + (t.path / "o").string() + " 2> " + err)
          .c_str());
  EXPECT_NE(rc, 0);
  EXPECT_THAT(read_text(err), HasSubstr("spec.yaml:2: vary.rp_rob.entries: 'many' is not a number"));
}

}  // namespace
}  // namespace edrnr::sweep
