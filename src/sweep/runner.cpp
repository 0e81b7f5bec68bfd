#include "sweep/runner.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <deque>

#include "core/error.h"
#include "core/file_io.h"
#include "sweep/table.h"

extern char** environ;

namespace edrnr::sweep {

namespace fs = std::filesystem;

namespace {

double seconds_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

// Writes all of `text` to fd; false if the other end is gone.
bool write_all(int fd, const std::string& text) {
  size_t off = 0;
  while (off < text.size()) {
    const ssize_t n = ::write(fd, text.data() + off, text.size() - off);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    off += size_t(n);
  }
  return true;
}

// Lines from a file descriptor.
class LineReader {
 public:
  explicit LineReader(int fd) : fd_(fd) {}
  // Reads what is there (one read call). False at end of input or on error.
  bool fill() {
    char buf[65536];
    for (;;) {
      const ssize_t n = ::read(fd_, buf, sizeof buf);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) return false;
      data_.append(buf, size_t(n));
      return true;
    }
  }
  std::optional<std::string> next() {
    const size_t nl = data_.find('\n');
    if (nl == std::string::npos) return std::nullopt;
    std::string line = data_.substr(0, nl);
    data_.erase(0, nl + 1);
    return line;
  }

 private:
  int fd_;
  std::string data_;
};

std::string describe_status(int status) {
  if (WIFSIGNALED(status))
    return fmt::format("killed by signal {} ({})", WTERMSIG(status), strsignal(WTERMSIG(status)));
  if (WIFEXITED(status)) return fmt::format("exited with status {}", WEXITSTATUS(status));
  return "ended";
}

struct WorkerProc {
  pid_t pid = -1;
  int to = -1, from = -1;  // its stdin, its stdout
  std::unique_ptr<LineReader> reader;
  bool ready = false;         // said hello
  std::optional<size_t> job;  // in flight
};

WorkerProc spawn_worker(const std::vector<std::string>& command) {
  int in[2], out[2];
  if (pipe2(in, O_CLOEXEC) != 0 || pipe2(out, O_CLOEXEC) != 0)
    fail("sweep: cannot create a pipe for a worker: {}", std::strerror(errno));
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_adddup2(&fa, in[0], 0);
  posix_spawn_file_actions_adddup2(&fa, out[1], 1);
  std::vector<char*> argv;
  for (const std::string& a : command) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  ::close(in[0]);
  ::close(out[1]);
  if (rc != 0) {
    ::close(in[1]);
    ::close(out[0]);
    fail("sweep: cannot start a worker process '{}': {}", command.empty() ? "" : command[0], std::strerror(rc));
  }
  WorkerProc w;
  w.pid = pid;
  w.to = in[1];
  w.from = out[0];
  w.reader = std::make_unique<LineReader>(w.from);
  return w;
}

}  // namespace

Collector::Collector(const SweepPlan& plan, fs::path dir, const RunOptions& options)
    : plan_(plan), dir_(std::move(dir)), options_(options) {
  std::map<std::string, Row> done = read_rows(results_jsonl_path(dir_));
  for (auto& [k, r] : read_shard_rows(dir_)) done.emplace(k, std::move(r));
  if (options_.shard) {
    rows_ = read_rows(shard_path(dir_, options_.shard->index, options_.shard->count));
    for (const auto& [k, r] : rows_) done[k] = r;
  } else {
    rows_ = done;
  }
  for (size_t i = 0; i < plan_.jobs.size(); ++i) {
    if (options_.shard && int(i % size_t(options_.shard->count)) != options_.shard->index) continue;
    ++summary_.jobs;
    auto it = done.find(plan_.jobs[i].key);
    const bool finished = it != done.end() && (it->second["status"] == "ok" || !options_.retry_failed);
    if (finished) {
      ++summary_.done_before;
      if (options_.shard) rows_[it->first] = it->second;
    } else {
      todo_.push_back(i);
    }
  }
  start_ = last_write_ = std::chrono::steady_clock::now();
}

void Collector::write_locked() {
  if (options_.shard) {
    const fs::path p = shard_path(dir_, options_.shard->index, options_.shard->count);
    std::error_code ec;
    fs::create_directories(p.parent_path(), ec);
    std::string text;
    for (const auto& [k, r] : rows_) text += r.dump() + "\n";
    write_file_atomic(p, text);
  } else {
    write_results(dir_, plan_, rows_);
  }
  last_write_ = std::chrono::steady_clock::now();
}

void Collector::add(size_t job, Row row) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++summary_.ran;
  if (row["status"] != "ok") ++summary_.failed;
  rows_[plan_.jobs[job].key] = std::move(row);
  if (options_.progress) {
    const double s = seconds_since(start_);
    const size_t left = todo_.size() - summary_.ran;
    const double eta = summary_.ran ? s / double(summary_.ran) * double(left) : 0;
    std::fprintf(stderr, "\r  sweep: %zu/%zu jobs run (%zu failed, %zu done before), %.1f s, ETA %.0f s   ",
                 summary_.ran, todo_.size(), summary_.failed, summary_.done_before, s, eta);
    if (left == 0) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  }
  if (seconds_since(last_write_) >= options_.write_interval_s) write_locked();
}

RunSummary Collector::finish() {
  std::lock_guard<std::mutex> lock(mutex_);
  write_locked();
  summary_.seconds = seconds_since(start_);
  return summary_;
}

void serve_worker(const SweepPlan& plan, int in_fd, int out_fd) {
  nlohmann::json hello = {{"hello", plan_hash(plan)}};
  if (!write_all(out_fd, hello.dump() + "\n")) return;
  ReferenceImages refs;
  LineReader in(in_fd);
  for (;;) {
    std::optional<std::string> line;
    while (!(line = in.next()))
      if (!in.fill()) return;
    size_t job = 0;
    try {
      size_t used = 0;
      job = std::stoull(*line, &used);
      if (used != line->size() || job >= plan.jobs.size()) throw std::out_of_range(*line);
    } catch (const std::exception&) {
      fail("sweep worker: '{}' is not a job of this plan (0..{})", *line, plan.jobs.size() - 1);
    }
    const Row row = evaluate_job(plan, job, refs);
    if (!write_all(out_fd, nlohmann::ordered_json{{"job", job}, {"row", row}}.dump() + "\n")) return;
  }
}

RunSummary run_local(const SweepPlan& plan, const fs::path& dir, const RunOptions& options) {
  if (options.workers < 1) fail("--workers {}: must be at least 1", options.workers);
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) fail("--out '{}': cannot create the folder: {}", dir.string(), ec.message());
  Collector collector(plan, dir, options);
  const std::vector<size_t>& todo = collector.todo();
  const size_t nworkers = std::min(size_t(options.workers), todo.size());
  if (nworkers <= 1 || options.worker_command.empty()) {
    ReferenceImages refs;
    for (size_t job : todo) collector.add(job, evaluate_job(plan, job, refs));
    return collector.finish();
  }

  // Worker processes, each fed one job at a time.
  struct sigaction ignore {
  }, old{};
  ignore.sa_handler = SIG_IGN;
  sigaction(SIGPIPE, &ignore, &old);
  const std::string expected_hello = nlohmann::json{{"hello", plan_hash(plan)}}.dump();
  std::deque<WorkerProc> workers;  // a deque: references stay valid when a replacement is added
  size_t next = 0, restarts = 0;
  std::string fatal;
  auto give = [&](WorkerProc& w) {
    if (next >= todo.size()) {
      ::close(w.to);
      w.to = -1;
      return;
    }
    w.job = todo[next++];
    if (!write_all(w.to, std::to_string(*w.job) + "\n")) {
      // Its end is reported by poll; the job is recorded there.
    }
  };
  try {
    for (size_t i = 0; i < nworkers; ++i) workers.push_back(spawn_worker(options.worker_command));
    for (;;) {
      std::vector<pollfd> fds;
      std::vector<size_t> which;
      for (size_t i = 0; i < workers.size(); ++i)
        if (workers[i].from >= 0) {
          fds.push_back({workers[i].from, POLLIN, 0});
          which.push_back(i);
        }
      if (fds.empty()) break;
      const int n = ::poll(fds.data(), fds.size(), -1);
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) fail("sweep: poll: {}", std::strerror(errno));
      for (size_t f = 0; f < fds.size(); ++f) {
        if (!fds[f].revents) continue;
        WorkerProc& w = workers[which[f]];
        const bool open = w.reader->fill();
        while (std::optional<std::string> line = w.reader->next()) {
          if (!w.ready) {
            if (*line != expected_hello)
              fail("sweep: a worker made a different plan (is the SPEC or a model changing while the sweep runs?)");
            w.ready = true;
            give(w);
            continue;
          }
          nlohmann::ordered_json msg;
          try {
            msg = nlohmann::ordered_json::parse(*line);
          } catch (const std::exception&) {
            fail("sweep: a worker wrote a line that is not a row: '{}'", line->substr(0, 200));
          }
          const size_t job = msg["job"].get<size_t>();
          if (!w.job || job != *w.job) fail("sweep: a worker answered job {} it was not given", job);
          w.job.reset();
          collector.add(job, std::move(msg["row"]));
          give(w);
        }
        if (!open) {
          ::close(w.from);
          w.from = -1;
          if (w.to >= 0) ::close(w.to), w.to = -1;
          int status = 0;
          while (waitpid(w.pid, &status, 0) < 0 && errno == EINTR) {
          }
          w.pid = -1;
          if (w.job) {
            collector.add(*w.job,
                          error_row(plan, *w.job,
                                    fmt::format("the worker process evaluating this job {}", describe_status(status))));
            w.job.reset();
            if (next < todo.size()) {
              if (++restarts > todo.size()) fail("sweep: worker processes keep dying; giving up");
              workers.push_back(spawn_worker(options.worker_command));
            }
          } else if (!w.ready) {
            fail("sweep: a worker process {} before it started (run with --workers 1 to see why)",
                 describe_status(status));
          }
        }
      }
    }
  } catch (...) {
    for (WorkerProc& w : workers) {
      if (w.to >= 0) ::close(w.to);
      if (w.from >= 0) ::close(w.from);
      if (w.pid > 0) {
        ::kill(w.pid, SIGTERM);
        int status;
        waitpid(w.pid, &status, 0);
      }
    }
    sigaction(SIGPIPE, &old, nullptr);
    collector.finish();
    throw;
  }
  sigaction(SIGPIPE, &old, nullptr);
  return collector.finish();
}

size_t merge_shards(const SweepPlan& plan, const fs::path& dir) {
  std::map<std::string, Row> rows = read_rows(results_jsonl_path(dir));
  for (auto& [k, r] : read_shard_rows(dir)) rows[k] = std::move(r);
  write_results(dir, plan, rows);
  size_t have = 0;
  for (const Job& j : plan.jobs) have += rows.count(j.key);
  return have;
}

}  // namespace edrnr::sweep
