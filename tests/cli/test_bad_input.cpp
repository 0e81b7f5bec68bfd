// The bad-input battery (issue #16, docs/reliability.md): one table of
// commands a hostile or careless user might type, each with the exit code and
// a fragment of the message it must get. Every input class is covered: model
// files, dataset JSON, images, chip and DRAM presets, train options, flags and
// outputs. A case passes only if edrnr exits with that code (no crash, no
// hang, no "internal error") and says that fragment on stderr.
//
// The inputs are tiny (a procedural scene at micro resolution 32, 16 x 16
// images), made once for the whole table.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/file_io.h"
#include "core/image.h"
#include "model/model_io.h"
#include "model/procedural.h"
#include "train/synthetic.h"

namespace edrnr {
namespace {

namespace fs = std::filesystem;

struct BadInput {
  const char* name;      // what the case is about (the test's name)
  const char* args;      // the command line; {D} is the fixture folder, {SRC} the source tree
  int exit_code;         // 1: an edrnr error; CLI11 parse errors: 104 conversion, 106 required, 109 extras
  const char* fragment;  // must appear on stderr
};

// clang-format off
const BadInput kCases[] = {
  // ---- flags and commands ----
  {"UnknownCommand", "frobnicate", 1, "unknown command 'frobnicate' (commands: inspect"},
  {"UnknownFlag", "render {D}/m.edrnr --orbit 0 --no-such-flag -o {D}/x.png", 109, "--no-such-flag"},
  {"MissingRequired", "render {D}/m.edrnr --orbit 0", 106, "--output is required"},
  {"NotANumber", "render {D}/m.edrnr --orbit 0 --width wide -o {D}/x.png", 104, "--width"},
  {"HugeImage", "render {D}/m.edrnr --orbit 0 --width 16384 --height 16384 -o {D}/x.png", 1,
   "--width/--height 16384x16384: 268435456 pixels, over the limit of 16777216 pixels per image"},
  {"ImageSideTooLong", "render {D}/m.edrnr --orbit 0 --width 20000 --height 2 -o {D}/x.png", 1,
   "--width/--height 20000x2: each side must be 1..16384 pixels"},
  {"ZeroWidth", "render {D}/m.edrnr --orbit 0 --width 0 -o {D}/x.png", 1, "each side must be 1..16384"},
  {"TooManyThreads", "render {D}/m.edrnr --orbit 0 --width 8 --threads 10000 -o {D}/x.png", 1,
   "--threads 10000: must be 0 (all cores) up to the limit of 256"},
  {"NegativeThreads", "eval {D}/m.edrnr {D}/data --threads -1", 1, "--threads -1: must be 0 (all cores)"},
  {"StepTiny", "render {D}/m.edrnr --orbit 0 --width 8 --step 1e-30 -o {D}/x.png", 1,
   "samples per ray at micro resolution 32, over the limit of 65536"},
  {"StepSmall", "render {D}/m.edrnr --orbit 0 --width 8 --step 1e-9 -o {D}/x.png", 1, "over the limit of 65536"},
  {"StepZero", "render {D}/m.edrnr --orbit 0 --width 8 --step 0 -o {D}/x.png", 1,
   "--step 0: must be a positive number of micro voxels"},
  {"StepHuge", "eval {D}/m.edrnr {D}/data --step 1e30", 1, "--step 1e+30: over the limit of 1024 micro voxels"},
  {"ChipRenderHugeImage", "chip-render {D}/m.edrnr --orbit 0 --width 20000 -o {D}/x.png", 1,
   "--width/--height 20000x20000"},
  {"SimulateClockInHz", "simulate {D}/m.edrnr --width 8 -q --clock 1e12", 1,
   "--clock 1000000000000: must be between 1 and 10000 MHz"},
  {"SimulateClockZero", "simulate {D}/m.edrnr --width 8 -q --clock 0", 1, "--clock 0: must be between 1 and 10000"},
  {"SimulateHugeImage", "simulate {D}/m.edrnr -q --width 16384 --height 16384", 1, "over the limit of 16777216"},
  {"SimulateBadTechnique", "simulate {D}/m.edrnr --width 8 -q --disable warp", 1, "unknown technique 'warp'"},
  {"DramRandomNegative", "dram --preset ddr3-1600-4gb-x16-16bit --random -1", 1,
   "--random -1: must be between 1 and 1000000000 requests"},
  {"DramStreamTooMany", "dram --preset ddr3-1600-4gb-x16-16bit --stream 2000000000", 1,
   "--stream 2000000000: must be between 1 and 1000000000"},
  {"DramNoWorkload", "dram --preset ddr3-1600-4gb-x16-16bit", 1, "give exactly one of --trace FILE"},
  {"DramWriteRatio", "dram --preset ddr3-1600-4gb-x16-16bit --stream 10 --write-ratio 2", 1,
   "--write-ratio 2 must be between 0 and 1"},

  // ---- model files ----
  {"ModelMissing", "inspect {D}/missing.edrnr", 1, "cannot open '{D}/missing.edrnr': No such file or directory"},
  {"ModelIsAFolder", "inspect {D}/folder", 1, "'{D}/folder' is a folder, not a file"},
  {"ModelIsDevZero", "render /dev/zero --orbit 0 --width 8 -o {D}/x.png", 1,
   "/dev/zero: not an edrnr model (the file does not start with the magic"},
  {"ModelIsText", "inspect {D}/text.txt", 1, "not an edrnr model"},
  {"ModelTruncated", "inspect {D}/cut.edrnr", 1, "(truncated or padded file)"},
  {"ModelHeaderClaimsHuge", "render {D}/huge.edrnr --orbit 0 --width 8 -o {D}/x.png", 1,
   "over the limit of 4294967296 bytes for a model"},
  {"ModelCorrupt", "inspect {D}/flipped.edrnr", 1, "CRC-32 mismatch"},
  {"MetadataTooDeepInspect", "inspect {D}/deep.edrnr", 1, "the JSON nests 100001 levels deep, over the limit of 64"},
  {"MetadataTooDeepRender", "render {D}/deep.edrnr --orbit 0 --width 8 -o {D}/x.png", 1, "over the limit of 64"},

  // ---- dataset JSON and images ----
  {"DatasetMissing", "eval {D}/m.edrnr {D}/nodata", 1, "split 'test' not found"},
  {"DatasetMalformedJson", "eval {D}/m.edrnr {D}/badjson", 1, "malformed JSON"},
  {"DatasetNoFrames", "eval {D}/m.edrnr {D}/noframes", 1, "'frames' is empty"},
  {"DatasetHugeSize", "eval {D}/m.edrnr {D}/hugesize", 1, "'w' must be an integer from 1 to 16384, got 30000"},
  {"DatasetTooManyPixels", "eval {D}/m.edrnr {D}/manypixels", 1, "over the limit of 16777216 pixels per image"},
  // simulate decodes only the chosen view (the split limit: tests/data/test_split_limit.cpp)
  {"SimulateViewImageMissing", "simulate {D}/m.edrnr -q --dataset {D}/bigsplit --width 8", 1,
   "bigsplit/test/r_0.png'"},
  {"PngClaimsHugeSize", "eval {D}/m.edrnr {D}/hugepng", 1, "30000x30000: each side must be 1..16384 pixels"},
  {"PngCorrupt", "eval {D}/m.edrnr {D}/corruptpng", 1, "r_0.png' is not a valid PNG"},
  {"PngMissing", "eval {D}/m.edrnr {D}/missingpng", 1, "image not found"},
  {"PngWrongSize", "eval {D}/m.edrnr {D}/wrongsize", 1, "but its camera expects 16x16"},
  {"EvalViewsTooSmallForSsim", "eval {D}/m.edrnr {D}/data8", 1, "views are 8x8 pixels; SSIM needs at least 11x11"},
  {"EvalDownscaledTooSmall", "eval {D}/m.edrnr {D}/data --downscale 2", 1, "after --downscale 2; SSIM needs"},
  {"EvalBadViews", "eval {D}/m.edrnr {D}/data --views 0,9", 1, "view 9 is out of range"},

  // ---- chip presets ----
  {"ChipPresetEmpty", "simulate {D}/m.edrnr --width 8 -q --chip {D}/empty.yaml", 1,
   "empty.yaml: the file is empty; a chip preset is a YAML map"},
  {"ChipPresetEmptySimulator", "simulate {D}/m.edrnr --width 8 -q --chip {D}/simnull.yaml", 1,
   "simnull.yaml.simulator: the section is empty"},
  {"ChipPresetNotYaml", "simulate {D}/m.edrnr --width 8 -q --chip {D}/notyaml.yaml", 1, "not valid YAML"},
  {"ChipPresetUnknownKey", "simulate {D}/m.edrnr --width 8 -q --chip {D}/unknown.yaml", 1, "unknown key 'warp'"},
  {"ChipPresetMissing", "simulate {D}/m.edrnr --width 8 -q --chip nosuchchip", 1, "--chip 'nosuchchip': no such file"},
  {"RpBufferHuge", "simulate {D}/m.edrnr --width 8 -q --chip {D}/rpbuf.yaml", 1,
   "rp_buffer_capacity 1000000000: must be between 1 and 65536 RPs"},
  {"RpBufferHugeChipRender", "chip-render {D}/m.edrnr --orbit 0 --width 8 --config {D}/rpbuf.yaml -o {D}/x.png", 1,
   "rp_buffer_capacity 1000000000: must be between 1 and 65536"},
  {"FeatureCacheHuge", "simulate {D}/m.edrnr --width 8 -q --chip {D}/fcache.yaml", 1,
   "feature_cache.bytes 9200000000000000000: must be between 1 and 268435456 bytes"},
  {"RobEntriesHuge", "simulate {D}/m.edrnr --width 8 -q --chip {D}/rob.yaml", 1,
   "rp_rob.entries 100000000: must be between 1 and 65536"},
  {"ChipStepTiny", "simulate {D}/m.edrnr --width 8 -q --chip {D}/step.yaml", 1,
   "chip config render.step_micro 1e-09: up to 5.54e+10 samples per ray"},
  {"ChipStepTinyChipRender", "chip-render {D}/m.edrnr --orbit 0 --width 8 --config {D}/step.yaml -o {D}/x.png", 1,
   "render.step_micro 1e-09: up to"},
  {"ChipClockInHz", "simulate {D}/m.edrnr --width 8 -q --chip {D}/clock.yaml", 1,
   "simulator.clock_MHz 1000000000000: must be between 1 and 10000 MHz"},
  {"ChipLatencyHuge", "simulate {D}/m.edrnr --width 8 -q --chip {D}/latency.yaml", 1,
   "simulator.timing.tme.latency_cycles 2000000000: over the limit of 1048576"},
  {"ChipBadDramName", "simulate {D}/m.edrnr --width 8 -q --chip {D}/baddram.yaml", 1,
   "baddram.yaml.simulator.memory.dram: no DRAM preset named 'nosuch'"},
  {"ChipDramTckTiny", "simulate {D}/m.edrnr --width 8 -q --chip {D}/tckchip.yaml", 1,
   "timing.tCK_ns = 1e-09 must be between 0.25 and 20 ns"},

  // ---- DRAM presets and traces ----
  {"DramTckTiny", "dram --preset {D}/tck_small.yaml --stream 10", 1, "timing.tCK_ns = 1e-09 must be between 0.25 and 20 ns"},
  {"DramTckHuge", "dram --preset {D}/tck_big.yaml --stream 10", 1, "timing.tCK_ns = 1000000000 must be between 0.25"},
  {"DramPresetMissing", "dram --preset nosuch --stream 10", 1, "--preset 'nosuch': no DRAM preset named 'nosuch'"},
  {"DramPresetFileMissing", "dram --preset {D}/nosuch.yaml --stream 10", 1, "DRAM preset file '{D}/nosuch.yaml' does not exist"},
  {"DramPresetMissingKey", "dram --preset {D}/nokey.yaml --stream 10", 1, "missing key 'timing.tRCD'"},
  {"DramTraceFarFuture", "dram --preset ddr3-1600-4gb-x16-16bit --trace {D}/far.trace", 1,
   "far.trace:2: cycle 9000000000000000000 is over the limit of 10000000000 DRAM clocks"},
  {"DramTraceBadLine", "dram --preset ddr3-1600-4gb-x16-16bit --trace {D}/bad.trace", 1,
   "bad.trace:1: request type 'FETCH' must be READ or WRITE"},
  {"DramTraceOutOfOrder", "dram --preset ddr3-1600-4gb-x16-16bit --trace {D}/order.trace", 1,
   "the trace must be in time order"},
  {"DramTraceBeyondCapacity", "dram --preset ddr3-1600-4gb-x16-16bit --trace {D}/capacity.trace", 1,
   "beyond the DRAM capacity"},
  {"DramTraceIsAFolder", "dram --preset ddr3-1600-4gb-x16-16bit --trace {D}/folder", 1, "is a folder, not a file"},

  // ---- train options ----
  {"TrainOneStep", "train {D}/data -o {D}/t.edrnr --config {SRC}/configs/train/tiny.yaml --iters 1", 1,
   "iters 1 (--iters or the preset) is too few"},
  {"TrainZeroSteps", "train {D}/data -o {D}/t.edrnr --iters 0", 1, "--iters 0: must be at least 1"},
  {"TrainCheckpointIsTheModel", "train {D}/data -o {D}/t.edrnr --checkpoint {D}/t.edrnr --iters 5", 1,
   "-o '{D}/t.edrnr' and --checkpoint '{D}/t.edrnr' name the same file"},
  {"TrainFloatOutputIsTheModel", "train {D}/data -o {D}/t.edrnr --float-output {D}/./t.edrnr --iters 5", 1,
   "-o '{D}/t.edrnr' and --float-output '{D}/./t.edrnr' name the same file"},
  {"TrainFloatOutputIsTheCheckpoint", "train {D}/data -o {D}/t.edrnr --float-output {D}/t.edrnr.ckpt --iters 5", 1,
   "--checkpoint '{D}/t.edrnr.ckpt' and --float-output '{D}/t.edrnr.ckpt' name the same file"},
  {"TrainOutputOverTheResumedCheckpoint", "train {D}/data -o {D}/m.edrnr --resume {D}/m.edrnr", 1,
   "-o '{D}/m.edrnr' is the checkpoint given to --resume"},
  {"TrainOutputFolderMissing", "train {D}/data -o {D}/nodir/t.edrnr --iters 5", 1,
   "-o '{D}/nodir/t.edrnr': cannot write: the folder '{D}/nodir' does not exist"},
  {"TrainFloatFolderMissing", "train {D}/data -o {D}/t.edrnr --float-output {D}/nodir/f.edrnr --iters 5", 1,
   "--float-output '{D}/nodir/f.edrnr': cannot write"},
  {"TrainTooManyThreads", "train {D}/data -o {D}/t.edrnr --threads 10000", 1, "--threads 10000: must be 0"},
  {"TrainResumeDevZero", "train {D}/data -o {D}/t.edrnr --resume /dev/zero", 1,
   "/dev/zero: not an edrnr training checkpoint (bad magic)"},
  {"TrainResumeModel", "train {D}/data -o {D}/t.edrnr --resume {D}/m.edrnr.copy", 1, "not an edrnr training checkpoint"},
  {"TrainResumeWithIters", "train {D}/data -o {D}/t.edrnr --resume {D}/x.ckpt --iters 9", 1,
   "--resume continues with the checkpoint's settings"},
  {"TrainConfigUnknownKey", "train {D}/data -o {D}/t.edrnr --config {D}/train_bad.yaml", 1, "unknown setting 'levles'"},
  {"TrainConfigHugeBatch", "train {D}/data -o {D}/t.edrnr --config {D}/train_batch.yaml", 1,
   "batch_samples 1000000000 must be between 1024 and 16777216"},
  {"TrainConfigHugeGrid", "train {D}/data -o {D}/t.edrnr --config {D}/train_grid.yaml", 1,
   "over the limit max_state_gib = 4 GiB"},
  {"TrainEvalWithoutTestSplit", "train {D}/trainonly -o {D}/t.edrnr --iters 5 --eval-views 2", 1,
   "has no test split (transforms_test.json)"},
  {"TrainDatasetMissing", "train {D}/nodata -o {D}/t.edrnr --iters 5", 1, "split 'train' not found"},
  {"TrainCheckpointBesideADevice", "train {D}/data -o {D}/fifo --iters 5", 1,
   "-o '{D}/fifo' is not a regular file, so the checkpoint cannot go beside it"},

  // ---- outputs ----
  {"RenderOutputIsAFolder", "render {D}/m.edrnr --orbit 0 --width 8 -o {D}/folder", 1,
   "-o '{D}/folder': cannot write: it is a folder"},
  {"RenderOutputFolderMissing", "render {D}/m.edrnr --orbit 0 --width 8 -o {D}/nodir/x.png", 1,
   "the folder '{D}/nodir' does not exist"},
  {"MakeSceneOutputIsAFolder", "make-scene sphere --res 32 -o {D}/folder", 1, "it is a folder"},
  {"MakeSceneLinkIntoMissingFolder", "make-scene sphere --res 32 -o {D}/dangling_dir.edrnr", 1,
   "cannot write: the folder '{D}/nodir' does not exist"},
  {"ChipStatsFolderMissing", "chip-render {D}/m.edrnr --orbit 0 --width 8 -o {D}/c.png --stats {D}/nodir/s.json", 1,
   "--stats '{D}/nodir/s.json': cannot write"},
  {"EvalJsonIsAFolder", "eval {D}/m.edrnr {D}/data --json {D}/folder", 1, "--json '{D}/folder': cannot write"},
  {"EvalSaveDirIsAFile", "eval {D}/m.edrnr {D}/data --save-dir {D}/text.txt", 1,
   "--save-dir '{D}/text.txt': not a folder"},
  {"DramJsonIsAFolder", "dram --preset ddr3-1600-4gb-x16-16bit --stream 10 --json {D}/folder", 1,
   "--json '{D}/folder': cannot write: it is a folder"},
  {"SimulateOutputIsAFile", "simulate {D}/m.edrnr --width 8 -q -o {D}/text.txt", 1, "-o '{D}/text.txt': not a folder"},
  {"SimulateDramTraceIsAFolder", "simulate {D}/m.edrnr --width 8 -q --dram-trace {D}/folder", 1,
   "--dram-trace '{D}/folder': cannot write: it is a folder"},
  {"SimulateDramTraceNoFolder", "simulate {D}/m.edrnr --width 8 -q --dram-trace {D}/nodir/t.trace", 1,
   "the folder '{D}/nodir' does not exist"},
};
// clang-format on

std::string replace_all(std::string s, const std::string& from, const std::string& to) {
  for (size_t at = s.find(from); at != std::string::npos; at = s.find(from, at + to.size()))
    s.replace(at, from.size(), to);
  return s;
}

class BadInputBattery : public ::testing::TestWithParam<BadInput> {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("edrnr_bad_input_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "folder");
    make_inputs();
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  static fs::path binary() { return fs::path(EDRNR_BINARY_DIR) / "edrnr"; }
  static std::string expand(const std::string& s) {
    return replace_all(replace_all(s, "{D}", dir_.string()), "{SRC}", EDRNR_SOURCE_DIR);
  }
  static void write(const std::string& name, const std::string& text) { write_file_atomic(dir_ / name, text); }

  // A dataset folder with one split.
  static void write_split(const std::string& folder, const std::string& split, const nlohmann::json& doc) {
    fs::create_directories(dir_ / folder);
    write_file_atomic(dir_ / folder / ("transforms_" + split + ".json"), doc.dump(1));
  }
  static nlohmann::json frames_json(int n, const std::string& file = "./test/r_0") {
    nlohmann::json frames = nlohmann::json::array();
    for (int i = 0; i < n; ++i)
      frames.push_back(
          {{"file_path", file}, {"transform_matrix", {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 4}, {0, 0, 0, 1}}}});
    return frames;
  }

  static void make_inputs() {
    // A model, and a copy of it under names other cases use.
    ProceduralOptions po;
    po.micro_res = 32;
    po.feature_channels = 4;
    const SceneModel m = make_procedural_model("sphere", procedural_shapes("sphere"), po);
    std::vector<uint8_t> bytes = serialize_model(m);
    write_file_atomic(dir_ / "m.edrnr", bytes);
    write_file_atomic(dir_ / "m.edrnr.copy", bytes);
    write_file_atomic(dir_ / "cut.edrnr", std::vector<uint8_t>(bytes.begin(), bytes.begin() + long(bytes.size() / 2)));
    std::vector<uint8_t> flipped = bytes;
    flipped[bytes.size() - 7] ^= 0x10;
    write_file_atomic(dir_ / "flipped.edrnr", flipped);
    std::vector<uint8_t> huge = bytes;
    for (int i = 0; i < 8; ++i) huge[16 + size_t(i)] = uint8_t((uint64_t{1} << 40) >> (8 * i));
    write_file_atomic(dir_ / "huge.edrnr", huge);
    write("text.txt", "this is not a model\n");
    // Metadata nested 100 000 levels: written as a same-length placeholder
    // (serialize_model refuses the deep text), replaced, and the CRC redone.
    const std::string deep = R"({"a":)" + std::string(100000, '[') + std::string(100000, ']') + "}";
    SceneModel dm = m;
    dm.metadata_json = R"({"a":")" + std::string(deep.size() - 8, 'x') + R"("})";
    std::vector<uint8_t> db = serialize_model(dm);
    const std::string placeholder = dm.metadata_json;
    auto at = std::search(db.begin(), db.end(), placeholder.begin(), placeholder.end());
    ASSERT_NE(at, db.end());
    std::copy(deep.begin(), deep.end(), at);
    const uint32_t crc = uint32_t(crc32(crc32(0L, Z_NULL, 0), db.data() + 32, uInt(db.size() - 32)));
    for (int i = 0; i < 4; ++i) db[24 + size_t(i)] = uint8_t(crc >> (8 * i));
    write_file_atomic(dir_ / "deep.edrnr", db);

    // Datasets: 16 x 16 (test and train splits), 8 x 8 (below SSIM's window),
    // and broken ones.
    train::SyntheticViews v;
    v.train_views = 4;
    v.test_views = 2;
    v.width = v.height = 16;
    train::write_synthetic_dataset(m, dir_ / "data", v);
    v.width = v.height = 8;
    train::write_synthetic_dataset(m, dir_ / "data8", v);
    v.width = v.height = 16;
    train::write_synthetic_dataset(m, dir_ / "trainonly", v);
    fs::remove(dir_ / "trainonly" / "transforms_test.json");
    fs::create_directories(dir_ / "badjson");
    write("badjson/transforms_test.json", R"({"camera_angle_x": 0.7, "frames": [)");
    write_split("noframes", "test", {{"camera_angle_x", 0.7}, {"frames", nlohmann::json::array()}});
    write_split("hugesize", "test", {{"fl_x", 100}, {"w", 30000}, {"h", 30000}, {"frames", frames_json(1)}});
    write_split("manypixels", "test", {{"fl_x", 100}, {"w", 8192}, {"h", 8192}, {"frames", frames_json(1)}});
    write_split("bigsplit", "test", {{"fl_x", 100}, {"w", 4096}, {"h", 4096}, {"frames", frames_json(20)}});
    // A PNG whose header claims 30000 x 30000 (its data is one pixel).
    const std::string png = read_file_text(dir_ / "data" / "test" / "r_0.png");
    std::string ihdr =
        std::string("\0\0\0\x0dIHDR", 8) + std::string("\0\0\x75\x30\0\0\x75\x30", 8) + png.substr(24, 5);
    const uint32_t ihdr_crc =
        uint32_t(crc32(crc32(0L, Z_NULL, 0), reinterpret_cast<const Bytef*>(ihdr.data() + 4), 17));
    for (int i = 3; i >= 0; --i) ihdr += char(ihdr_crc >> (8 * i));
    write_split("hugepng", "test", {{"camera_angle_x", 0.7}, {"frames", frames_json(1)}});
    fs::create_directories(dir_ / "hugepng" / "test");
    write("hugepng/test/r_0.png", png.substr(0, 8) + ihdr + png.substr(33));
    write_split("corruptpng", "test", {{"camera_angle_x", 0.7}, {"w", 16}, {"h", 16}, {"frames", frames_json(1)}});
    fs::create_directories(dir_ / "corruptpng" / "test");
    write("corruptpng/test/r_0.png", "not a png at all");
    write_split("missingpng", "test", {{"camera_angle_x", 0.7}, {"w", 16}, {"h", 16}, {"frames", frames_json(1)}});
    write_split("wrongsize", "test", {{"camera_angle_x", 0.7}, {"w", 16}, {"h", 16}, {"frames", frames_json(1)}});
    fs::create_directories(dir_ / "wrongsize" / "test");
    write_png(dir_ / "wrongsize" / "test" / "r_0.png", Image(12, 12, 4, 0.5f));

    // Chip presets.
    write("empty.yaml", "");
    write("simnull.yaml", "simulator:\n");
    write("notyaml.yaml", "simulator: [1, 2\n");
    write("unknown.yaml", "warp: 9\n");
    write("rpbuf.yaml", "rp_buffer_capacity: 1000000000\n");
    write("fcache.yaml", "feature_cache:\n  bytes: 9200000000000000000\n");
    write("rob.yaml", "rp_rob:\n  entries: 100000000\n");
    write("step.yaml", "render:\n  step_micro: 1e-9\n");
    write("clock.yaml", "simulator:\n  clock_MHz: 1e12\n");
    write("latency.yaml", "simulator:\n  timing:\n    tme:\n      latency_cycles: 2000000000\n");
    write("baddram.yaml", "simulator:\n  memory:\n    dram: nosuch\n");
    // DRAM presets: the shipped one with one value changed.
    const std::string preset =
        read_file_text(fs::path(EDRNR_SOURCE_DIR) / "configs" / "dram" / "ddr3-1600-4gb-x16-16bit.yaml");
    auto changed = [&](const std::string& from, const std::string& to) {
      std::string s = preset;
      const size_t p = s.find(from);
      EXPECT_NE(p, std::string::npos) << from;
      return s.replace(p, from.size(), to);
    };
    write("tck_small.yaml", changed("tCK_ns: 1.25", "tCK_ns: 1e-9"));
    write("tck_big.yaml", changed("tCK_ns: 1.25", "tCK_ns: 1e9"));
    write("nokey.yaml", changed("tRCD:", "tRCDX:"));
    write("tckchip.yaml", "simulator:\n  memory:\n    dram: " + (dir_ / "tck_small.yaml").string() + "\n");
    write("far.trace", "0x0 READ 0\n0x40 READ 9000000000000000000\n");
    write("bad.trace", "0x0 FETCH 0\n");
    write("order.trace", "0x0 READ 10\n0x40 READ 9\n");
    write("capacity.trace", "0xffffffffffff READ 0\n");
    // Train presets.
    write("train_bad.yaml", "levles: [8]\n");
    write("train_batch.yaml", "batch_samples: 1000000000\n");
    write("train_grid.yaml", "micro_res: 1024\nlevels: [128, 256, 512, 1024]\n");
    write("x.ckpt", "not used: --iters is refused first\n");
    // Outputs: a FIFO and a link whose target's folder is missing.
    ASSERT_EQ(::mkfifo((dir_ / "fifo").c_str(), 0600), 0);
    fs::create_symlink(dir_ / "nodir" / "m.edrnr", dir_ / "dangling_dir.edrnr");
  }

  static fs::path dir_;
};

fs::path BadInputBattery::dir_;

TEST_P(BadInputBattery, RefusedWithAClearMessage) {
  const BadInput& c = GetParam();
  const fs::path out = dir_ / (std::string(c.name) + ".out"), err = dir_ / (std::string(c.name) + ".err");
  const std::string cmd =
      binary().string() + " " + expand(c.args) + " >" + out.string() + " 2>" + err.string() + " </dev/null";
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status)) << cmd << ": killed by signal " << (WIFSIGNALED(status) ? WTERMSIG(status) : -1);
  const std::string stderr_text = read_file_text(err);
  EXPECT_EQ(WEXITSTATUS(status), c.exit_code) << cmd << "\n" << stderr_text;
  EXPECT_NE(stderr_text.find(expand(c.fragment)), std::string::npos)
      << cmd << "\nexpected: " << expand(c.fragment) << "\nstderr:   " << stderr_text;
  EXPECT_EQ(stderr_text.find("internal error"), std::string::npos) << stderr_text;
}

INSTANTIATE_TEST_SUITE_P(Battery, BadInputBattery, ::testing::ValuesIn(kCases),
                         [](const ::testing::TestParamInfo<BadInput>& info) { return std::string(info.param.name); });

}  // namespace
}  // namespace edrnr
