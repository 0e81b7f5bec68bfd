#pragma once
// A small tagged binary container for trainer checkpoints: magic
// "EDRNRCKP", format version, section count, CRC-32 of everything after the
// 24-byte header; then sections of (name, byte size, bytes). Little-endian
// host layout (x86-64 and AArch64).
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "core/error.h"

namespace edrnr::train {

inline constexpr uint32_t kCheckpointVersion = 1;

// Reads a checkpoint file for CheckpointReader: a file that does not start
// with the magic is refused after its first bytes, one larger than
// limits::kMaxCheckpointBytes before it is read. Throws Error naming the file.
std::vector<uint8_t> read_checkpoint_file(const std::filesystem::path& path);

class CheckpointWriter {
 public:
  // A writer; with count_only, one that only adds up the sections' sizes
  // (body_bytes(), for reserve() of the writer that writes them).
  explicit CheckpointWriter(bool count_only = false);
  void put_bytes(const std::string& name, const void* data, size_t bytes);
  template <class T>
  void put(const std::string& name, const std::vector<T>& v) {
    put_bytes(name, v.data(), v.size() * sizeof(T));
  }
  template <class T>
  void put_value(const std::string& name, const T& v) {
    put_bytes(name, &v, sizeof v);
  }
  void put_string(const std::string& name, const std::string& s) { put_bytes(name, s.data(), s.size()); }
  // Bytes of the sections so far (as written, names and sizes included).
  size_t body_bytes() const { return body_bytes_; }
  // Room for body_bytes of sections, so that no section is copied twice.
  void reserve(size_t body_bytes);
  // The finished file; the writer is left empty.
  std::vector<uint8_t> finish();

 private:
  bool count_only_ = false;
  std::vector<uint8_t> out_;  // the header's room, then the sections
  size_t body_bytes_ = 0;
  uint32_t count_ = 0;
};

class CheckpointReader {
 public:
  // Validates magic, version, sizes and CRC; throws Error naming `source`.
  CheckpointReader(const std::vector<uint8_t>& bytes, std::string source);
  bool has(const std::string& name) const { return sections_.count(name) != 0; }
  // The section names, sorted.
  std::vector<std::string> names() const {
    std::vector<std::string> out;
    for (const auto& [name, bytes] : sections_) out.push_back(name);
    return out;
  }
  std::string_view bytes(const std::string& name) const;
  template <class T>
  std::vector<T> get(const std::string& name) const {
    auto b = bytes(name);
    if (b.size() % sizeof(T))
      fail("{}: section '{}' has {} bytes, not a whole number of items", source_, name, b.size());
    std::vector<T> v(b.size() / sizeof(T));
    if (!v.empty()) std::memcpy(v.data(), b.data(), b.size());
    return v;
  }
  template <class T>
  T get_value(const std::string& name) const {
    auto b = bytes(name);
    if (b.size() != sizeof(T)) fail("{}: section '{}' has {} bytes, expected {}", source_, name, b.size(), sizeof(T));
    T v;
    std::memcpy(&v, b.data(), sizeof v);
    return v;
  }
  std::string get_string(const std::string& name) const { return std::string(bytes(name)); }
  const std::string& source() const { return source_; }

 private:
  std::string source_;
  std::map<std::string, std::string_view> sections_;
};

}  // namespace edrnr::train
