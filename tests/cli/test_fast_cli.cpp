// `edrnr bench render` and `edrnr render --turntable` through the built
// binary: flag checks, a small benchmark run on a procedural scene, the
// turntable frames and the video step with and without ffmpeg on PATH.
#include <gtest/gtest.h>

#include <filesystem>
#include <sstream>
#include <string>

#include "cli_fixture.h"
#include "core/file_io.h"
#include "core/image.h"

namespace edrnr {
namespace {

namespace fs = std::filesystem;

class FastCliTest : public CliTest {
 protected:
  // Runs `args` with PATH set to `path` only (the binary is called by its full path).
  RunResult run_with_path(const fs::path& path, const std::string& args) {
    const fs::path out = dir_ / "stdout.txt", err = dir_ / "stderr.txt";
    const std::string cmd = "PATH=" + path.string() + " " + binary().string() + " " + args + " >" + out.string() +
                            " 2>" + err.string() + " </dev/null";
    const int status = std::system(cmd.c_str());
    RunResult r;
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = read_file_text(out);
    r.err = read_file_text(err);
    return r;
  }

  static bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

  // The value column of statistic `name` in a printed table ("" if absent).
  static std::string stat(const std::string& text, const std::string& name) {
    std::istringstream in(text);
    std::string line;
    while (std::getline(in, line)) {
      std::istringstream fields(line);
      std::string key, value;
      if (fields >> key >> value && key == name) return value;
    }
    return "";
  }
};

TEST_F(FastCliTest, BenchRenderRejectsBadFlags) {
  const std::string m = sphere_model();
  struct Case {
    std::string args, message;
  };
  const Case cases[] = {
      {"--frames 0", "--frames 0 is outside 1..1000"},
      {"--frames 1001", "--frames 1001 is outside 1..1000"},
      {"--warmup 101", "--warmup 101 is outside 0..100"},
      {"--vs chip", "--vs 'chip': only 'reference' is supported"},
      {"--views 24", "--views '24': 24 is out of range (0..23)"},
      {"--views 3-1", "--views '3-1': range 3-1 is backwards"},
      {"--views x", "--views 'x': 'x' is not an index"},
      {"--engine warp", "--engine 'warp': unknown"},
      {"--form half", "--form"},
      {"--step 0", "--step"},
  };
  for (const Case& c : cases) {
    const RunResult r = run("bench render " + m + " --width 16 " + c.args);
    EXPECT_NE(r.exit_code, 0) << c.args;
    EXPECT_TRUE(has(r.err, c.message)) << c.args << ": " << r.err;
  }
  const RunResult missing = run("bench render " + (dir_ / "absent.edrnr").string() + " --width 16");
  EXPECT_NE(missing.exit_code, 0);
  EXPECT_TRUE(has(missing.err, "absent.edrnr")) << missing.err;
}

TEST_F(FastCliTest, BenchRenderRunsOnATinyScene) {
  const std::string m = sphere_model();
  const RunResult r =
      run("bench render " + m + " --width 32 --views 0,1 --frames 1 --warmup 0 --vs reference --threads 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(has(r.out, "engine fast (INT8 path)")) << r.out;
  EXPECT_TRUE(has(r.out, "orbit 0 deg")) << r.out;
  EXPECT_TRUE(has(r.out, "orbit 15 deg")) << r.out;
  EXPECT_TRUE(has(r.out, "32x32")) << r.out;
  EXPECT_TRUE(has(r.out, "CPU-time ratio to the reference")) << r.out;
  EXPECT_TRUE(has(r.out, "time shares (profiled frames")) << r.out;
  // One profiled frame per view: two views of 32 x 32 rays.
  EXPECT_EQ(stat(r.out, "fast.rays"), "2048") << r.out;
  EXPECT_TRUE(has(r.out, "peak memory")) << r.out;

  const RunResult ref = run("bench render " + m + " --width 16 --views 2 --frames 1 --warmup 0 --engine reference");
  ASSERT_EQ(ref.exit_code, 0) << ref.err;
  EXPECT_TRUE(has(ref.out, "orbit 30 deg")) << ref.out;
  EXPECT_TRUE(has(ref.out, "time shares: measured for the fast engines only")) << ref.out;
}

TEST_F(FastCliTest, TurntableWithoutFfmpegKeepsTheFrames) {
  const std::string m = sphere_model();
  const fs::path bin = dir_ / "empty_bin", frames = dir_ / "frames";
  fs::create_directories(bin);
  const RunResult r =
      run_with_path(bin, "render " + m + " --engine fast --turntable 3 --width 24 -o " + frames.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(has(r.out, "3 frames 24x24")) << r.out;
  EXPECT_TRUE(has(r.out, "ffmpeg is not installed: no video made; the frames are in " + frames.string())) << r.out;
  for (int i = 0; i < 3; ++i) {
    const fs::path f = frames / ("frame_000" + std::to_string(i) + ".png");
    ASSERT_TRUE(fs::exists(f)) << f;
    const Image img = read_png_rgba(f);
    EXPECT_EQ(img.width, 24);
    EXPECT_EQ(img.height, 24);
  }
  EXPECT_FALSE(fs::exists(frames / "frame_0003.png"));
  EXPECT_FALSE(fs::exists(frames / "turntable.mp4"));

  // Frame 1 of 3 is the orbit view at azimuth 120 degrees.
  const fs::path single = dir_ / "single.png";
  const RunResult one = run("render " + m + " --engine fast --orbit 120 --width 24 -o " + single.string());
  ASSERT_EQ(one.exit_code, 0) << one.err;
  EXPECT_EQ(read_file_text(single), read_file_text(frames / "frame_0001.png"));
}

TEST_F(FastCliTest, TurntableHandsTheFramesToFfmpeg) {
  const std::string m = sphere_model();
  const fs::path bin = dir_ / "bin", frames = dir_ / "frames";
  fs::create_directories(bin);
  // A stand-in ffmpeg: records its arguments and writes its last one (the video).
  const fs::path ffmpeg = bin / "ffmpeg";
  write_file_atomic(ffmpeg, "#!/bin/sh\necho \"$@\" > " + (dir_ / "ffmpeg_args.txt").string() +
                                "\nfor a in \"$@\"; do last=\"$a\"; done\necho video > \"$last\"\n");
  fs::permissions(ffmpeg, fs::perms::owner_all);
  const RunResult r = run_with_path(bin.string() + ":/usr/bin:/bin",
                                    "render " + m + " --engine fast --turntable 2 --width 16 -o " + frames.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(has(r.out, (frames / "turntable.mp4").string() + ": MP4 made with ffmpeg")) << r.out;
  EXPECT_EQ(read_file_text(frames / "turntable.mp4"), "video\n");
  const std::string args = read_file_text(dir_ / "ffmpeg_args.txt");
  EXPECT_TRUE(has(args, (frames / "frame_%04d.png").string())) << args;
  EXPECT_TRUE(fs::exists(frames / "frame_0000.png"));
  EXPECT_TRUE(fs::exists(frames / "frame_0001.png"));

  // ffmpeg failing is an error that says the frames are kept.
  write_file_atomic(ffmpeg, "#!/bin/sh\nexit 3\n");
  fs::permissions(ffmpeg, fs::perms::owner_all);
  const RunResult bad = run_with_path(bin.string() + ":/usr/bin:/bin",
                                      "render " + m + " --engine fast --turntable 2 --width 16 -o " + frames.string());
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_TRUE(has(bad.err, "ffmpeg failed")) << bad.err;
  EXPECT_TRUE(has(bad.err, "they are kept in " + frames.string())) << bad.err;
}

TEST_F(FastCliTest, TurntableRejectsBadFlags) {
  const std::string m = sphere_model();
  const std::string out = (dir_ / "t").string();
  RunResult r = run("render " + m + " --engine fast --turntable 0 -o " + out);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_TRUE(has(r.err, "--turntable 0 is outside 1..3600 frames")) << r.err;
  r = run("render " + m + " --engine fast --turntable 2 --orbit 30 -o " + out);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_TRUE(has(r.err, "--turntable makes its own orbit cameras")) << r.err;
}

}  // namespace
}  // namespace edrnr
