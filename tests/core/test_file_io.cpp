#include <fcntl.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <filesystem>
#include <functional>
#include <string>
#include <thread>
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

// ---- outputs that are not plain new files (issue #16) ----

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

// A symbolic link given as the output is followed: its target gets the new
// contents (atomically, through a temporary file beside the target) and the
// link itself stays a link.
TEST_F(FileIo, SymbolicLinkIsFollowedAndItsTargetReplaced) {
  fs::create_directories(dir_ / "real");
  write_file_atomic(dir_ / "real" / "t.txt", std::string("old"));
  fs::create_symlink("real/t.txt", dir_ / "link.txt");
  fs::create_symlink("link.txt", dir_ / "chain.txt");
  write_file_atomic(dir_ / "chain.txt", std::string("new contents"));
  EXPECT_TRUE(fs::is_symlink(dir_ / "link.txt"));
  EXPECT_TRUE(fs::is_symlink(dir_ / "chain.txt"));
  EXPECT_EQ(read_file_text(dir_ / "real" / "t.txt"), "new contents");
  EXPECT_EQ(read_file_text(dir_ / "chain.txt"), "new contents");
  // A dangling link: the missing target is created.
  fs::create_symlink("real/new.txt", dir_ / "dangling.txt");
  write_file_atomic(dir_ / "dangling.txt", std::string("made"));
  EXPECT_TRUE(fs::is_symlink(dir_ / "dangling.txt"));
  EXPECT_EQ(read_file_text(dir_ / "real" / "new.txt"), "made");
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir_ / "real")) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"new.txt", "t.txt"}));  // no temporary left
  EXPECT_TRUE(same_file(dir_ / "chain.txt", dir_ / "real" / "t.txt"));
  EXPECT_FALSE(same_file(dir_ / "chain.txt", dir_ / "real" / "new.txt"));
  EXPECT_TRUE(same_file(dir_ / "x" / ".." / "real" / "zz", dir_ / "real" / "zz"));  // neither exists
}

// A FIFO is written through (a device would be too): it stays a FIFO and the
// reader gets the bytes.
TEST_F(FileIo, FifoIsWrittenThroughNotReplaced) {
  const fs::path fifo = dir_ / "pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  std::string got;
  std::thread reader([&] { got = read_file_text(fifo); });
  write_file_atomic(fifo, std::string("through the pipe"));
  reader.join();
  EXPECT_EQ(got, "through the pipe");
  struct stat st {};
  ASSERT_EQ(::lstat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
  EXPECT_FALSE(output_is_regular_file(fifo));
  EXPECT_TRUE(output_is_regular_file(dir_ / "new.png"));
  check_output_path(fifo, "-o");  // accepted
  // A link to the FIFO is followed to it.
  fs::create_symlink("pipe", dir_ / "to_pipe");
  std::thread reader2([&] { got = read_file_text(fifo); });
  write_file_atomic(dir_ / "to_pipe", std::string("again"));
  reader2.join();
  EXPECT_EQ(got, "again");
  EXPECT_TRUE(fs::is_symlink(dir_ / "to_pipe"));
}

TEST_F(FileIo, FolderAsOutputOrInputIsRefusedByName) {
  fs::create_directories(dir_ / "sub");
  std::string m = error_of([&] { write_file_atomic(dir_ / "sub", std::string("x")); });
  EXPECT_NE(m.find("is a folder"), std::string::npos) << m;
  m = error_of([&] { check_output_path(dir_ / "sub", "-o"); });
  EXPECT_NE(m.find("-o"), std::string::npos) << m;
  EXPECT_NE(m.find("folder"), std::string::npos) << m;
  EXPECT_TRUE(fs::is_directory(dir_ / "sub"));
  m = error_of([&] { read_file_bytes(dir_ / "sub"); });
  EXPECT_NE(m.find("is a folder, not a file"), std::string::npos) << m;
  m = error_of([&] { check_output_path(dir_ / "nodir" / "m.edrnr", "--float-output"); });
  EXPECT_NE(m.find("--float-output"), std::string::npos) << m;
  EXPECT_NE(m.find("'" + (dir_ / "nodir").string() + "' does not exist"), std::string::npos) << m;
}

// A failed write (here: the file size limit, as a full disk would) names the
// reason, leaves the old file as it was and no temporary file behind.
TEST_F(FileIo, FailedWriteNamesTheReasonAndKeepsTheOldFile) {
  write_file_atomic(dir_ / "keep.bin", std::string("precious"));
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::close(fds[0]);
    std::signal(SIGXFSZ, SIG_IGN);
    rlimit lim{4096, 4096};
    ::setrlimit(RLIMIT_FSIZE, &lim);
    const std::string m = error_of([&] { write_file_atomic(dir_ / "keep.bin", std::string(100000, 'z')); });
    (void)!::write(fds[1], m.data(), m.size());
    ::_exit(0);
  }
  ::close(fds[1]);
  std::string m;
  char buf[512];
  for (ssize_t n; (n = ::read(fds[0], buf, sizeof buf)) > 0;) m.append(buf, size_t(n));
  ::close(fds[0]);
  int status = 0;
  ::waitpid(pid, &status, 0);
  EXPECT_NE(m.find("error writing '" + (dir_ / "keep.bin").string() + "': File too large"), std::string::npos) << m;
  EXPECT_EQ(read_file_text(dir_ / "keep.bin"), "precious");
  EXPECT_EQ(listing(), std::vector<std::string>{"keep.bin"});
}

TEST_F(FileIo, ReadsStopAtTheLimitBeforeReading) {
  write_file_atomic(dir_ / "big.txt", std::string(5000, 'a'));
  std::string m = error_of([&] { read_file_text(dir_ / "big.txt", 4096); });
  EXPECT_NE(m.find("5000 bytes, over the limit of 4096"), std::string::npos) << m;
  EXPECT_EQ(read_file_text(dir_ / "big.txt", 5000).size(), 5000u);
  // A pipe is read only up to the limit.
  const fs::path fifo = dir_ / "pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  std::thread writer([&] {
    const int fd = ::open(fifo.c_str(), O_WRONLY);
    std::string chunk(1 << 16, 'b');
    for (int i = 0; i < 64; ++i)
      if (::write(fd, chunk.data(), chunk.size()) < 0) break;  // the reader stops early: EPIPE ends this
    ::close(fd);
  });
  std::signal(SIGPIPE, SIG_IGN);
  m = error_of([&] { read_file_bytes(fifo, 100000); });
  writer.join();
  EXPECT_NE(m.find("past the limit of 100000 bytes"), std::string::npos) << m;
}

}  // namespace
}  // namespace edrnr
