// Sweeps across MPI ranks (built when CMake finds MPI; see runner.h).
#include <cstdlib>
#include <string>

#include "core/error.h"
#include "sweep/runner.h"
#include "sweep/table.h"

#ifdef EDRNR_HAVE_MPI
#include <mpi.h>

#include <atomic>
#include <thread>
#endif

namespace edrnr::sweep {

bool started_by_mpi_launcher() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", "MPI_LOCALNRANKS"})
    if (std::getenv(v)) return true;
  return false;
}

#ifndef EDRNR_HAVE_MPI

bool mpi_available() { return false; }

RunSummary run_mpi(const SweepPlan&, const std::filesystem::path&, const RunOptions&, int*) {
  fail(
      "MPI is unavailable: this edrnr was built without it (install libopenmpi-dev and openmpi-bin, "
      "scripts/setup.sh does, and configure again); run the sweep with --workers instead");
}

#else

bool mpi_available() { return true; }

namespace {

constexpr int kTagRequest = 1;  // worker -> rank 0: {"hello": plan hash} or {"job", "row"}
constexpr int kTagJob = 2;      // rank 0 -> worker: a job index, or -1: stop

void check(int rc, const char* what) {
  if (rc != MPI_SUCCESS) fail("MPI: {} failed (error {})", what, rc);
}

// Waits for a message without spinning a core (MPI_Recv polls at full speed,
// which would take the core a rank's simulation needs).
MPI_Status wait_message(int source, int tag) {
  MPI_Status st;
  for (;;) {
    int flag = 0;
    check(MPI_Iprobe(source, tag, MPI_COMM_WORLD, &flag, &st), "MPI_Iprobe");
    if (flag) return st;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

std::string receive_text(const MPI_Status& st) {
  int count = 0;
  MPI_Get_count(&st, MPI_CHAR, &count);
  std::string text(size_t(count), '\0');
  check(MPI_Recv(text.data(), count, MPI_CHAR, st.MPI_SOURCE, st.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE),
        "MPI_Recv");
  return text;
}

void send_text(const std::string& text, int dest) {
  check(MPI_Send(text.data(), int(text.size()), MPI_CHAR, dest, kTagRequest, MPI_COMM_WORLD), "MPI_Send");
}

void send_job(long long job, int dest) {
  check(MPI_Send(&job, 1, MPI_LONG_LONG, dest, kTagJob, MPI_COMM_WORLD), "MPI_Send");
}

struct Finalizer {
  ~Finalizer() {
    int finalized = 0;
    MPI_Finalized(&finalized);
    if (!finalized) MPI_Finalize();
  }
};

}  // namespace

RunSummary run_mpi(const SweepPlan& plan, const std::filesystem::path& dir, const RunOptions& options, int* rank_out) {
  int provided = 0;
  check(MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided), "MPI_Init_thread");
  Finalizer finalizer;
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  if (rank_out) *rank_out = rank;
  const std::string hash = plan_hash(plan);

  if (rank != 0) {
    ReferenceImages refs;
    RunSummary summary;
    std::string message = nlohmann::json{{"hello", hash}}.dump();
    for (;;) {
      send_text(message, 0);
      const MPI_Status st = wait_message(0, kTagJob);
      long long job = -1;
      check(MPI_Recv(&job, 1, MPI_LONG_LONG, 0, kTagJob, MPI_COMM_WORLD, MPI_STATUS_IGNORE), "MPI_Recv");
      (void)st;
      if (job < 0 || size_t(job) >= plan.jobs.size()) break;
      const Row row = evaluate_job(plan, size_t(job), refs);
      ++summary.ran;
      if (row["status"] != "ok") ++summary.failed;
      message = nlohmann::ordered_json{{"job", job}, {"row", row}}.dump();
    }
    MPI_Barrier(MPI_COMM_WORLD);
    return summary;
  }

  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) fail("--out '{}': cannot create the folder: {}", dir.string(), ec.message());
  write_plan_files(dir, plan);
  Collector collector(plan, dir, options);
  const std::vector<size_t>& todo = collector.todo();
  std::atomic<size_t> next{0};
  auto take = [&]() -> long long {
    const size_t n = next.fetch_add(1);
    return n < todo.size() ? (long long)todo[n] : -1;
  };
  // Rank 0 evaluates too, on a second thread that makes no MPI calls.
  std::thread local([&] {
    ReferenceImages refs;
    for (long long job; (job = take()) >= 0;) collector.add(size_t(job), evaluate_job(plan, size_t(job), refs));
  });
  std::string mismatch;
  int active = size - 1;
  try {
    while (active > 0) {
      const MPI_Status st = wait_message(MPI_ANY_SOURCE, kTagRequest);
      const nlohmann::ordered_json msg = nlohmann::ordered_json::parse(receive_text(st));
      if (msg.contains("hello")) {
        if (msg["hello"] != hash) {
          mismatch =
              fmt::format("rank {} made a different plan (the SPEC or a model differs on its node)", st.MPI_SOURCE);
          send_job(-1, st.MPI_SOURCE);
          --active;
          continue;
        }
      } else {
        collector.add(msg["job"].get<size_t>(), msg["row"]);
      }
      const long long job = mismatch.empty() ? take() : -1;
      send_job(job, st.MPI_SOURCE);
      if (job < 0) --active;
    }
  } catch (...) {
    next = todo.size();
    local.join();
    MPI_Abort(MPI_COMM_WORLD, 1);
    throw;
  }
  local.join();
  MPI_Barrier(MPI_COMM_WORLD);
  RunSummary summary = collector.finish();
  if (!mismatch.empty()) fail("sweep over MPI: {}", mismatch);
  return summary;
}

#endif

}  // namespace edrnr::sweep
