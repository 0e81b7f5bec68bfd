#pragma once
// Whole-file reads with a size limit, and writes that lose no data.
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "core/limits.h"

namespace edrnr {

// Reads the whole file. Throws Error naming the path if it is missing, a
// folder, unreadable, or longer than max_bytes (a regular file is checked
// against its size before anything is read; a pipe or device is read up to the
// limit). The message gives the system's reason for a failed read.
std::vector<uint8_t> read_file_bytes(const std::filesystem::path& path,
                                     uint64_t max_bytes = limits::kMaxModelFileBytes);
std::string read_file_text(const std::filesystem::path& path, uint64_t max_bytes = limits::kMaxTextFileBytes);

// An open input file, for readers that check a header before reading the rest
// (so that /dev/zero or a huge file is refused after a few bytes).
class InputFile {
 public:
  // Opens `path` for reading. Throws Error naming it if it is missing,
  // unreadable or a folder.
  explicit InputFile(const std::filesystem::path& path);
  ~InputFile();
  InputFile(const InputFile&) = delete;
  InputFile& operator=(const InputFile&) = delete;

  // The size of a regular file, or -1 for a pipe, socket or device.
  int64_t regular_size() const { return size_; }
  // Reads up to n bytes, fewer only at the end of the file. Returns the count.
  size_t read(uint8_t* out, size_t n);
  // Appends the rest of the file to `out`, reading at most max_total - out.size()
  // bytes. Returns false (having read one byte more than that) if the file
  // goes on past max_total bytes.
  bool read_rest(std::vector<uint8_t>& out, uint64_t max_total);
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
  int fd_ = -1;
  int64_t size_ = -1;
};

// Writes `bytes` to `path` so that no data is ever lost:
//  - a new name or an existing regular file: the bytes go to a temporary file
//    "<name>.tmp.<pid>" in the same folder, are flushed to disk, and the
//    temporary file is renamed over the name (a reader never sees half a file;
//    a failed or interrupted write leaves the old file as it was). An existing
//    file keeps its permissions.
//  - a symbolic link: followed (through any chain of links); its final target
//    is replaced as above and the link stays.
//  - a character device or a FIFO: written through directly (opening a FIFO
//    waits for a reader).
//  - a folder, a block device or a socket: refused.
// Throws Error naming the path and the system's reason ("No space left on
// device", "Permission denied", ...); no temporary file is left behind.
void write_file_atomic(const std::filesystem::path& path, std::string_view bytes);
void write_file_atomic(const std::filesystem::path& path, const std::vector<uint8_t>& bytes);

// Checks, before any work, that write_file_atomic(path, ...) can succeed as
// far as can be known: the folder that will hold the file exists and is
// writable, and the path (after symbolic links) is not a folder, block device
// or socket. `flag` names the option in the message (e.g. "-o"). Throws Error.
void check_output_path(const std::filesystem::path& path, std::string_view flag);

// True if `path` (after symbolic links) is, or will be created as, a regular
// file; false for a character device or FIFO. Callers use it to decide whether
// side files beside the output make sense.
bool output_is_regular_file(const std::filesystem::path& path);

// The final target of `path` after following symbolic links (to any depth; a
// missing final target is returned as is). Throws Error on a loop.
std::filesystem::path resolve_symlinks(const std::filesystem::path& path);

// True if a and b name the same file: the same path after symbolic links and
// normalisation, or (both existing) the same inode.
bool same_file(const std::filesystem::path& a, const std::filesystem::path& b);

}  // namespace edrnr
