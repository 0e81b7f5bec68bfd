#pragma once
// Running a sweep's jobs and collecting their rows: in this process, in
// worker processes on this machine, across MPI ranks (sweep/mpi.cpp), or as
// one shard of a Slurm job array. Every way hands out jobs one at a time to
// whoever is free (points differ in cost), in plan order, and writes the same
// rows; the table is written in plan order, so it is the same whatever ran it.
#include <chrono>
#include <filesystem>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "sweep/evaluate.h"
#include "sweep/plan.h"

namespace edrnr::sweep {

struct Shard {
  int index = 0, count = 1;  // this shard runs the jobs whose plan index % count == index
};

struct RunOptions {
  // Processes on this machine. 1: the jobs run in this process; more: each
  // runs in a worker started with worker_command (it must run serve_worker
  // on its stdin and stdout for the same plan).
  int workers = 1;
  std::vector<std::string> worker_command;
  std::optional<Shard> shard;   // write DIR/shards/shard-i-of-n.jsonl, not the table
  bool retry_failed = false;    // run jobs whose earlier row is an error again
  bool progress = false;        // a progress line with ETA on stderr
  double write_interval_s = 2;  // the table is rewritten at most this often while running
};

struct RunSummary {
  size_t jobs = 0;         // jobs of the plan (of the shard)
  size_t done_before = 0;  // found in the folder and skipped
  size_t ran = 0;          // evaluated now
  size_t failed = 0;       // of those, rows with status "error"
  double seconds = 0;
};

// The rows of a sweep as they arrive: which jobs are left, progress, and the
// table (or shard file) rewritten as rows come in. Thread-safe.
class Collector {
 public:
  Collector(const SweepPlan& plan, std::filesystem::path dir, const RunOptions& options);
  // Jobs still to run, plan order (of this shard).
  const std::vector<size_t>& todo() const { return todo_; }
  void add(size_t job, Row row);
  // Writes the final table (or shard file); returns the summary.
  RunSummary finish();

 private:
  void write_locked();
  const SweepPlan& plan_;
  std::filesystem::path dir_;
  RunOptions options_;
  std::map<std::string, Row> rows_;  // every row of the output file, by key
  std::vector<size_t> todo_;
  RunSummary summary_;
  std::mutex mutex_;
  std::chrono::steady_clock::time_point start_, last_write_;
};

// Runs the plan's jobs in this process or in options.workers worker
// processes, writing DIR's table (or the shard's file). A job whose worker
// dies becomes an error row naming the signal or exit status, and a new
// worker takes over.
RunSummary run_local(const SweepPlan& plan, const std::filesystem::path& dir, const RunOptions& options);

// The worker side: writes {"hello": plan_hash} on out_fd, then for each job
// index read as a line from in_fd writes its row as one line, until end of
// input.
void serve_worker(const SweepPlan& plan, int in_fd, int out_fd);

// MPI (sweep/mpi.cpp). Whether edrnr was built with MPI.
bool mpi_available();
// Whether this process was started by an MPI launcher (mpirun, srun with PMI).
bool started_by_mpi_launcher();
// Runs the plan over the MPI ranks: rank 0 hands out jobs (and runs them too
// on a second thread), gathers the rows and writes; the others evaluate.
// Initializes and finalizes MPI. Throws Error if MPI is unavailable.
RunSummary run_mpi(const SweepPlan& plan, const std::filesystem::path& dir, const RunOptions& options,
                   int* rank = nullptr);

// Merges DIR/results.jsonl with every shard file and writes the table.
// Returns the number of the plan's jobs that have a row.
size_t merge_shards(const SweepPlan& plan, const std::filesystem::path& dir);

}  // namespace edrnr::sweep
