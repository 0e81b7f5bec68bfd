// What every command does with its output paths (issue #16): a symbolic link
// is followed and its target replaced, a FIFO (standing in for a device) is
// written through and stays what it was, a failed write keeps the old file,
// and training never destroys its own model or ends without a checkpoint.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "cli_fixture.h"
#include "core/file_io.h"
#include "model/procedural.h"
#include "train/synthetic.h"
#include "train/trainer.h"

namespace edrnr {
namespace {

namespace fs = std::filesystem;

class Outputs : public CliTest {
 protected:
  // 4 training and 2 test views at 16 x 16 of a sphere.
  std::string dataset() {
    const fs::path d = dir_ / "data";
    if (!fs::exists(d)) {
      ProceduralOptions po;
      po.micro_res = 32;
      po.feature_channels = 4;
      train::SyntheticViews v;
      v.train_views = 4;
      v.test_views = 2;
      v.width = v.height = 16;
      train::write_synthetic_dataset(make_procedural_model("sphere", procedural_shapes("sphere"), po), d, v);
    }
    return d.string();
  }
  // A smaller preset than configs/train/tiny.yaml: a 32^3 grid, for speed.
  std::string tiny_config() {
    const fs::path p = dir_ / "micro.yaml";
    if (!fs::exists(p))
      write_file_atomic(p, std::string("micro_res: 32\nlevels: [8, 16, 32]\nbatch_samples: 2048\nmin_rays: 32\n"
                                       "max_rays: 512\nper_cv_fraction: 0.15\nqat_fraction: 0.15\n"
                                       "occupancy_every: 8\naabb_start: 64\naabb_every: 64\nlr_warmup: 20\n"
                                       "plan_step: 120\nprune_cv_weight: 0\nqat_activations: false\n"));
    return p.string();
  }

  // Runs a command while a thread reads the FIFO; returns what it read.
  std::string run_into_fifo(const fs::path& fifo, const std::string& args, RunResult& r) {
    std::string got;
    std::thread reader([&] { got = read_file_text(fifo); });
    r = run(args);
    if (r.exit_code != 0) {
      // Unblock the reader if the command never opened the FIFO.
      const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);
      if (fd >= 0) ::close(fd);
    }
    reader.join();
    return got;
  }

  // Runs a command in a shell that first applies `prefix` (e.g. a ulimit).
  RunResult run_with(const std::string& prefix, const std::string& args) {
    const fs::path out = dir_ / "stdout.txt", err = dir_ / "stderr.txt";
    const std::string cmd =
        prefix + "; " + binary().string() + " " + args + " >" + out.string() + " 2>" + err.string() + " </dev/null";
    const int status = std::system(("sh -c '" + cmd + "'").c_str());
    RunResult r;
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = read_file_text(out);
    r.err = read_file_text(err);
    return r;
  }

  std::vector<std::string> names(const fs::path& d) {
    std::vector<std::string> v;
    for (const auto& e : fs::directory_iterator(d)) v.push_back(e.path().filename().string());
    std::sort(v.begin(), v.end());
    return v;
  }
  bool is_fifo(const fs::path& p) {
    struct stat st {};
    return ::lstat(p.c_str(), &st) == 0 && S_ISFIFO(st.st_mode);
  }
};

// Every command's output given as a symbolic link: the link stays, its target
// gets the new contents.
TEST_F(Outputs, SymbolicLinksAreFollowedByEveryCommand) {
  const std::string m = sphere_model(), data = dataset();
  fs::create_directories(dir_ / "real");
  struct Case {
    std::string link, args;
  };
  const std::string d = dir_.string();
  const std::vector<Case> cases = {
      {"scene.edrnr", "make-scene box --res 32 --quantized-only -o " + d + "/scene.edrnr"},
      {"view.png", "render " + m + " --orbit 10 --width 12 -o " + d + "/view.png"},
      {"chip.png", "chip-render " + m + " --orbit 10 --width 12 -o " + d + "/chip.png"},
      {"stats.json", "chip-render " + m + " --orbit 10 --width 12 -o " + d + "/c2.png --stats " + d + "/stats.json"},
      {"eval.json", "eval " + m + " " + data + " --json " + d + "/eval.json"},
      {"dram.json", "dram --preset ddr3-1600-4gb-x16-16bit --stream 10 --json " + d + "/dram.json"},
  };
  for (const Case& c : cases) {
    write_file_atomic(dir_ / "real" / c.link, std::string("old"));
    fs::create_symlink(fs::path("real") / c.link, dir_ / c.link);
    const RunResult r = run(c.args);
    ASSERT_EQ(r.exit_code, 0) << c.args << "\n" << r.err;
    EXPECT_TRUE(fs::is_symlink(dir_ / c.link)) << c.link;
    const std::string now = read_file_text(dir_ / "real" / c.link);
    EXPECT_NE(now, "old") << c.link;
    EXPECT_GT(now.size(), 10u) << c.link;
  }
  // The targets' folder holds the targets only: no temporary left behind.
  std::vector<std::string> want;
  for (const Case& c : cases) want.push_back(c.link);
  std::sort(want.begin(), want.end());
  EXPECT_EQ(names(dir_ / "real"), want);
  // The chip config goes beside the name given, as before.
  EXPECT_TRUE(fs::exists(dir_ / "chip.png.chip.yaml"));
}

// A FIFO (as a device would be) is written through and stays a FIFO; nothing
// is written beside it.
TEST_F(Outputs, FifosAreWrittenThroughByEveryCommand) {
  const std::string m = sphere_model(), data = dataset();
  const fs::path fifo = dir_ / "pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::string f = fifo.string();
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"make-scene sphere --res 32 --quantized-only -o " + f, "EDRNRMDL"},
      {"render " + m + " --orbit 0 --width 8 -o " + f, "\x89PNG"},
      {"chip-render " + m + " --orbit 0 --width 8 -o " + f, "\x89PNG"},
      {"chip-render " + m + " --orbit 0 --width 8 -o " + (dir_ / "c.png").string() + " --stats " + f, "{"},
      {"eval " + m + " " + data + " --json " + f, "{"},
      {"dram --preset ddr3-1600-4gb-x16-16bit --stream 10 --json " + f, "{"},
  };
  for (const auto& [args, head] : cases) {
    RunResult r;
    const std::string got = run_into_fifo(fifo, args, r);
    ASSERT_EQ(r.exit_code, 0) << args << "\n" << r.err;
    EXPECT_EQ(got.substr(0, head.size()), head) << args;
    EXPECT_TRUE(is_fifo(fifo)) << args;
  }
  EXPECT_FALSE(fs::exists(dir_ / "pipe.chip.yaml"));
  for (const std::string& n : names(dir_)) EXPECT_EQ(n.find(".tmp."), std::string::npos) << n;
}

// A write that fails (the file size limit standing in for a full disk) says
// why, exits 1 and leaves the old file as it was, with no temporary file.
TEST_F(Outputs, AFailedWriteKeepsTheOldFile) {
  write_file_atomic(dir_ / "keep.edrnr", std::string("the old model"));
  const RunResult r =
      run_with("trap \"\" XFSZ; ulimit -f 32", "make-scene sphere --res 64 -o " + (dir_ / "keep.edrnr").string());
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("error writing '" + (dir_ / "keep.edrnr").string() + "': File too large"), std::string::npos)
      << r.err;
  EXPECT_EQ(read_file_text(dir_ / "keep.edrnr"), "the old model");
  for (const std::string& n : names(dir_)) EXPECT_EQ(n.find(".tmp."), std::string::npos) << n;
}

// The checkpoint clean-up deleted the model when both had one name, and the
// float model overwrote the quantized one; both are refused before training,
// and the file already there is left alone.
TEST_F(Outputs, TrainingRefusesOutputsThatCollide) {
  const std::string data = dataset();
  const fs::path m = dir_ / "m2.edrnr";
  write_file_atomic(m, std::string("an earlier model"));
  RunResult r = run("train " + data + " -o " + m.string() + " --checkpoint " + m.string() + " --iters 5 --config " +
                    tiny_config());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("name the same file"), std::string::npos) << r.err;
  fs::create_symlink("m2.edrnr", dir_ / "alias.edrnr");
  r = run("train " + data + " -o " + m.string() + " --float-output " + (dir_ / "alias.edrnr").string() +
          " --iters 5 --threads 1 --config " + tiny_config());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("name the same file"), std::string::npos) << r.err;
  EXPECT_EQ(read_file_text(m), "an earlier model");
  // A run that writes both gets two different files and removes its checkpoint.
  r = run("train " + data + " -o " + m.string() + " --float-output " + (dir_ / "f.edrnr").string() +
          " --iters 6 --threads 1 --config " + tiny_config());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(read_file_text(m), read_file_text(dir_ / "f.edrnr"));
  EXPECT_EQ(run("inspect " + m.string()).exit_code, 0);
  EXPECT_FALSE(fs::exists(dir_ / "m2.edrnr.ckpt"));
}

// A run logged to a file says what it does (it printed nothing but the final
// summary when stderr was not a terminal): loading, then each phase change.
TEST_F(Outputs, TrainingLogsItsStepsWhenStderrIsAFile) {
  const std::string data = dataset();
  const fs::path m = dir_ / "logged.edrnr";
  const RunResult r = run("train " + data + " -o " + m.string() + " --iters 12 --threads 1 --config " + tiny_config());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("loading " + data), std::string::npos) << r.err;
  // The default pilot (fit_box_steps 1500) is skipped for so short a run.
  EXPECT_NE(r.err.find("scene box as given: 12 steps are fewer than 4 times the pilot's 1500"), std::string::npos)
      << r.err;
  EXPECT_EQ(r.err.find("fitting the scene box"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find(": per-CV phase ("), std::string::npos) << r.err;
  EXPECT_NE(r.err.find(": quantize phase ("), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find('\r'), std::string::npos) << "no live progress line in a file";
}

// A --minutes run with the scene-box pilot is repeated bit for bit by
// --iters with the step count it planned (how the bundled models are
// repeated on other machines): the pilot is the same fixed number of steps
// either way, and the run proper changes phase at the same steps.
TEST_F(Outputs, MinutesRunWithPilotRepeatsWithItsPlannedSteps) {
  const std::string data = dataset();
  const fs::path pilot = dir_ / "pilot.yaml";
  write_file_atomic(pilot, std::string("fit_box_steps: 70\nfit_box_margin: 0.1\n"));
  const fs::path timed = dir_ / "timed.edrnr", replay = dir_ / "replay.edrnr";
  const std::string cfg = " --threads 1 --config " + tiny_config() + " --config " + pilot.string();
  RunResult r = run("train " + data + " -o " + timed.string() + " --minutes 0.03" + cfg);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("fitting the scene box: a pilot run of 70 steps"), std::string::npos) << r.err;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.err, m, std::regex("training for ([0-9]+) steps"))) << r.err;
  const int64_t steps = std::stoll(m[1].str());
  ASSERT_GE(steps, 4 * 70) << "the replay would skip the pilot";
  r = run("train " + data + " -o " + replay.string() + " --iters " + std::to_string(steps) + cfg);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("fitting the scene box: a pilot run of 70 steps"), std::string::npos) << r.err;
  EXPECT_EQ(read_file_bytes(replay), read_file_bytes(timed));
}

// --config may be repeated: each file's keys override the one before, the
// keys a file does not set are kept, and a bad key names its file.
TEST_F(Outputs, RepeatedConfigsApplyInOrder) {
  const std::string data = dataset();
  const fs::path overlay = dir_ / "overlay.yaml", bad = dir_ / "bad-overlay.yaml";
  write_file_atomic(overlay, std::string("qat_fraction: 0.2\ndistortion_weight: 0.02\ntv_levels: 2\n"));
  write_file_atomic(bad, std::string("tv_levels: 9\n"));
  const fs::path m = dir_ / "o.edrnr", ckpt = dir_ / "o.edrnr.ckpt";
  RunResult r = run("train " + data + " -o " + m.string() + " --iters 40 --stop-after 0 --threads 1 --config " +
                    tiny_config() + " --config " + overlay.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const train::TrainConfig c = train::Trainer::checkpoint_config(read_file_bytes(ckpt), ckpt.string());
  EXPECT_EQ(c.micro_res, 32);             // from the first file only
  EXPECT_FLOAT_EQ(c.qat_fraction, 0.2f);  // both set it: the second wins
  EXPECT_FLOAT_EQ(c.per_cv_fraction, 0.15f);
  EXPECT_FLOAT_EQ(c.distortion_weight, 0.02f);
  EXPECT_EQ(c.tv_levels, 2);
  EXPECT_EQ(c.iters, 40);  // flags override every file
  r = run("train " + data + " -o " + (dir_ / "b.edrnr").string() + " --iters 40 --config " + tiny_config() +
          " --config " + bad.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("bad-overlay.yaml"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("tv_levels"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "b.edrnr"));
}

// `edrnr calibrate` on a model trained without activation calibration gives
// the bytes training with it exports (the trainer calls the same function
// on the same cameras), and refuses what it cannot calibrate.
TEST_F(Outputs, CalibrateGivesWhatTrainingWithCalibrationExports) {
  const std::string data = dataset();
  const fs::path off = dir_ / "no-calibration.yaml";
  write_file_atomic(off, std::string("calibrate_activations: false\n"));
  const fs::path plain = dir_ / "plain.edrnr", cal = dir_ / "cal.edrnr", trained = dir_ / "trained.edrnr";
  RunResult r = run("train " + data + " -o " + plain.string() + " --iters 40 --threads 1 --config " + tiny_config() +
                    " --config " + off.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run("train " + data + " -o " + trained.string() + " --iters 40 --threads 1 --config " + tiny_config());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run("calibrate " + plain.string() + " " + data + " -o " + cal.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("layer input steps changed"), std::string::npos) << r.out;
  EXPECT_EQ(read_file_bytes(cal), read_file_bytes(trained));
  EXPECT_NE(read_file_bytes(cal), read_file_bytes(plain));
  // A missing model, a missing dataset: an error naming it, nothing written.
  r = run("calibrate " + (dir_ / "missing.edrnr").string() + " " + data + " -o " + cal.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("missing.edrnr"), std::string::npos) << r.err;
  r = run("calibrate " + plain.string() + " " + (dir_ / "nodata").string() + " -o " + (dir_ / "c2.edrnr").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_FALSE(fs::exists(dir_ / "c2.edrnr"));
}

// SIGTERM stops training with a checkpoint, as SIGINT does, and the run
// resumes from it. The signal is raised, blocked, before edrnr starts, so it
// arrives exactly when edrnr is ready for it (no timing).
TEST_F(Outputs, SigtermStopsTrainingWithACheckpoint) {
  const std::string data = dataset();
  const fs::path m = dir_ / "t.edrnr", ckpt = dir_ / "t.edrnr.ckpt";
  const fs::path out = dir_ / "stdout.txt", err = dir_ / "stderr.txt";
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, SIGTERM);
    sigprocmask(SIG_BLOCK, &set, nullptr);
    ::raise(SIGTERM);  // pending until edrnr unblocks it
    const int o = ::open(out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int e = ::open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(o, 1);
    ::dup2(e, 2);
    const std::string bin = binary().string(), cfg = tiny_config(), mo = m.string();
    ::execl(bin.c_str(), bin.c_str(), "train", data.c_str(), "-o", mo.c_str(), "--iters", "6", "--threads", "1",
            "--config", cfg.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status)) << "killed by signal " << WTERMSIG(status);
  EXPECT_EQ(WEXITSTATUS(status), 1);
  EXPECT_NE(read_file_text(err).find("interrupted by SIGTERM"), std::string::npos) << read_file_text(err);
  EXPECT_NE(read_file_text(out).find("checkpoint written to " + ckpt.string()), std::string::npos);
  ASSERT_TRUE(fs::exists(ckpt));
  EXPECT_FALSE(fs::exists(m));
  const RunResult r = run("train " + data + " -o " + m.string() + " --resume " + ckpt.string() + " --threads 1");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(run("inspect " + m.string()).exit_code, 0);
  EXPECT_FALSE(fs::exists(ckpt));
}

// A periodic checkpoint that cannot be written (here: larger than the file
// size limit, which the model is not) is a warning: training still ends with
// its model.
TEST_F(Outputs, AFailedPeriodicCheckpointDoesNotEndTraining) {
  const std::string data = dataset();
  const fs::path m = dir_ / "p.edrnr";
  const RunResult r = run_with("trap \"\" XFSZ; ulimit -f 2048",  // 1 MiB (dash counts 512-byte blocks)
                               "train " + data + " -o " + m.string() +
                                   " --iters 5 --checkpoint-minutes 0.000001 --threads 1 --config " + tiny_config());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("not written (error writing '" + m.string() + ".ckpt': File too large); training goes on"),
            std::string::npos)
      << r.err;
  EXPECT_EQ(run("inspect " + m.string()).exit_code, 0);
}

// When the final model cannot be written, the finished run is kept as a
// checkpoint if that can be written; here neither can, and the message says
// both.
TEST_F(Outputs, AFailedFinalWriteSaysWhatSurvives) {
  const std::string data = dataset();
  const fs::path m = dir_ / "big.edrnr";
  const RunResult r = run_with("trap \"\" XFSZ; ulimit -f 16", "train " + data + " -o " + m.string() +
                                                                   " --iters 6 --threads 1 --config " + tiny_config());
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("error writing '" + m.string() + "': File too large"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("the checkpoint '" + m.string() + ".ckpt' could not be written either"), std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(m));
}

}  // namespace
}  // namespace edrnr
