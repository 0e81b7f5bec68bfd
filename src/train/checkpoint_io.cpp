#include "train/checkpoint_io.h"

#include <zlib.h>

#include <algorithm>

#include "core/file_io.h"
#include "core/limits.h"

namespace edrnr::train {
namespace {

constexpr char kMagic[8] = {'E', 'D', 'R', 'N', 'R', 'C', 'K', 'P'};
constexpr size_t kHeaderBytes = 24;

uint32_t crc32_of(const uint8_t* data, size_t n) {
  uLong crc = crc32(0L, Z_NULL, 0);
  while (n) {
    const uInt chunk = uInt(std::min<size_t>(n, 1u << 30));
    crc = crc32(crc, data, chunk);
    data += chunk;
    n -= chunk;
  }
  return uint32_t(crc);
}

template <class T>
void append(std::vector<uint8_t>& out, const T& v) {
  const auto* p = reinterpret_cast<const uint8_t*>(&v);
  out.insert(out.end(), p, p + sizeof v);
}

}  // namespace

std::vector<uint8_t> read_checkpoint_file(const std::filesystem::path& path) {
  InputFile f(path);
  std::vector<uint8_t> bytes(kHeaderBytes);
  bytes.resize(f.read(bytes.data(), kHeaderBytes));
  if (bytes.size() < sizeof kMagic || std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0)
    fail("{}: not an edrnr training checkpoint (bad magic)", path.string());
  if (f.regular_size() >= 0 && uint64_t(f.regular_size()) > limits::kMaxCheckpointBytes)
    fail("{}: {} bytes, over the limit of {} bytes for a checkpoint", path.string(), f.regular_size(),
         limits::kMaxCheckpointBytes);
  if (!f.read_rest(bytes, limits::kMaxCheckpointBytes))
    fail("{}: goes on past the limit of {} bytes for a checkpoint", path.string(), limits::kMaxCheckpointBytes);
  return bytes;
}

CheckpointWriter::CheckpointWriter(bool count_only) : count_only_(count_only) {
  if (!count_only_) out_.resize(kHeaderBytes);
}

void CheckpointWriter::reserve(size_t body_bytes) {
  if (!count_only_) out_.reserve(kHeaderBytes + body_bytes);
}

void CheckpointWriter::put_bytes(const std::string& name, const void* data, size_t bytes) {
  body_bytes_ += sizeof(uint32_t) + name.size() + sizeof(uint64_t) + bytes;
  ++count_;
  if (count_only_) return;
  append(out_, uint32_t(name.size()));
  out_.insert(out_.end(), name.begin(), name.end());
  append(out_, uint64_t(bytes));
  const auto* p = static_cast<const uint8_t*>(data);
  if (bytes) out_.insert(out_.end(), p, p + bytes);
}

std::vector<uint8_t> CheckpointWriter::finish() {
  if (count_only_) fail("checkpoint writer: a counting writer has no file to finish");
  // The header in the room left for it: magic, version, count, CRC, padding.
  uint8_t* h = out_.data();
  const uint32_t crc = crc32_of(h + kHeaderBytes, out_.size() - kHeaderBytes), pad = 0;
  std::memcpy(h, kMagic, sizeof kMagic);
  std::memcpy(h + 8, &kCheckpointVersion, 4);
  std::memcpy(h + 12, &count_, 4);
  std::memcpy(h + 16, &crc, 4);
  std::memcpy(h + 20, &pad, 4);
  std::vector<uint8_t> done = std::move(out_);
  out_.assign(kHeaderBytes, 0);
  body_bytes_ = 0;
  count_ = 0;
  return done;
}

CheckpointReader::CheckpointReader(const std::vector<uint8_t>& bytes, std::string source) : source_(std::move(source)) {
  if (bytes.size() < kHeaderBytes || std::memcmp(bytes.data(), kMagic, 8) != 0)
    fail("{}: not an edrnr training checkpoint (bad magic)", source_);
  uint32_t version, count, crc;
  std::memcpy(&version, bytes.data() + 8, 4);
  std::memcpy(&count, bytes.data() + 12, 4);
  std::memcpy(&crc, bytes.data() + 16, 4);
  if (version != kCheckpointVersion)
    fail("{}: checkpoint version {} is not the supported version {}", source_, version, kCheckpointVersion);
  if (crc32_of(bytes.data() + kHeaderBytes, bytes.size() - kHeaderBytes) != crc)
    fail("{}: checkpoint is corrupt (CRC mismatch)", source_);
  size_t pos = kHeaderBytes;
  for (uint32_t i = 0; i < count; ++i) {
    uint32_t name_len;
    uint64_t size;
    if (bytes.size() - pos < 4) fail("{}: checkpoint truncated in section {}", source_, i);
    std::memcpy(&name_len, bytes.data() + pos, 4);
    pos += 4;
    if (bytes.size() - pos < uint64_t(name_len) + 8) fail("{}: checkpoint truncated in section {}", source_, i);
    std::string name(reinterpret_cast<const char*>(bytes.data() + pos), name_len);
    pos += name_len;
    std::memcpy(&size, bytes.data() + pos, 8);
    pos += 8;
    if (bytes.size() - pos < size) fail("{}: checkpoint section '{}' is truncated", source_, name);
    sections_[name] = std::string_view(reinterpret_cast<const char*>(bytes.data() + pos), size_t(size));
    pos += size_t(size);
  }
  if (pos != bytes.size()) fail("{}: checkpoint has {} trailing bytes", source_, bytes.size() - pos);
}

std::string_view CheckpointReader::bytes(const std::string& name) const {
  auto it = sections_.find(name);
  if (it == sections_.end()) fail("{}: checkpoint has no section '{}'", source_, name);
  return it->second;
}

}  // namespace edrnr::train
