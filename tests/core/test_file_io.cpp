#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/file_io.h"

namespace edrnr {
namespace {

namespace fs = std::filesystem;

class FileIo : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ =
        fs::temp_directory_path() / fmt::format("edrnr_test_{}_{}_{}", info->test_suite_name(), info->name(), getpid());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Names of the files in the test folder.
  std::vector<std::string> listing() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir_)) names.push_back(e.path().filename().string());
    return names;
  }

  fs::path dir_;
};

TEST_F(FileIo, BinaryRoundTrip) {
  std::vector<uint8_t> bytes;
  for (int i = 0; i < 256; ++i) bytes.push_back(uint8_t(i));
  bytes.push_back(0);
  bytes.push_back('\n');
  write_file_atomic(dir_ / "b.bin", bytes);
  EXPECT_EQ(fs::file_size(dir_ / "b.bin"), 258u);
  EXPECT_EQ(read_file_bytes(dir_ / "b.bin"), bytes);
  std::string text = read_file_text(dir_ / "b.bin");
  ASSERT_EQ(text.size(), 258u);
  EXPECT_EQ(text[0], '\0');
  EXPECT_EQ(uint8_t(text[255]), 255);
}

TEST_F(FileIo, LargerThanOneReadBuffer) {
  std::string big(200000, 'x');
  big[123456] = 'y';
  write_file_atomic(dir_ / "big.txt", big);
  EXPECT_EQ(read_file_text(dir_ / "big.txt"), big);
}

TEST_F(FileIo, EmptyFile) {
  write_file_atomic(dir_ / "empty", std::string());
  EXPECT_TRUE(fs::exists(dir_ / "empty"));
  EXPECT_TRUE(read_file_bytes(dir_ / "empty").empty());
}

TEST_F(FileIo, OverwriteReplacesContentAndLeavesNoTemporary) {
  write_file_atomic(dir_ / "f.txt", std::string("a much longer first version"));
  write_file_atomic(dir_ / "f.txt", std::string("short"));
  EXPECT_EQ(read_file_text(dir_ / "f.txt"), "short");
  EXPECT_EQ(listing(), std::vector<std::string>{"f.txt"});
}

TEST_F(FileIo, ErrorsNameThePath) {
  try {
    read_file_text(dir_ / "missing.txt");
    ADD_FAILURE() << "no Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("missing.txt"), std::string::npos) << e.what();
  }
  try {
    write_file_atomic(dir_ / "no_dir" / "f.txt", std::string("x"));
    ADD_FAILURE() << "no Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no_dir"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(listing().empty());
  // A folder is not a readable file.
  EXPECT_THROW(read_file_bytes(dir_), Error);
}

}  // namespace
}  // namespace edrnr
