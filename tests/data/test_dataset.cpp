#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <initializer_list>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>

#include "core/error.h"
#include "core/file_io.h"
#include "core/image.h"
#include "data/dataset.h"

namespace edrnr {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// Runs f, which must throw edrnr::Error whose message contains every word.
void expect_error(const std::function<void()>& f, std::initializer_list<const char*> words) {
  try {
    f();
  } catch (const Error& e) {
    std::string msg = e.what();
    for (const char* w : words) EXPECT_NE(msg.find(w), std::string::npos) << "missing '" << w << "' in: " << msg;
    return;
  }
  ADD_FAILURE() << "no edrnr::Error thrown";
}

json matrix_json(std::initializer_list<std::initializer_list<double>> rows) {
  json m = json::array();
  for (const auto& r : rows) m.push_back(json(std::vector<double>(r)));
  return m;
}

json identity_matrix() { return matrix_json({{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}}); }

json frame_json(const std::string& file_path) {
  json f = json::object();
  f["file_path"] = file_path;
  f["transform_matrix"] = identity_matrix();
  return f;
}

// A transforms JSON with explicit intrinsics, so that parsing needs no image.
json ngp_json(int frames) {
  json doc = json::object();
  doc["fl_x"] = 100.0;
  doc["w"] = 8;
  doc["h"] = 4;
  doc["frames"] = json::array();
  for (int i = 0; i < frames; ++i) doc["frames"].push_back(frame_json(fmt::format("./train/r_{}", i)));
  return doc;
}

std::vector<Frame> parse(const json& doc, int downscale = 1) {
  return parse_transforms(doc.dump(), "/nonexistent", "scene.json", downscale);
}

class DatasetFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ =
        fs::temp_directory_path() / fmt::format("edrnr_test_{}_{}_{}", info->test_suite_name(), info->name(), getpid());
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "train");
  }
  void TearDown() override { fs::remove_all(dir_); }

  void write_json(const std::string& name, const json& doc) { write_file_atomic(dir_ / name, doc.dump(2)); }

  fs::path dir_;
};

// 8-bit channel value k as the PNG reader returns it.
double v8(int k) { return k / 255.0; }

// A 4x2 RGBA test image: red 0, 51, 102, 153 along x, green 0 / 255 by row,
// blue 102, alpha 0, 51, 255, 204 along x.
const int kRed[4] = {0, 51, 102, 153};
const int kAlpha[4] = {0, 51, 255, 204};
Image rgba_test_image() {
  Image img(4, 2, 4);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 4; ++x) {
      float* p = img.at(x, y);
      p[0] = float(v8(kRed[x]));
      p[1] = float(y);
      p[2] = float(v8(102));
      p[3] = float(v8(kAlpha[x]));
    }
  return img;
}

// rgb * a + bg * (1 - a) for the test image, by hand.
double composited(int x, int y, int c, const float bg[3]) {
  double rgb[3] = {v8(kRed[x]), double(y), v8(102)};
  double a = v8(kAlpha[x]);
  return rgb[c] * a + bg[c] * (1 - a);
}

// ---- the shipped Blender scene ---------------------------------------------

fs::path lego_dir() { return fs::path(EDRNR_SOURCE_DIR "/../shared/data") / "nerf_synthetic" / "lego"; }

TEST(LegoDataset, TestSplitCameras) {
  if (!fs::exists(lego_dir() / "transforms_test.json")) GTEST_SKIP() << "no data at " << lego_dir();
  DatasetOptions opt;
  opt.split = "test";
  opt.load_images = false;
  Dataset ds = load_dataset(lego_dir(), opt);
  EXPECT_EQ(ds.split, "test");
  ASSERT_EQ(ds.frames.size(), 25u);
  // 0.5 * 800 / tan(0.5 * 0.6911112070083618), computed separately.
  const double focal = 1111.1110311937682;
  for (const Frame& f : ds.frames) {
    EXPECT_EQ(f.camera.width, 800);
    EXPECT_EQ(f.camera.height, 800);
    EXPECT_NEAR(f.camera.fx, focal, 1e-9);
    EXPECT_NEAR(f.camera.fy, focal, 1e-9);
    EXPECT_EQ(f.camera.cx, 400);
    EXPECT_EQ(f.camera.cy, 400);
    EXPECT_TRUE(fs::is_regular_file(f.image_path)) << f.image_path;
    EXPECT_TRUE(f.image.data.empty());
    // Every Blender camera looks at the world origin: the centre ray passes it.
    Ray r = f.camera.ray_at(400, 400);
    EXPECT_LT(length(cross(r.origin, r.dir)), 1e-5);
    EXPECT_LT(dot(r.origin, r.dir), 0);  // the origin lies ahead, not behind
  }
  // The first two frames as written in the JSON: ./test/r_0 and ./test/r_8.
  EXPECT_EQ(ds.frames[0].image_path.filename(), "r_0.png");
  EXPECT_EQ(ds.frames[0].image_path.parent_path().filename(), "test");
  EXPECT_EQ(ds.frames[1].image_path.filename(), "r_8.png");
  EXPECT_EQ(ds.frames[0].camera.c2w[0], -0.9999999403953552);
  EXPECT_EQ(ds.frames[0].camera.c2w[7], 2.737260103225708);
  EXPECT_EQ(ds.frames[0].camera.c2w[11], 2.959291696548462);
  EXPECT_EQ(ds.frames[0].camera.c2w[15], 1.0);
}

TEST(LegoDataset, TestSplitImagesDownscaledOnBlack) {
  if (!fs::exists(lego_dir() / "transforms_test.json")) GTEST_SKIP() << "no data at " << lego_dir();
  DatasetOptions opt;
  opt.split = "test";
  opt.downscale = 8;
  opt.background[0] = opt.background[1] = opt.background[2] = 0.f;
  Dataset ds = load_dataset(lego_dir(), opt);
  ASSERT_EQ(ds.frames.size(), 25u);
  for (const Frame& f : ds.frames) {
    ASSERT_EQ(f.image.width, 100);
    ASSERT_EQ(f.image.height, 100);
    ASSERT_EQ(f.image.channels, 3);
    EXPECT_NEAR(f.camera.fx, 1111.1110311937682 / 8, 1e-9);
    EXPECT_EQ(f.camera.cx, 50);
    // The corners are empty background (alpha 0): exactly black.
    for (int c = 0; c < 3; ++c) EXPECT_EQ(f.image.at(0, 0)[c], 0.f);
    // The object fills the middle of every view.
    float centre_sum = 0;
    for (int y = 40; y < 60; ++y)
      for (int x = 40; x < 60; ++x) centre_sum += f.image.at(x, y)[0];
    EXPECT_GT(centre_sum, 1.f);
    for (float v : f.image.data) ASSERT_TRUE(v >= 0.f && v <= 1.f);
  }
}

// ---- intrinsics ---------------------------------------------------------------

TEST(ParseTransforms, CameraAngleWithExplicitSize) {
  json doc = json::object();
  doc["camera_angle_x"] = std::numbers::pi / 2;  // f = (w / 2) / tan(45 deg) = w / 2
  doc["w"] = 8;
  doc["h"] = 6;
  doc["frames"] = json::array({frame_json("a.png")});
  auto frames = parse(doc);
  ASSERT_EQ(frames.size(), 1u);
  const Camera& c = frames[0].camera;
  EXPECT_EQ(c.width, 8);
  EXPECT_EQ(c.height, 6);
  EXPECT_NEAR(c.fx, 4.0, 1e-12);
  EXPECT_NEAR(c.fy, 4.0, 1e-12);
  EXPECT_EQ(c.cx, 4);
  EXPECT_EQ(c.cy, 3);
  EXPECT_EQ(frames[0].image_path, fs::path("/nonexistent/a.png"));
}

TEST(ParseTransforms, InstantNgpKeys) {
  json doc = json::object();
  doc["fl_x"] = 700.5;
  doc["fl_y"] = 650.25;
  doc["cx"] = 310.0;
  doc["cy"] = 250.5;
  doc["w"] = 640.0;  // written as a float, as some tools do
  doc["h"] = 480;
  doc["camera_angle_x"] = 1.0;  // fl_x takes precedence
  doc["k1"] = 0.0;              // zero distortion is accepted
  doc["aabb_scale"] = 16;       // unknown keys are ignored
  doc["frames"] = json::array({frame_json("./images/0001.jpg")});
  auto frames = parse(doc);
  const Camera& c = frames[0].camera;
  EXPECT_EQ(c.width, 640);
  EXPECT_EQ(c.height, 480);
  EXPECT_EQ(c.fx, 700.5);
  EXPECT_EQ(c.fy, 650.25);
  EXPECT_EQ(c.cx, 310);
  EXPECT_EQ(c.cy, 250.5);
  // An extension in file_path is kept; "./" is dropped.
  EXPECT_EQ(frames[0].image_path, fs::path("/nonexistent/images/0001.jpg"));
}

TEST(ParseTransforms, FocalYDefaultsToFocalXAndCameraAngleY) {
  json doc = ngp_json(1);
  auto frames = parse(doc);
  EXPECT_EQ(frames[0].camera.fy, 100);
  EXPECT_EQ(frames[0].camera.cx, 4);
  EXPECT_EQ(frames[0].camera.cy, 2);

  doc.erase("fl_x");
  doc["camera_angle_x"] = std::numbers::pi / 2;
  doc["camera_angle_y"] = 2 * std::atan(0.25);  // f = (h / 2) / 0.25 = 8
  frames = parse(doc);
  EXPECT_NEAR(frames[0].camera.fx, 4, 1e-12);
  EXPECT_NEAR(frames[0].camera.fy, 8, 1e-12);
}

TEST(ParseTransforms, PerFrameValuesOverrideTopLevel) {
  json doc = ngp_json(2);
  doc["frames"][1]["fl_x"] = 50.0;
  doc["frames"][1]["cy"] = 1.25;
  auto frames = parse(doc);
  EXPECT_EQ(frames[0].camera.fx, 100);
  EXPECT_EQ(frames[0].camera.cy, 2);
  EXPECT_EQ(frames[1].camera.fx, 50);
  EXPECT_EQ(frames[1].camera.fy, 50);
  EXPECT_EQ(frames[1].camera.cy, 1.25);
}

TEST(ParseTransforms, MatrixIsRowMajorCameraToWorld) {
  json doc = ngp_json(1);
  doc["frames"][0]["transform_matrix"] = matrix_json({{0, 0, 1, 1}, {0, 1, 0, 2}, {-1, 0, 0, 3}, {0, 0, 0, 1}});
  auto frames = parse(doc);
  const Camera& c = frames[0].camera;
  EXPECT_EQ(c.c2w[2], 1);
  EXPECT_EQ(c.c2w[8], -1);
  Ray r = c.ray_at(c.cx, c.cy);
  EXPECT_EQ(r.origin, (Vec3d{1, 2, 3}));
  EXPECT_NEAR(r.dir.x, -1, 1e-15);  // camera -Z is world -X
}

TEST(ParseTransforms, DownscaleDividesIntrinsics) {
  json doc = ngp_json(2);
  doc["cx"] = 3.0;
  auto frames = parse(doc, 2);
  const Camera& c = frames[1].camera;
  EXPECT_EQ(c.width, 4);
  EXPECT_EQ(c.height, 2);
  EXPECT_EQ(c.fx, 50);
  EXPECT_EQ(c.fy, 50);
  EXPECT_EQ(c.cx, 1.5);
  EXPECT_EQ(c.cy, 1);
}

// ---- malformed JSON -------------------------------------------------------------

TEST(ParseTransforms, MalformedJsonNamesSourceAndPosition) {
  expect_error([] { parse_transforms("{\"frames\": [\n  {\"file_path\": }\n]}", ".", "scene.json"); },
               {"scene.json", "malformed JSON", "line 2", "column"});
  expect_error([] { parse_transforms("", ".", "scene.json"); }, {"scene.json", "malformed JSON"});
  // A number too large for a double (the only way to write a non-finite one).
  expect_error([] { parse_transforms("{\"fl_x\": 1e999, \"frames\": []}", ".", "scene.json"); },
               {"scene.json", "1e999"});
}

TEST(ParseTransforms, StructureErrors) {
  expect_error([] { parse_transforms("[1, 2]", ".", "scene.json"); }, {"scene.json", "object"});
  json doc = ngp_json(1);
  doc.erase("frames");
  expect_error([&] { parse(doc); }, {"scene.json", "missing key 'frames'"});
  doc["frames"] = json::object();
  expect_error([&] { parse(doc); }, {"'frames'", "array"});
  doc["frames"] = json::array();
  expect_error([&] { parse(doc); }, {"'frames'", "empty"});
  doc["frames"] = json::array({1});
  expect_error([&] { parse(doc); }, {"frames[0]", "object"});
}

TEST(ParseTransforms, FilePathErrors) {
  json doc = ngp_json(2);
  doc["frames"][1].erase("file_path");
  expect_error([&] { parse(doc); }, {"scene.json", "frames[1].file_path"});
  doc["frames"][1]["file_path"] = 3;
  expect_error([&] { parse(doc); }, {"frames[1].file_path", "string"});
  doc["frames"][1]["file_path"] = "";
  expect_error([&] { parse(doc); }, {"frames[1].file_path", "non-empty"});
}

TEST(ParseTransforms, MatrixErrors) {
  json doc = ngp_json(2);
  doc["frames"][1].erase("transform_matrix");
  expect_error([&] { parse(doc); }, {"scene.json", "frames[1].transform_matrix"});
  doc["frames"][1]["transform_matrix"] = matrix_json({{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}});
  expect_error([&] { parse(doc); }, {"frames[1].transform_matrix", "4x4"});
  doc["frames"][1]["transform_matrix"] = matrix_json({{1, 0, 0, 0}, {0, 1, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}});
  expect_error([&] { parse(doc); }, {"frames[1].transform_matrix", "4x4", "row 1"});
  doc["frames"][1]["transform_matrix"] = identity_matrix();
  doc["frames"][1]["transform_matrix"][2][3] = "3";
  expect_error([&] { parse(doc); }, {"frames[1].transform_matrix[2][3]", "number"});
  doc["frames"][1]["transform_matrix"] = identity_matrix();
  doc["frames"][1]["transform_matrix"][3][1] = 0.5;
  expect_error([&] { parse(doc); }, {"frames[1].transform_matrix", "[0, 0, 0, 1]"});
}

TEST(ParseTransforms, IntrinsicsErrors) {
  json doc = ngp_json(1);
  doc.erase("fl_x");
  expect_error([&] { parse(doc); }, {"scene.json", "camera_angle_x", "fl_x"});
  doc["camera_angle_x"] = 0.0;
  expect_error([&] { parse(doc); }, {"camera_angle_x", "(0, pi)"});
  doc["camera_angle_x"] = 3.5;
  expect_error([&] { parse(doc); }, {"camera_angle_x", "(0, pi)"});
  doc["camera_angle_x"] = "wide";
  expect_error([&] { parse(doc); }, {"camera_angle_x", "number"});
  doc.erase("camera_angle_x");
  doc["fl_x"] = -5.0;
  expect_error([&] { parse(doc); }, {"focal", "positive"});
  doc["fl_x"] = 100.0;
  doc["w"] = 8.5;
  expect_error([&] { parse(doc); }, {"'w'", "integer"});
  doc["w"] = 0;
  expect_error([&] { parse(doc); }, {"'w'", "integer"});
  doc["w"] = 8;
  doc["frames"][0]["k1"] = 0.1;
  expect_error([&] { parse(doc); }, {"frames[0]", "distortion", "k1"});
}

TEST(ParseTransforms, FramesOfDifferentSizes) {
  json doc = ngp_json(3);
  doc["frames"][2]["w"] = 16;
  expect_error([&] { parse(doc); }, {"scene.json", "frames[2]", "16x4", "same size"});
}

TEST(ParseTransforms, DownscaleErrors) {
  json doc = ngp_json(1);  // 8x4
  expect_error([&] { parse(doc, 3); }, {"scene.json", "downscale 3", "does not divide", "8x4"});
  expect_error([&] { parse(doc, 8); }, {"does not divide"});
  expect_error([&] { parse(doc, 0); }, {"downscale", "positive integer"});
}

// Image sizes have a stated limit, checked from the JSON before any image is
// read (issue #16).
TEST(ParseTransforms, ImageSizeLimits) {
  json doc = ngp_json(1);
  doc["w"] = 30000;
  expect_error([&] { parse(doc); }, {"'w'", "1 to 16384"});
  doc["w"] = 8192;
  doc["h"] = 8192;
  expect_error([&] { parse(doc); }, {"scene.json", "frames[0]", "67108864 pixels, over the limit of 16777216"});
  doc["w"] = 4096;
  doc["h"] = 4096;
  EXPECT_NO_THROW(parse(doc));
}

// ---- datasets on disk -----------------------------------------------------------

// All the images of a split are counted before any is decoded.
TEST_F(DatasetFiles, SplitPixelLimit) {
  json doc = ngp_json(20);
  doc["w"] = 4096;
  doc["h"] = 4096;
  write_json("transforms_train.json", doc);
  DatasetOptions o;
  expect_error([&] { load_dataset(dir_, o); },
               {"20 images of 16777216 pixels", "335544320 pixels in all, over the limit of 268435456"});
  o.load_images = false;
  EXPECT_EQ(load_dataset(dir_, o).frames.size(), 20u);  // cameras only: nothing decoded
}

TEST_F(DatasetFiles, LoadsAndCompositesRgbaOnBackground) {
  write_png(dir_ / "train" / "r_0.png", rgba_test_image());
  json doc = json::object();
  doc["camera_angle_x"] = std::numbers::pi / 2;
  doc["frames"] = json::array({frame_json("./train/r_0")});
  write_json("transforms_train.json", doc);

  DatasetOptions opt;
  opt.background[0] = 0.5f;
  opt.background[1] = 0.25f;
  opt.background[2] = 1.f;
  Dataset ds = load_dataset(dir_, opt);
  ASSERT_EQ(ds.frames.size(), 1u);
  const Frame& f = ds.frames[0];
  EXPECT_EQ(f.image_path, dir_ / "train" / "r_0.png");
  // Size from the image (no w/h in the JSON): 4x2, f = 4 / 2 / tan(45 deg) = 2.
  EXPECT_EQ(f.camera.width, 4);
  EXPECT_EQ(f.camera.height, 2);
  EXPECT_NEAR(f.camera.fx, 2, 1e-12);
  EXPECT_NEAR(f.camera.fy, 2, 1e-12);
  EXPECT_EQ(f.camera.cx, 2);
  EXPECT_EQ(f.camera.cy, 1);
  ASSERT_EQ(f.image.width, 4);
  ASSERT_EQ(f.image.height, 2);
  ASSERT_EQ(f.image.channels, 3);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 4; ++x)
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(f.image.at(x, y)[c], composited(x, y, c, opt.background), 1e-6) << x << "," << y << "," << c;
  // Alpha 0 shows exactly the background; alpha 1 exactly the colour.
  EXPECT_EQ(f.image.at(0, 1)[0], 0.5f);
  EXPECT_EQ(f.image.at(0, 1)[2], 1.f);
  EXPECT_EQ(f.image.at(2, 1)[1], 1.f);
  EXPECT_EQ(f.image.at(2, 0)[0], float(v8(102)));
}

TEST_F(DatasetFiles, DefaultBackgroundIsWhiteAndCamerasOnlySkipsImages) {
  write_png(dir_ / "train" / "r_0.png", rgba_test_image());
  json doc = ngp_json(1);
  doc["w"] = 4;
  doc["h"] = 2;
  doc["frames"][0]["file_path"] = "train/r_0.png";
  write_json("transforms_train.json", doc);
  Dataset ds = load_dataset(dir_, {});
  EXPECT_EQ(ds.frames[0].image.at(0, 0)[0], 1.f);  // alpha 0 on white
  EXPECT_EQ(ds.frames[0].image.at(0, 0)[1], 1.f);

  DatasetOptions cameras_only;
  cameras_only.load_images = false;
  Dataset cams = load_dataset(dir_, cameras_only);
  EXPECT_TRUE(cams.frames[0].image.data.empty());
  EXPECT_EQ(cams.frames[0].camera.width, 4);
}

TEST_F(DatasetFiles, RgbImagesAreUsedAsTheyAre) {
  Image rgb(2, 2, 3);
  for (size_t i = 0; i < rgb.data.size(); ++i) rgb.data[i] = float(v8(int(i) * 20));
  write_png(dir_ / "train" / "r_0.png", rgb);
  json doc = json::object();
  doc["camera_angle_x"] = 1.0;
  doc["frames"] = json::array({frame_json("train/r_0")});
  write_json("transforms_train.json", doc);
  DatasetOptions opt;
  opt.background[0] = opt.background[1] = opt.background[2] = 0.f;
  Dataset ds = load_dataset(dir_, opt);
  ASSERT_EQ(ds.frames[0].image.data.size(), rgb.data.size());
  for (size_t i = 0; i < rgb.data.size(); ++i) EXPECT_EQ(ds.frames[0].image.data[i], float(v8(int(i) * 20)));
}

TEST_F(DatasetFiles, DownscaleAveragesCompositedPixels) {
  write_png(dir_ / "train" / "r_0.png", rgba_test_image());
  json doc = json::object();
  doc["camera_angle_x"] = std::numbers::pi / 2;
  doc["frames"] = json::array({frame_json("./train/r_0.png")});
  write_json("transforms_train.json", doc);
  DatasetOptions opt;
  opt.downscale = 2;
  Dataset ds = load_dataset(dir_, opt);
  const Frame& f = ds.frames[0];
  EXPECT_EQ(f.camera.width, 2);
  EXPECT_EQ(f.camera.height, 1);
  EXPECT_NEAR(f.camera.fx, 1, 1e-12);
  EXPECT_EQ(f.camera.cx, 1);
  EXPECT_EQ(f.camera.cy, 0.5);
  ASSERT_EQ(f.image.width, 2);
  ASSERT_EQ(f.image.height, 1);
  for (int bx = 0; bx < 2; ++bx)
    for (int c = 0; c < 3; ++c) {
      double mean = 0;
      for (int y = 0; y < 2; ++y)
        for (int x = 2 * bx; x < 2 * bx + 2; ++x) mean += composited(x, y, c, opt.background) / 4;
      EXPECT_NEAR(f.image.at(bx, 0)[c], mean, 1e-6);
    }
}

TEST_F(DatasetFiles, FramesKeepJsonOrderWhenLoadedInParallel) {
  const int n = 9;
  json doc = json::object();
  doc["camera_angle_x"] = 1.0;
  doc["frames"] = json::array();
  for (int i = 0; i < n; ++i) {
    int k = 10 * i + 3;
    write_png(dir_ / "train" / fmt::format("v{}.png", k), Image(2, 2, 3, float(v8(k))));
    json f = frame_json(fmt::format("train/v{}", k));
    f["transform_matrix"][0][3] = double(i);
    doc["frames"].push_back(f);
  }
  write_json("transforms_train.json", doc);
  Dataset ds = load_dataset(dir_, {});
  ASSERT_EQ(ds.frames.size(), size_t(n));
  for (int i = 0; i < n; ++i) {
    EXPECT_EQ(ds.frames[i].camera.c2w[3], double(i));
    EXPECT_EQ(ds.frames[i].image.data[0], float(v8(10 * i + 3)));
    EXPECT_EQ(ds.frames[i].image_path.filename(), fmt::format("v{}.png", 10 * i + 3));
  }
}

TEST_F(DatasetFiles, AbsoluteFilePath) {
  write_png(dir_ / "elsewhere.png", Image(2, 2, 3, 0.f));
  json doc = ngp_json(1);
  doc["w"] = 2;
  doc["h"] = 2;
  doc["frames"][0]["file_path"] = (dir_ / "elsewhere").string();
  write_json("transforms_val.json", doc);
  DatasetOptions opt;
  opt.split = "val";
  Dataset ds = load_dataset(dir_, opt);
  EXPECT_EQ(ds.split, "val");
  EXPECT_EQ(ds.frames[0].image_path, dir_ / "elsewhere.png");
}

TEST_F(DatasetFiles, MissingJson) {
  DatasetOptions opt;
  opt.split = "test";
  expect_error([&] { load_dataset(dir_, opt); }, {"transforms_test.json", "not found", "'test'"});
}

TEST_F(DatasetFiles, MalformedJsonOnDiskNamesTheFile) {
  write_file_atomic(dir_ / "transforms_train.json", std::string("{\"frames\": [}"));
  expect_error([&] { load_dataset(dir_, {}); }, {"transforms_train.json", "malformed JSON", "line 1"});
}

TEST_F(DatasetFiles, MissingImage) {
  write_png(dir_ / "train" / "r_0.png", Image(8, 4, 3, 0.f));
  json doc = ngp_json(2);  // 8x4, images train/r_0 and train/r_1
  write_json("transforms_train.json", doc);
  expect_error([&] { load_dataset(dir_, {}); }, {"transforms_train.json", "frames[1]", "not found", "r_1.png"});
  // Without w/h the first image's size is needed even for cameras only.
  doc.erase("w");
  doc["frames"][0]["file_path"] = "train/r_9";
  write_json("transforms_train.json", doc);
  DatasetOptions cameras_only;
  cameras_only.load_images = false;
  expect_error([&] { load_dataset(dir_, cameras_only); }, {"r_9.png", "not found", "'w'"});
}

TEST_F(DatasetFiles, ImageSizeMismatch) {
  write_png(dir_ / "train" / "r_0.png", Image(4, 4, 3, 0.f));
  write_png(dir_ / "train" / "r_1.png", Image(4, 2, 3, 0.f));
  json doc = json::object();
  doc["camera_angle_x"] = 1.0;
  doc["frames"] = json::array({frame_json("train/r_0"), frame_json("train/r_1")});
  write_json("transforms_train.json", doc);
  expect_error([&] { load_dataset(dir_, {}); }, {"r_1.png", "4x2", "frames[1]", "4x4", "same size"});
  // The JSON's w/h disagree with the image.
  doc["w"] = 8;
  doc["frames"][1]["file_path"] = "train/r_0";
  write_json("transforms_train.json", doc);
  expect_error([&] { load_dataset(dir_, {}); }, {"r_0.png", "is 4x4", "expects 8x4"});
}

TEST_F(DatasetFiles, DownscaleNotDividingImage) {
  write_png(dir_ / "train" / "r_0.png", Image(6, 4, 3, 0.f));
  json doc = json::object();
  doc["camera_angle_x"] = 1.0;
  doc["frames"] = json::array({frame_json("train/r_0")});
  write_json("transforms_train.json", doc);
  DatasetOptions opt;
  opt.downscale = 4;
  expect_error([&] { load_dataset(dir_, opt); }, {"transforms_train.json", "downscale 4", "6x4"});
}

TEST_F(DatasetFiles, CorruptImage) {
  write_file_atomic(dir_ / "train" / "r_0.png", std::string("not a png at all, just text"));
  json doc = ngp_json(1);
  write_json("transforms_train.json", doc);
  expect_error([&] { load_dataset(dir_, {}); }, {"r_0.png", "PNG"});
  doc.erase("w");
  write_json("transforms_train.json", doc);
  expect_error([&] { load_dataset(dir_, {}); }, {"r_0.png", "PNG"});
}

}  // namespace
}  // namespace edrnr
