// edrnr sweep: runs a design-space sweep (docs/sweeps.md) through the cycle
// simulator: on all cores of this machine (worker processes), across MPI
// ranks (started by mpirun), or as shards of a Slurm job array; writes the
// results table, the Pareto front and its plot.
#include <fmt/format.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "commands.h"
#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"
#include "search_paths.h"
#include "subprocess.h"
#include "sweep/pareto.h"
#include "sweep/plan.h"
#include "sweep/runner.h"
#include "sweep/table.h"

namespace edrnr::cli {
namespace {

namespace fs = std::filesystem;

struct SweepOptions {
  std::string spec, out, shard, python;
  int workers = 0, shards = 4, cpus_per_task = 1;
  bool mpi = false, merge = false, slurm = false, retry_failed = false, quiet = false, no_plot = false, worker = false,
       dry_run = false;
  CLI::Option* workers_opt = nullptr;
};

sweep::Shard parse_shard(const std::string& text) {
  const size_t slash = text.find('/');
  try {
    if (slash == std::string::npos) throw std::invalid_argument(text);
    size_t a = 0, b = 0;
    const int i = std::stoi(text.substr(0, slash), &a), n = std::stoi(text.substr(slash + 1), &b);
    if (a != slash || b != text.size() - slash - 1 || n < 1 || n > 100000 || i < 0 || i >= n)
      throw std::invalid_argument(text);
    return {i, n};
  } catch (const std::exception&) {
    fail("--shard '{}': expected I/N with 0 <= I < N <= 100000 (e.g. 0/4)", text);
  }
}

int default_workers() {
  if (const char* c = std::getenv("SLURM_CPUS_PER_TASK")) {
    const int n = std::atoi(c);
    if (n >= 1 && n <= limits::kMaxThreads) return n;
  }
  const unsigned n = std::thread::hardware_concurrency();
  return n ? int(std::min<unsigned>(n, limits::kMaxThreads)) : 1;
}

std::string quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

fs::path absolute_path(const fs::path& p) {
  std::error_code ec;
  const fs::path a = fs::absolute(p, ec);
  return ec ? p : a.lexically_normal();
}

// Writes DIR/slurm/{sweep.sbatch, merge.sbatch, submit.sh}.
void write_slurm_scripts(const SweepOptions& o, const sweep::SweepPlan& plan) {
  if (o.shards < 1 || o.shards > 100000) fail("--shards {}: must be between 1 and 100000", o.shards);
  if (o.cpus_per_task < 1 || o.cpus_per_task > limits::kMaxThreads)
    fail("--cpus-per-task {}: must be between 1 and {}", o.cpus_per_task, limits::kMaxThreads);
  const fs::path dir = absolute_path(o.out), slurm = dir / "slurm";
  std::error_code ec;
  fs::create_directories(slurm, ec);
  if (ec) fail("--out '{}': cannot create the folder: {}", slurm.string(), ec.message());
  const std::string exe = absolute_path(executable_dir() / "edrnr").string();
  const std::string spec = absolute_path(o.spec).string(), cwd = absolute_path(fs::current_path()).string();
  const int shards = int(std::min<size_t>(size_t(o.shards), std::max<size_t>(plan.jobs.size(), 1)));
  const std::string sweep_script = fmt::format(
      "#!/bin/bash\n"
      "# Slurm job array of `edrnr sweep {spec}`: task i of {n} runs the jobs whose\n"
      "# index % {n} == i and writes {dir}/shards/shard-i-of-{n}.jsonl. Submit with submit.sh\n"
      "# (it queues merge.sbatch after the array).\n"
      "#SBATCH --job-name=edrnr-sweep\n"
      "#SBATCH --array=0-{last}\n"
      "#SBATCH --ntasks=1\n"
      "#SBATCH --cpus-per-task={cpus}\n"
      "#SBATCH --output={dir}/slurm/shard-%a.log\n"
      "set -euo pipefail\n"
      "cd {qcwd}\n"
      "exec {qexe} sweep {qspec} --out {qdir} --shard \"${{SLURM_ARRAY_TASK_ID}}/{n}\" "
      "--workers \"${{SLURM_CPUS_PER_TASK:-1}}\" --quiet\n",
      fmt::arg("spec", spec), fmt::arg("n", shards), fmt::arg("last", shards - 1), fmt::arg("cpus", o.cpus_per_task),
      fmt::arg("dir", dir.string()), fmt::arg("qcwd", quote(cwd)), fmt::arg("qexe", quote(exe)),
      fmt::arg("qspec", quote(spec)), fmt::arg("qdir", quote(dir.string())));
  const std::string merge_script = fmt::format(
      "#!/bin/bash\n"
      "# Merges the shards of the sweep into {dir}/results.{{jsonl,csv}} and the Pareto report.\n"
      "#SBATCH --job-name=edrnr-sweep-merge\n"
      "#SBATCH --ntasks=1\n"
      "#SBATCH --output={dir}/slurm/merge.log\n"
      "set -euo pipefail\n"
      "cd {qcwd}\n"
      "exec {qexe} sweep {qspec} --out {qdir} --merge\n",
      fmt::arg("dir", dir.string()), fmt::arg("qcwd", quote(cwd)), fmt::arg("qexe", quote(exe)),
      fmt::arg("qspec", quote(spec)), fmt::arg("qdir", quote(dir.string())));
  const std::string submit = fmt::format(
      "#!/bin/bash\n"
      "# Queues the shards as a job array and the merge step after it (whatever the\n"
      "# shards' exit status: failed points are rows, and a shard that died leaves\n"
      "# its jobs for a rerun). Prints the two job ids.\n"
      "set -euo pipefail\n"
      "here=$(cd \"$(dirname \"$0\")\" && pwd)\n"
      "array=$(sbatch --parsable \"$here/sweep.sbatch\")\n"
      "array=${{array%%;*}}\n"
      "merge=$(sbatch --parsable --dependency=afterany:\"$array\" \"$here/merge.sbatch\")\n"
      "echo \"$array ${{merge%%;*}}\"\n");
  write_file_atomic(slurm / "sweep.sbatch", sweep_script);
  write_file_atomic(slurm / "merge.sbatch", merge_script);
  write_file_atomic(slurm / "submit.sh", submit);
  fs::permissions(slurm / "submit.sh", fs::perms::owner_exec | fs::perms::group_exec | fs::perms::others_exec,
                  fs::perm_options::add, ec);
  sweep::write_plan_files(dir, plan);
  fmt::print("wrote {0}/sweep.sbatch (job array of {1} shards, {2} jobs), {0}/merge.sbatch, {0}/submit.sh\n",
             slurm.string(), shards, plan.jobs.size());
  fmt::print("submit with: {}/submit.sh\n", slurm.string());
}

// Runs `python args...`; its exit status (127: python could not be started).
int run_python(const std::string& python, const std::vector<std::string>& args) {
  std::vector<std::string> argv = {python};
  argv.insert(argv.end(), args.begin(), args.end());
  return run_program(argv);
}

// pareto.csv, and pareto.png through scripts/pareto.py (matplotlib).
void write_pareto(const SweepOptions& o, const sweep::SweepPlan& plan) {
  const fs::path dir = o.out;
  const std::map<std::string, sweep::Row> rows = sweep::read_rows(sweep::results_jsonl_path(dir));
  const std::vector<sweep::ParetoPoint> points = sweep::pareto_points(plan, rows);
  write_file_atomic(dir / "pareto.csv", sweep::pareto_csv(plan, points));
  size_t front = 0;
  for (const sweep::ParetoPoint& p : points) front += p.on_front;
  fmt::print("pareto      {} of {} complete points on the front (FPS, nJ/pixel, SRAM): {}/pareto.csv\n", front,
             points.size(), o.out);
  if (o.no_plot || points.empty()) return;
  const std::optional<fs::path> script = find_shipped_file("scripts/pareto.py");
  if (!script) {
    fmt::print("pareto      no plot: scripts/pareto.py was not found beside the source tree or the executable\n");
    return;
  }
  const std::string label = plan.spec.base == "edr_nr_40nm" ? "paper design (edr_nr_40nm)" : "base: " + plan.spec.base;
  std::vector<std::string> candidates = {"python3", "/usr/bin/python3"};
  if (!o.python.empty()) candidates = {o.python};
  for (const std::string& py : candidates) {
    if (run_python(py, {script->string(), "--check"}) != 0) continue;
    const int rc = run_python(py, {script->string(), dir.string(), "--base-label", label});
    if (rc == 0) {
      fmt::print("pareto      plot: {}/pareto.png\n", o.out);
      return;
    }
  }
  fmt::print("pareto      no plot: no python3 with matplotlib (scripts/setup.sh installs python3-matplotlib)\n");
}

void print_summary(const SweepOptions& o, const sweep::SweepPlan& plan, const sweep::RunSummary& s, const char* how) {
  fmt::print("sweep       {} points x {} models, {} jobs{}; {} done before, {} run now ({} failed) in {:.1f} s {}\n",
             plan.points.size(), plan.models.size(), s.jobs,
             plan.duplicate_points ? fmt::format(" ({} duplicate points dropped)", plan.duplicate_points) : "",
             s.done_before, s.ran, s.failed, s.seconds, how);
}

void run_sweep_cmd(const SweepOptions& o) {
  const int modes = int(o.merge) + int(o.slurm) + int(!o.shard.empty()) + int(o.mpi) + int(o.dry_run);
  if (modes > 1) fail("--merge, --slurm-script, --shard, --mpi and --dry-run exclude each other");
  const sweep::SweepSpec spec = sweep::load_sweep_spec(o.spec);
  const sweep::SearchDirs dirs{preset_dirs("chip"), preset_dirs("dram")};
  const sweep::SweepPlan plan = sweep::make_plan(spec, dirs);
  if (o.worker) {
    sweep::serve_worker(plan, STDIN_FILENO, STDOUT_FILENO);
    return;
  }
  if (o.dry_run) {
    fmt::print("sweep       {} points x {} models, {} jobs ({} duplicate points dropped); base {}\n",
               plan.points.size(), plan.models.size(), plan.jobs.size(), plan.duplicate_points,
               plan.base_preset.string());
    for (const sweep::Point& p : plan.points) {
      std::string values;
      for (size_t i = 0; i < plan.varied.size(); ++i)
        values += fmt::format("{}{}={}", i ? " " : "", plan.varied[i], sweep::yaml_to_json(p.values[i]).dump());
      fmt::print("  point {:4}  {}  {}{}\n", p.index, p.config_hash.substr(0, 12), values,
                 p.config ? "" : "  (invalid: " + p.config_error + ")");
    }
    return;
  }
  if (o.out.empty()) fail("--out: required (the folder of the results table)");
  if (std::error_code ec; fs::exists(o.out, ec) && !fs::is_directory(o.out, ec))
    fail("--out '{}': not a folder", o.out);
  if (o.slurm) {
    write_slurm_scripts(o, plan);
    return;
  }
  if (o.merge) {
    const size_t have = sweep::merge_shards(plan, o.out);
    fmt::print("merge       {} of {} jobs have a row: {}/results.jsonl, {}/results.csv\n", have, plan.jobs.size(),
               o.out, o.out);
    write_pareto(o, plan);
    if (have < plan.jobs.size())
      fail("{} jobs have no row yet (a shard did not finish): run the sweep again to complete them",
           plan.jobs.size() - have);
    return;
  }

  sweep::RunOptions ro;
  ro.retry_failed = o.retry_failed;
  ro.progress = !o.quiet && isatty(STDERR_FILENO);
  if (!o.shard.empty()) ro.shard = parse_shard(o.shard);
  if (o.mpi || (o.shard.empty() && sweep::started_by_mpi_launcher())) {
    if (o.workers_opt->count() && o.workers != 1)
      fail("--workers {}: under MPI each rank is one worker (start more ranks instead)", o.workers);
    if (!sweep::mpi_available()) sweep::run_mpi(plan, o.out, ro);  // says MPI is unavailable
    int rank = 0;
    const sweep::RunSummary s = sweep::run_mpi(plan, o.out, ro, &rank);
    if (rank != 0) return;
    print_summary(o, plan, s, "over MPI");
    write_pareto(o, plan);
    return;
  }
  ro.workers = o.workers_opt->count() ? o.workers : default_workers();
  if (ro.workers < 1 || ro.workers > limits::kMaxThreads)
    fail("--workers {}: must be between 1 and {}", ro.workers, limits::kMaxThreads);
  ro.worker_command = {absolute_path(executable_dir() / "edrnr").string(), "sweep", o.spec, "--worker", "--quiet"};
  sweep::write_plan_files(o.out, plan);
  const sweep::RunSummary s = sweep::run_local(plan, o.out, ro);
  print_summary(o, plan, s,
                ro.shard ? fmt::format("(shard {}/{})", ro.shard->index, ro.shard->count).c_str()
                         : fmt::format("with {} worker process{}", ro.workers, ro.workers > 1 ? "es" : "").c_str());
  if (ro.shard) {
    fmt::print("shard       rows in {}\n", sweep::shard_path(o.out, ro.shard->index, ro.shard->count).string());
    return;
  }
  fmt::print("table       {0}/results.csv, {0}/results.jsonl\n", o.out);
  write_pareto(o, plan);
}

void register_sweep_cmd(CLI::App& app) {
  auto o = std::make_shared<SweepOptions>();
  CLI::App* cmd = app.add_subcommand(
      "sweep", "Run a design-space sweep through the cycle simulator (all cores, MPI ranks or Slurm shards)");
  cmd->add_option("spec", o->spec, "the sweep SPEC (YAML; docs/sweeps.md)")->required();
  cmd->add_option("--out", o->out, "folder of the results table (resumed if it holds one)");
  o->workers_opt = cmd->add_option("--workers", o->workers,
                                   "worker processes on this machine (default: every core; 1: in this process)");
  cmd->add_flag("--mpi", o->mpi, "spread the jobs over MPI ranks (automatic under mpirun)");
  cmd->add_option("--shard", o->shard, "run shard I/N only (Slurm array task), into DIR/shards/");
  cmd->add_flag("--merge", o->merge, "merge DIR/shards into the table and write the Pareto report");
  cmd->add_flag("--slurm-script", o->slurm, "write DIR/slurm/ (a job-array script, a merge step, submit.sh)");
  cmd->add_option("--shards", o->shards, "with --slurm-script: array tasks")->capture_default_str();
  cmd->add_option("--cpus-per-task", o->cpus_per_task, "with --slurm-script: cores of each array task")
      ->capture_default_str();
  cmd->add_flag("--retry-failed", o->retry_failed, "run the points recorded as errors again");
  cmd->add_flag("--dry-run", o->dry_run, "list the points and their config hashes, run nothing");
  cmd->add_flag("--no-plot", o->no_plot, "no pareto.png");
  cmd->add_option("--python", o->python, "python with matplotlib for pareto.png (default: python3, /usr/bin/python3)");
  cmd->add_flag("-q,--quiet", o->quiet, "no progress line");
  cmd->add_flag("--worker", o->worker, "internal: serve jobs on stdin/stdout")->group("");
  cmd->callback([o] { run_sweep_cmd(*o); });
}

Registrar reg{58, register_sweep_cmd};

}  // namespace
}  // namespace edrnr::cli
