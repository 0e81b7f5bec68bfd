#pragma once
// A test fixture that runs the built `edrnr` binary in a private temporary
// folder and captures its exit code, stdout and stderr.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>

#include "core/file_io.h"
#include "model/model_io.h"

namespace edrnr {

struct RunResult {
  int exit_code = -1;
  std::string out, err;
};

class CliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = std::filesystem::temp_directory_path() /
           ("edrnr_cli_" + std::string(info->name()) + "_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
    ASSERT_TRUE(std::filesystem::exists(binary())) << binary() << " is not built";
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  static std::filesystem::path binary() { return std::filesystem::path(EDRNR_BINARY_DIR) / "edrnr"; }

  RunResult run(const std::string& args) {
    std::filesystem::path out = dir_ / "stdout.txt", err = dir_ / "stderr.txt";
    std::string cmd = binary().string() + " " + args + " >" + out.string() + " 2>" + err.string() + " </dev/null";
    int status = std::system(cmd.c_str());
    RunResult r;
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = read_file_text(out);
    r.err = read_file_text(err);
    return r;
  }

  // A small quantized sphere model (make-scene) in the test folder, made once.
  std::string sphere_model() {
    const std::filesystem::path m = dir_ / "sphere.edrnr";
    if (!std::filesystem::exists(m)) {
      const RunResult r = run("make-scene sphere --res 32 --quantized-only -o " + m.string());
      EXPECT_EQ(r.exit_code, 0) << r.err;
    }
    return m.string();
  }

  std::filesystem::path save(const SceneModel& m, const std::string& name) {
    std::filesystem::path p = dir_ / name;
    save_model(p, m);
    return p;
  }

  std::filesystem::path dir_;
};

}  // namespace edrnr
