// edrnr train: learns a scene model from a NeRF dataset on the CPU and writes
// the quantized (INT4 features, INT8 MLPs) model; the float model on request.
#include <fmt/format.h>
#include <pthread.h>
#include <sys/resource.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <iterator>
#include <memory>
#include <string>
#include <vector>

#include "commands.h"
#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"
#include "core/metrics.h"
#include "data/dataset.h"
#include "model/model_io.h"
#include "render/reference.h"
#include "train/checkpoint_io.h"
#include "train/fit_box.h"
#include "train/images.h"
#include "train/trainer.h"

namespace edrnr::cli {
namespace {

// SIGINT, SIGTERM and SIGHUP all stop the run at the end of the current step
// with a checkpoint (a SIGKILL cannot be caught: the last periodic checkpoint
// is what survives it).
std::atomic<bool> g_interrupt{false};
std::atomic<int> g_signal{0};
extern "C" void on_stop_signal(int sig) {
  g_signal.store(sig);
  g_interrupt.store(true);
}
constexpr int kStopSignals[] = {SIGINT, SIGTERM, SIGHUP};

const char* signal_name(int sig) { return sig == SIGTERM ? "SIGTERM" : sig == SIGHUP ? "SIGHUP" : "SIGINT"; }

struct TrainCmdOptions {
  std::string dataset, output, float_output, resume, checkpoint;
  std::vector<std::string> configs;
  double minutes = 0, checkpoint_minutes = 5;
  int64_t iters = 0, stop_after = -1;
  uint64_t seed = 0;
  int threads = 0, downscale = 0, eval_views = 0;
  bool profile = false;
  CLI::Option *minutes_opt, *iters_opt, *seed_opt, *downscale_opt, *config_opt;
};

// Every file the run will write, checked before any work: each can be
// written, and no two name the same file (the checkpoint clean-up would
// otherwise delete the model, or the float model overwrite the quantized one).
void check_outputs(const TrainCmdOptions& o, const std::filesystem::path& checkpoint) {
  struct Out {
    const char* flag;
    std::filesystem::path path;
  };
  std::vector<Out> outs = {{"-o", o.output}, {"--checkpoint", checkpoint}};
  if (!o.float_output.empty()) outs.push_back({"--float-output", o.float_output});
  for (size_t i = 0; i < outs.size(); ++i)
    for (size_t j = i + 1; j < outs.size(); ++j)
      if (same_file(outs[i].path, outs[j].path))
        fail("{} '{}' and {} '{}' name the same file; each output needs its own", outs[i].flag, outs[i].path.string(),
             outs[j].flag, outs[j].path.string());
  if (!o.resume.empty())
    for (const Out& out : outs)
      if (std::string(out.flag) != "--checkpoint" && same_file(out.path, o.resume))
        fail("{} '{}' is the checkpoint given to --resume: writing the model there would destroy it", out.flag,
             out.path.string());
  for (const Out& out : outs) check_output_path(out.path, out.flag);
}

double peak_rss_gib() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / (1024.0 * 1024.0);  // ru_maxrss is in KiB on Linux
}

// Mean PSNR of a model over the first `n` views of a split.
double eval_split(const SceneModel& model, const std::filesystem::path& root, const train::TrainConfig& cfg, int n,
                  int threads) {
  DatasetOptions d;
  d.split = "test";
  d.downscale = cfg.downscale;
  for (int c = 0; c < 3; ++c) d.background[c] = cfg.background[c];
  const Dataset ds = load_dataset(root, d);
  RenderSettings rs;
  rs.step_micro = cfg.step_micro;
  rs.transmittance_min = cfg.transmittance_min;
  for (int c = 0; c < 3; ++c) rs.background[c] = cfg.background[c];
  rs.threads = threads;
  const int views = std::min<int>(n, int(ds.frames.size()));
  double sum = 0;
  for (int v = 0; v < views; ++v)
    sum += psnr(render_reference(model, ds.frames[size_t(v)].camera, rs), ds.frames[size_t(v)].image);
  return views ? sum / views : 0.0;
}

void run_train(const TrainCmdOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  limits::check_threads(o.threads);
  if (!(o.checkpoint_minutes > 0)) fail("--checkpoint-minutes {}: must be positive", o.checkpoint_minutes);
  if (o.eval_views < 0) fail("--eval-views {}: must not be negative", o.eval_views);
  const bool resuming = !o.resume.empty();
  if (resuming && (o.config_opt->count() || o.iters_opt->count() || o.minutes_opt->count() || o.seed_opt->count() ||
                   o.downscale_opt->count()))
    fail(
        "--resume continues with the checkpoint's settings: --config, --iters, --minutes, --seed and --downscale "
        "cannot change them");

  if (o.checkpoint.empty() && !output_is_regular_file(o.output))
    fail("-o '{}' is not a regular file, so the checkpoint cannot go beside it as '{}.ckpt': give --checkpoint FILE",
         o.output, o.output);
  const std::filesystem::path checkpoint_path(o.checkpoint.empty() ? o.output + ".ckpt" : o.checkpoint);
  check_outputs(o, checkpoint_path);
  if (o.eval_views > 0 && !std::filesystem::is_regular_file(std::filesystem::path(o.dataset) / "transforms_test.json"))
    fail("--eval-views {}: '{}' has no test split (transforms_test.json) to evaluate on", o.eval_views, o.dataset);

  std::vector<uint8_t> ckpt;
  train::TrainConfig cfg;
  if (resuming) {
    ckpt = train::read_checkpoint_file(o.resume);
    // The dataset must be loaded as the checkpoint's run loaded it.
    cfg = train::Trainer::checkpoint_config(ckpt, o.resume);
  } else {
    for (const auto& c : o.configs) cfg = train::load_train_config(c, cfg);
    if (o.iters_opt->count()) {
      if (o.iters < 1) fail("--iters {}: must be at least 1", o.iters);
      cfg.iters = o.iters;
      cfg.minutes = 0;
    }
    if (o.minutes_opt->count()) {
      if (!(o.minutes > 0)) fail("--minutes {}: must be positive", o.minutes);
      cfg.minutes = o.minutes;
    }
    if (o.seed_opt->count()) cfg.seed = o.seed;
    if (o.downscale_opt->count()) {
      if (o.downscale < 1) fail("--downscale {}: must be a positive integer", o.downscale);
      cfg.downscale = o.downscale;
    }
    cfg.validate();
  }

  const bool tty = isatty(STDERR_FILENO) != 0;
  // Messages go to stderr whether or not it is a terminal, so a long run
  // written to a log file shows where it is; only the live line needs a tty.
  auto say = [&](const std::string& m) {
    fmt::print(stderr, "{}\n", m);
    std::fflush(stderr);
  };
  DatasetOptions d;
  d.split = cfg.split;
  d.downscale = cfg.downscale;
  for (int c = 0; c < 3; ++c) d.background[c] = cfg.background[c];
  say(fmt::format("loading {} ({} split, downscale {})", o.dataset, cfg.split, cfg.downscale));
  d.load_images = !cfg.random_background;
  Dataset data = load_dataset(o.dataset, d);
  if (cfg.random_background) train::load_premultiplied_rgba(data, cfg.downscale);

  // With fit_box_steps the trainer is made after the pilot run (below).
  const bool fit_box = !resuming && train::pilot_pays(cfg);
  if (!resuming && cfg.fit_box_steps > 0 && !fit_box) {
    say(fmt::format("scene box as given: {} steps are fewer than {} times the pilot's {} (fit_box_steps)", cfg.iters,
                    train::kPilotShare, cfg.fit_box_steps));
    cfg.fit_box_steps = 0;
  }
  std::unique_ptr<train::Trainer> trainer;
  if (resuming)
    trainer = std::make_unique<train::Trainer>(data, ckpt, o.resume);
  else if (!fit_box)
    trainer = std::make_unique<train::Trainer>(data, cfg);
  ckpt.clear();
  ckpt.shrink_to_fit();

  train::TrainOptions opt;
  opt.threads = o.threads;
  opt.checkpoint_path = checkpoint_path;
  opt.checkpoint_minutes = o.checkpoint_minutes;
  opt.progress = tty;
  opt.progress_log_seconds = tty ? 0 : 60;
  opt.stop_after = o.stop_after;
  opt.interrupt = &g_interrupt;
  opt.log = say;
  g_interrupt.store(false);
  g_signal.store(0);
  using Handler = void (*)(int);
  Handler previous[std::size(kStopSignals)];
  for (size_t i = 0; i < std::size(kStopSignals); ++i) previous[i] = std::signal(kStopSignals[i], on_stop_signal);
  // A stop signal that arrived while blocked (inherited mask) is handled now.
  sigset_t stop_set;
  sigemptyset(&stop_set);
  for (int sig : kStopSignals) sigaddset(&stop_set, sig);
  pthread_sigmask(SIG_UNBLOCK, &stop_set, nullptr);
  auto restore = [&] {
    for (size_t i = 0; i < std::size(kStopSignals); ++i) std::signal(kStopSignals[i], previous[i]);
  };
  bool done;
  try {
    if (fit_box) {
      say(fmt::format("fitting the scene box: a pilot run of {} steps", cfg.fit_box_steps));
      cfg = train::fit_scene_box(data, cfg, opt).config;
      trainer = std::make_unique<train::Trainer>(data, cfg);
    }
    done = trainer->run(opt);
  } catch (...) {
    restore();
    throw;
  }
  restore();
  const train::TrainStats st = trainer->stats();
  if (!done) {
    fmt::print("stopped at step {}/{}; checkpoint written to {}\n", st.step, st.iters, opt.checkpoint_path.string());
    fmt::print("continue with: edrnr train {} -o {} --resume {}\n", o.dataset, o.output, opt.checkpoint_path.string());
    std::fflush(stdout);
    if (g_interrupt.load()) fail("interrupted by {}", signal_name(g_signal.load()));
    return;
  }
  const SceneModel quantized = trainer->export_model(true);
  SceneModel float_model;
  if (!o.float_output.empty() || o.eval_views > 0) float_model = trainer->export_model(false);
  try {
    save_model(o.output, quantized);
    if (!o.float_output.empty()) save_model(o.float_output, float_model);
  } catch (const Error& e) {
    // The finished run is not lost with the write: it is kept as a
    // checkpoint, from which --resume writes the model without training again.
    std::string kept;
    try {
      write_file_atomic(opt.checkpoint_path, trainer->checkpoint());
      kept = fmt::format(
          "the finished run is saved in the checkpoint '{}': once the problem is fixed, `edrnr train {} -o {} "
          "--resume {}{}` writes the model without training again",
          opt.checkpoint_path.string(), o.dataset, o.output, opt.checkpoint_path.string(),
          o.float_output.empty() ? "" : " --float-output " + o.float_output);
    } catch (const Error& e2) {
      kept = fmt::format(
          "the checkpoint '{}' could not be written either ({}); an earlier checkpoint there, if any, "
          "is intact",
          opt.checkpoint_path.string(), e2.what());
    }
    fail("{}; {}", e.what(), kept);
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  fmt::print("trained {} steps in {:.1f} min: {} blocks, {} MLPs; peak memory {:.2f} GiB\n", st.step, seconds / 60,
             st.blocks, st.mlps, peak_rss_gib());
  fmt::print("training PSNR (running): float {:.2f} dB, quantized {:.2f} dB\n", st.psnr_float, st.psnr_quantized);
  if (o.profile) {
    fmt::print("time per stage:");
    for (const auto& [name, sec] : st.stage_seconds) fmt::print("  {} {:.1f} s", name, sec);
    fmt::print("\n");
  }
  fmt::print("wrote {}{}\n", o.output, o.float_output.empty() ? "" : " and " + o.float_output);
  if (o.eval_views > 0) {
    const double pf = eval_split(float_model, o.dataset, trainer->config(), o.eval_views, o.threads);
    const double pq = eval_split(quantized, o.dataset, trainer->config(), o.eval_views, o.threads);
    fmt::print("test PSNR ({} views): float {:.2f} dB, quantized {:.2f} dB\n", o.eval_views, pf, pq);
  }
  std::error_code ec;
  std::filesystem::remove(opt.checkpoint_path, ec);  // the run finished: its checkpoint is no longer needed
}

void register_train_cmd(CLI::App& app) {
  auto o = std::make_shared<TrainCmdOptions>();
  CLI::App* cmd = app.add_subcommand("train", "Learn a scene model from a NeRF dataset (CPU), quantization-aware");
  cmd->add_option("dataset", o->dataset, "NeRF dataset folder (transforms_train.json and images)")->required();
  cmd->add_option("-o,--output", o->output, "the quantized .edrnr model to write")->required();
  o->config_opt = cmd->add_option("--config", o->configs,
                                  "YAML preset (configs/train/*.yaml); repeated, each file's keys override the one "
                                  "before; flags override them all")
                      ->allow_extra_args(false);
  o->minutes_opt = cmd->add_option("--minutes", o->minutes, "time budget: the step count is fitted to it");
  o->iters_opt = cmd->add_option("--iters", o->iters, "training steps (overrides the preset and --minutes)");
  o->seed_opt = cmd->add_option("--seed", o->seed, "random seed");
  o->downscale_opt = cmd->add_option("--downscale", o->downscale, "integer image downscale factor");
  cmd->add_option("--resume", o->resume, "continue from this checkpoint (same dataset)");
  cmd->add_option("--checkpoint", o->checkpoint, "checkpoint file (default: <output>.ckpt)");
  cmd->add_option("--checkpoint-minutes", o->checkpoint_minutes, "minutes between checkpoints")->capture_default_str();
  cmd->add_option("--float-output", o->float_output, "also write the float model here");
  cmd->add_option("--eval-views", o->eval_views, "after training, report test-split PSNR over this many views")
      ->capture_default_str();
  cmd->add_option("--stop-after", o->stop_after, "checkpoint and stop after this many steps (for resuming later)");
  cmd->add_option("--threads", o->threads, "threads (0: all cores)")->capture_default_str();
  cmd->add_flag("--profile", o->profile, "print the time spent in each stage of training");
  cmd->callback([o] { run_train(*o); });
}

Registrar reg{60, register_train_cmd};

}  // namespace
}  // namespace edrnr::cli
