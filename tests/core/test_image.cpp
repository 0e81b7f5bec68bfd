#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>
#include <zlib.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/file_io.h"
#include "core/image.h"

namespace edrnr {
namespace {

namespace fs = std::filesystem;

class ImageFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ =
        fs::temp_directory_path() / fmt::format("edrnr_test_{}_{}_{}", info->test_suite_name(), info->name(), getpid());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

// A PNG written by hand from the format's definition (signature, IHDR, one
// zlib-compressed IDAT of filter-0 rows, IEND), independent of the PNG library.
void put_be32(std::string& out, uint32_t v) {
  for (int shift = 24; shift >= 0; shift -= 8) out.push_back(char((v >> shift) & 0xff));
}

void put_chunk(std::string& out, const char* type, const std::string& data) {
  put_be32(out, uint32_t(data.size()));
  std::string body = std::string(type, 4) + data;
  out += body;
  put_be32(out, uint32_t(crc32(0, reinterpret_cast<const Bytef*>(body.data()), uInt(body.size()))));
}

// `samples` holds width * height * channels values, row by row.
std::string make_png(int width, int height, int bit_depth, int color_type, int channels,
                     const std::vector<uint16_t>& samples) {
  std::string raw;
  size_t k = 0;
  for (int y = 0; y < height; ++y) {
    raw.push_back(0);  // filter type None
    for (int i = 0; i < width * channels; ++i, ++k) {
      if (bit_depth == 16) raw.push_back(char(samples[k] >> 8));  // big-endian
      raw.push_back(char(samples[k] & 0xff));
    }
  }
  uLongf packed_size = compressBound(uLong(raw.size()));
  std::string packed(packed_size, '\0');
  EXPECT_EQ(compress(reinterpret_cast<Bytef*>(packed.data()), &packed_size, reinterpret_cast<const Bytef*>(raw.data()),
                     uLong(raw.size())),
            Z_OK);
  packed.resize(packed_size);

  std::string png = "\x89PNG\r\n\x1a\n";
  std::string ihdr;
  put_be32(ihdr, uint32_t(width));
  put_be32(ihdr, uint32_t(height));
  ihdr += {char(bit_depth), char(color_type), 0, 0, 0};  // compression, filter, interlace
  put_chunk(png, "IHDR", ihdr);
  put_chunk(png, "IDAT", packed);
  put_chunk(png, "IEND", "");
  return png;
}

// Runs f, which must throw edrnr::Error whose message contains `word`.
template <class F>
void expect_error(F&& f, const std::string& word) {
  try {
    f();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << "missing '" << word << "' in: " << e.what();
    return;
  }
  ADD_FAILURE() << "no edrnr::Error thrown";
}

TEST_F(ImageFiles, Reads16BitRgbaExactly) {
  // Samples whose two bytes differ, so a byte-order mistake shows.
  std::vector<uint16_t> s = {0x0102, 0xffff, 0x0000, 0x8000, 0x1234, 0xabcd, 0x00ff, 0xff00};
  write_file_atomic(dir_ / "a.png", make_png(2, 1, 16, 6, 4, s));
  Image img = read_png_rgba(dir_ / "a.png");
  ASSERT_EQ(img.width, 2);
  ASSERT_EQ(img.height, 1);
  ASSERT_EQ(img.channels, 4);
  for (size_t i = 0; i < s.size(); ++i) EXPECT_EQ(img.data[i], float(s[i]) / 65535.f) << i;
}

TEST_F(ImageFiles, Reads8BitRgbAndGrayAsOpaqueRgba) {
  std::vector<uint16_t> rgb = {0, 1, 2, 100, 200, 255, 17, 34, 51, 254, 128, 64};  // 2x2 RGB
  write_file_atomic(dir_ / "rgb.png", make_png(2, 2, 8, 2, 3, rgb));
  Image img = read_png_rgba(dir_ / "rgb.png");
  ASSERT_EQ(img.channels, 4);
  ASSERT_EQ(img.data.size(), 16u);
  for (int p = 0; p < 4; ++p) {
    for (int c = 0; c < 3; ++c) EXPECT_EQ(img.data[p * 4 + c], float(rgb[p * 3 + c]) / 255.f);
    EXPECT_EQ(img.data[p * 4 + 3], 1.f);
  }

  std::vector<uint16_t> gray = {0, 85, 170, 255};  // 4x1 gray
  write_file_atomic(dir_ / "gray.png", make_png(4, 1, 8, 0, 1, gray));
  Image g = read_png_rgba(dir_ / "gray.png");
  ASSERT_EQ(g.width, 4);
  for (int p = 0; p < 4; ++p) {
    for (int c = 0; c < 3; ++c) EXPECT_EQ(g.data[p * 4 + c], float(gray[p]) / 255.f);
    EXPECT_EQ(g.data[p * 4 + 3], 1.f);
  }
}

TEST_F(ImageFiles, RgbRoundTripIsExactForEveryLevel) {
  Image img(16, 16, 3);
  for (size_t i = 0; i < img.data.size(); ++i) img.data[i] = float(i % 256) / 255.f;
  write_png(dir_ / "rt.png", img);
  Image back = read_png_rgba(dir_ / "rt.png");
  ASSERT_EQ(back.width, 16);
  ASSERT_EQ(back.height, 16);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) {
      for (int c = 0; c < 3; ++c) ASSERT_EQ(back.at(x, y)[c], img.at(x, y)[c]) << x << "," << y;
      ASSERT_EQ(back.at(x, y)[3], 1.f);
    }
}

TEST_F(ImageFiles, RgbaRoundTripKeepsAlpha) {
  Image img(3, 2, 4);
  for (size_t i = 0; i < img.data.size(); ++i) img.data[i] = float((i * 37) % 256) / 255.f;
  write_png(dir_ / "rgba.png", img);
  Image back = read_png_rgba(dir_ / "rgba.png");
  ASSERT_EQ(back.data.size(), img.data.size());
  for (size_t i = 0; i < img.data.size(); ++i) EXPECT_EQ(back.data[i], img.data[i]) << i;
}

TEST_F(ImageFiles, WriteClampsAndRoundsToNearest) {
  Image img(5, 1, 3);
  float values[5] = {-0.5f, 2.f, (10 + 0.4f) / 255.f, (10 + 0.6f) / 255.f, 254.7f / 255.f};
  int expected[5] = {0, 255, 10, 11, 255};
  for (int x = 0; x < 5; ++x)
    for (int c = 0; c < 3; ++c) img.at(x, 0)[c] = values[x];
  write_png(dir_ / "clamp.png", img);
  Image back = read_png_rgba(dir_ / "clamp.png");
  for (int x = 0; x < 5; ++x) EXPECT_EQ(back.at(x, 0)[1], float(expected[x]) / 255.f) << x;
}

TEST_F(ImageFiles, WriteErrors) {
  expect_error([&] { write_png(dir_ / "one.png", Image(2, 2, 1)); }, "channels");
  expect_error([&] { write_png(dir_ / "no_such_dir" / "x.png", Image(2, 2, 3)); }, "no_such_dir");
}

TEST_F(ImageFiles, ReadErrorsNameTheFile) {
  expect_error([&] { read_png_rgba(dir_ / "missing.png"); }, "missing.png");
  write_file_atomic(dir_ / "text.png", std::string("hello, this is not an image"));
  expect_error([&] { read_png_rgba(dir_ / "text.png"); }, "text.png");
  expect_error([&] { read_png_rgba(dir_ / "text.png"); }, "PNG");
  // A valid PNG cut short.
  std::string png = make_png(4, 4, 8, 2, 3, std::vector<uint16_t>(48, 7));
  write_file_atomic(dir_ / "cut.png", png.substr(0, png.size() - 20));
  expect_error([&] { read_png_rgba(dir_ / "cut.png"); }, "cut.png");
}

// A PNG's size is checked from its header before anything of that size is
// allocated (issue #16: a 4 MB PNG claiming 30000x30000 needed 11 GB).
TEST_F(ImageFiles, SizeLimitIsCheckedBeforeDecoding) {
  // Only the header is valid for these sizes: the image data is a single row.
  std::string png = make_png(1, 1, 8, 2, 3, std::vector<uint16_t>(3, 7));
  auto with_size = [&](uint32_t w, uint32_t h) {
    std::string p = png;
    std::string ihdr;
    put_be32(ihdr, w);
    put_be32(ihdr, h);
    ihdr += {char(8), char(2), 0, 0, 0};
    std::string fixed = "\x89PNG\r\n\x1a\n";
    put_chunk(fixed, "IHDR", ihdr);
    return fixed + p.substr(8 + 25);  // the original IDAT and IEND
  };
  write_file_atomic(dir_ / "huge.png", with_size(30000, 30000));
  expect_error([&] { read_png_rgba(dir_ / "huge.png"); }, "30000x30000: each side must be 1..16384 pixels");
  write_file_atomic(dir_ / "many.png", with_size(8192, 8192));
  expect_error([&] { read_png_rgba(dir_ / "many.png"); }, "67108864 pixels, over the limit of 16777216");
  expect_error([&] { read_png_rgba(dir_ / "many.png"); }, "many.png");
}

TEST(Image, CompositeOverBackground) {
  Image rgba(3, 1, 4);
  float px[3][4] = {{0.2f, 0.4f, 0.6f, 0.25f}, {0.3f, 0.7f, 0.9f, 0.f}, {0.3f, 0.7f, 0.9f, 1.f}};
  for (int x = 0; x < 3; ++x)
    for (int c = 0; c < 4; ++c) rgba.at(x, 0)[c] = px[x][c];
  const float bg[3] = {1.f, 0.f, 0.5f};
  Image out = composite_rgba(rgba, bg);
  ASSERT_EQ(out.channels, 3);
  ASSERT_EQ(out.width, 3);
  // 0.2 * 0.25 + 1 * 0.75 = 0.8; 0.4 * 0.25 + 0 = 0.1; 0.6 * 0.25 + 0.5 * 0.75 = 0.525.
  EXPECT_NEAR(out.at(0, 0)[0], 0.8, 1e-6);
  EXPECT_NEAR(out.at(0, 0)[1], 0.1, 1e-6);
  EXPECT_NEAR(out.at(0, 0)[2], 0.525, 1e-6);
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(out.at(1, 0)[c], bg[c]);     // transparent: the background exactly
    EXPECT_EQ(out.at(2, 0)[c], px[2][c]);  // opaque: the colour exactly
  }
  const float black[3] = {0.f, 0.f, 0.f};
  expect_error([&] { composite_rgba(Image(2, 2, 3), black); }, "4 channels");
}

TEST(Image, DownscaleAveragesBlocks) {
  Image img(4, 2, 2);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 4; ++x) {
      img.at(x, y)[0] = float(1 + x + 4 * y);  // 1 2 3 4 / 5 6 7 8
      img.at(x, y)[1] = x == 0 && y == 0 ? 1.f : 0.f;
    }
  Image half = downscale(img, 2);
  ASSERT_EQ(half.width, 2);
  ASSERT_EQ(half.height, 1);
  ASSERT_EQ(half.channels, 2);
  EXPECT_EQ(half.at(0, 0)[0], 3.5f);  // (1 + 2 + 5 + 6) / 4
  EXPECT_EQ(half.at(1, 0)[0], 5.5f);  // (3 + 4 + 7 + 8) / 4
  EXPECT_EQ(half.at(0, 0)[1], 0.25f);
  EXPECT_EQ(half.at(1, 0)[1], 0.f);

  Image quarter = downscale(Image(4, 4, 1, 0.75f), 4);
  ASSERT_EQ(quarter.data.size(), 1u);
  EXPECT_EQ(quarter.data[0], 0.75f);

  Image same = downscale(img, 1);
  EXPECT_EQ(same.data, img.data);
  expect_error([&] { downscale(img, 3); }, "divide");
  expect_error([&] { downscale(img, 0); }, "factor");
}

}  // namespace
}  // namespace edrnr
