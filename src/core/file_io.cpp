#include "core/file_io.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "core/error.h"

namespace edrnr {

namespace fs = std::filesystem;

namespace {

std::string reason(int err) { return std::strerror(err); }

std::string kind_name(mode_t mode) {
  if (S_ISDIR(mode)) return "a folder";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISFIFO(mode)) return "a FIFO";
  return "a special file";
}

// What a path names once symbolic links are followed.
struct Target {
  fs::path path;  // the final target
  bool exists = false;
  struct stat st {};  // valid when exists
};

Target resolve_target(const fs::path& given) {
  Target t;
  t.path = given;
  for (int depth = 0;; ++depth) {
    if (depth > 40) fail("'{}': too many levels of symbolic links", given.string());
    struct stat st {};
    if (::lstat(t.path.c_str(), &st) != 0) {
      const int e = errno;
      if (e == ENOENT) return t;  // a new file (possibly the target of a dangling link)
      fail("cannot access '{}': {}", t.path.string(), reason(e));
    }
    if (!S_ISLNK(st.st_mode)) {
      t.exists = true;
      t.st = st;
      return t;
    }
    std::error_code ec;
    fs::path link = fs::read_symlink(t.path, ec);
    if (ec) fail("cannot read the symbolic link '{}': {}", t.path.string(), ec.message());
    t.path = link.is_absolute() ? link : t.path.parent_path() / link;
  }
}

// The folder that holds `file` ("." for a bare name).
fs::path folder_of(const fs::path& file) { return file.has_parent_path() ? file.parent_path() : fs::path("."); }

void check_folder(const fs::path& file, const fs::path& given, std::string_view flag) {
  const fs::path dir = folder_of(file);
  std::string prefix = flag.empty() ? "" : std::string(flag) + " ";
  struct stat st {};
  if (::stat(dir.c_str(), &st) != 0) {
    const int e = errno;
    fail("{}'{}': cannot write: the folder '{}' {}", prefix, given.string(), dir.string(),
         e == ENOENT ? std::string("does not exist") : "cannot be reached: " + reason(e));
  }
  if (!S_ISDIR(st.st_mode)) fail("{}'{}': cannot write: '{}' is not a folder", prefix, given.string(), dir.string());
  if (::access(dir.c_str(), W_OK | X_OK) != 0) {
    const int e = errno;
    fail("{}'{}': cannot write into the folder '{}': {}", prefix, given.string(), dir.string(), reason(e));
  }
}

// Writes all of `bytes` to fd; returns 0 or the errno of the failure.
int write_all(int fd, std::string_view bytes) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    if (n == 0) return EIO;
    done += size_t(n);
  }
  return 0;
}

void write_through(const fs::path& target, const fs::path& given, std::string_view bytes) {
  int fd;
  do fd = ::open(target.c_str(), O_WRONLY | O_NOCTTY | O_CLOEXEC);
  while (fd < 0 && errno == EINTR);
  if (fd < 0) {
    const int e = errno;
    fail("cannot write '{}': {}", given.string(), reason(e));
  }
  const int err = write_all(fd, bytes);
  const int close_err = ::close(fd) != 0 ? errno : 0;
  if (err) fail("error writing '{}': {}", given.string(), reason(err));
  if (close_err && close_err != EINTR) fail("error writing '{}': {}", given.string(), reason(close_err));
}

void replace_regular(const Target& t, const fs::path& given, std::string_view bytes) {
  const fs::path dir = folder_of(t.path);
  // A fresh temporary name beside the target (never following a link there).
  fs::path tmp;
  int fd = -1;
  for (int attempt = 0; fd < 0; ++attempt) {
    tmp = t.path;
    tmp += fmt::format(".tmp.{}", ::getpid());
    if (attempt) tmp += fmt::format(".{}", attempt);
    const mode_t mode = t.exists ? (t.st.st_mode & 07777) : 0666;
    fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, mode);
    if (fd < 0 && errno == EINTR) continue;
    if (fd < 0 && errno == EEXIST && attempt < 100) continue;
    if (fd < 0) {
      const int e = errno;
      if (e == ENOENT) fail("cannot write '{}': the folder '{}' does not exist", given.string(), dir.string());
      fail("cannot write '{}': {}", given.string(), reason(e));
    }
  }
  int err = write_all(fd, bytes);
  if (!err && t.exists) (void)::fchmod(fd, t.st.st_mode & 07777);  // keep the old permissions (umask aside)
  if (!err && ::fsync(fd) != 0) err = errno;
  if (::close(fd) != 0 && !err && errno != EINTR) err = errno;
  if (err) {
    ::unlink(tmp.c_str());
    fail("error writing '{}': {}", given.string(), reason(err));
  }
  if (::rename(tmp.c_str(), t.path.c_str()) != 0) {
    const int e = errno;
    ::unlink(tmp.c_str());
    fail("cannot replace '{}': {}", t.path.string(), reason(e));
  }
  // Make the rename itself durable.
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    (void)::fsync(dfd);
    ::close(dfd);
  }
}

}  // namespace

// ---- reading ----

InputFile::InputFile(const fs::path& path) : path_(path) {
  do fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  while (fd_ < 0 && errno == EINTR);
  if (fd_ < 0) {
    const int e = errno;
    fail("cannot open '{}': {}", path.string(), reason(e));
  }
  struct stat st {};
  if (::fstat(fd_, &st) != 0) {
    const int e = errno;
    ::close(fd_);
    fd_ = -1;
    fail("cannot read '{}': {}", path.string(), reason(e));
  }
  if (S_ISDIR(st.st_mode)) {
    ::close(fd_);
    fd_ = -1;
    fail("'{}' is a folder, not a file", path.string());
  }
  size_ = S_ISREG(st.st_mode) ? int64_t(st.st_size) : -1;
}

InputFile::~InputFile() {
  if (fd_ >= 0) ::close(fd_);
}

size_t InputFile::read(uint8_t* out, size_t n) {
  size_t done = 0;
  while (done < n) {
    const ssize_t r = ::read(fd_, out + done, n - done);
    if (r < 0) {
      if (errno == EINTR) continue;
      const int e = errno;
      fail("error reading '{}': {}", path_.string(), reason(e));
    }
    if (r == 0) break;
    done += size_t(r);
  }
  return done;
}

bool InputFile::read_rest(std::vector<uint8_t>& out, uint64_t max_total) {
  if (size_ >= 0 && uint64_t(size_) > out.size()) {
    // A regular file: one read of what it should hold, then a check for more.
    const uint64_t want = std::min<uint64_t>(uint64_t(size_), max_total + 1);
    if (want > out.size()) {
      const size_t at = out.size();
      out.resize(size_t(want));
      out.resize(at + read(out.data() + at, size_t(want) - at));
    }
  }
  uint8_t buf[1 << 16];
  while (out.size() <= max_total) {
    const size_t room = size_t(std::min<uint64_t>(sizeof buf, max_total + 1 - out.size()));
    const size_t n = read(buf, room);
    if (n == 0) break;
    out.insert(out.end(), buf, buf + n);
  }
  return out.size() <= max_total;
}

namespace {
std::vector<uint8_t> read_limited(const fs::path& path, uint64_t max_bytes) {
  InputFile f(path);
  if (f.regular_size() >= 0 && uint64_t(f.regular_size()) > max_bytes)
    fail("'{}' is {} bytes, over the limit of {} bytes for this input", path.string(), f.regular_size(), max_bytes);
  std::vector<uint8_t> out;
  if (!f.read_rest(out, max_bytes))
    fail("'{}' goes on past the limit of {} bytes for this input", path.string(), max_bytes);
  return out;
}
}  // namespace

std::vector<uint8_t> read_file_bytes(const fs::path& path, uint64_t max_bytes) { return read_limited(path, max_bytes); }

std::string read_file_text(const fs::path& path, uint64_t max_bytes) {
  std::vector<uint8_t> b = read_limited(path, max_bytes);
  return std::string(b.begin(), b.end());
}

// ---- writing ----

void write_file_atomic(const fs::path& path, std::string_view bytes) {
  if (path.empty()) fail("cannot write a file with an empty name");
  const Target t = resolve_target(path);
  if (t.exists && !S_ISREG(t.st.st_mode)) {
    if (S_ISCHR(t.st.st_mode) || S_ISFIFO(t.st.st_mode)) return write_through(t.path, path, bytes);
    fail("cannot write '{}': it is {}{} (edrnr writes regular files, character devices and FIFOs)", path.string(),
         kind_name(t.st.st_mode), t.path == path ? "" : " ('" + t.path.string() + "')");
  }
  replace_regular(t, path, bytes);
}

void write_file_atomic(const fs::path& path, const std::vector<uint8_t>& bytes) {
  write_file_atomic(path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

void check_output_path(const fs::path& path, std::string_view flag) {
  std::string prefix = flag.empty() ? "" : std::string(flag) + " ";
  if (path.empty()) fail("{}: the file name is empty", flag);
  const Target t = resolve_target(path);
  if (t.exists && !S_ISREG(t.st.st_mode)) {
    if (S_ISCHR(t.st.st_mode) || S_ISFIFO(t.st.st_mode)) return;  // written through
    fail("{}'{}': cannot write: it is {}{}", prefix, path.string(), kind_name(t.st.st_mode),
         t.path == path ? "" : " ('" + t.path.string() + "')");
  }
  check_folder(t.path, path, flag);
}

bool output_is_regular_file(const fs::path& path) {
  const Target t = resolve_target(path);
  return !t.exists || S_ISREG(t.st.st_mode);
}

fs::path resolve_symlinks(const fs::path& path) { return resolve_target(path).path; }

bool same_file(const fs::path& a, const fs::path& b) {
  const Target ta = resolve_target(a), tb = resolve_target(b);
  if (ta.exists && tb.exists) return ta.st.st_dev == tb.st.st_dev && ta.st.st_ino == tb.st.st_ino;
  std::error_code ec1, ec2;
  const fs::path na = fs::weakly_canonical(fs::absolute(ta.path), ec1);
  const fs::path nb = fs::weakly_canonical(fs::absolute(tb.path), ec2);
  if (ec1 || ec2) return fs::absolute(ta.path).lexically_normal() == fs::absolute(tb.path).lexically_normal();
  return na == nb;
}

}  // namespace edrnr
