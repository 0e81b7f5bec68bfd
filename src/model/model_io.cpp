#include "model/model_io.h"

#include <fmt/format.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"
#include "model/model_format.h"

namespace edrnr {
namespace {

using namespace model_format;

// ---- little-endian encoding ----

uint32_t load_u32(const uint8_t* p) {
  return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}
uint64_t load_u64(const uint8_t* p) { return uint64_t(load_u32(p)) | uint64_t(load_u32(p + 4)) << 32; }

class Writer {
 public:
  void u8(uint8_t v) { buf_.push_back(v); }
  void u32(uint32_t v) {
    for (int i = 0; i < 4; ++i) buf_.push_back(uint8_t(v >> (8 * i)));
  }
  void u64(uint64_t v) {
    u32(uint32_t(v));
    u32(uint32_t(v >> 32));
  }
  void i32(int32_t v) { u32(uint32_t(v)); }
  void f32(float v) { u32(std::bit_cast<uint32_t>(v)); }
  void bytes(const void* p, size_t n) {
    const uint8_t* b = static_cast<const uint8_t*>(p);
    buf_.insert(buf_.end(), b, b + n);
  }
  void f32s(const std::vector<float>& v) {
    size_t at = buf_.size();
    buf_.resize(at + 4 * v.size());
    for (size_t i = 0; i < v.size(); ++i) {
      uint32_t bits = std::bit_cast<uint32_t>(v[i]);
      for (int k = 0; k < 4; ++k) buf_[at + 4 * i + size_t(k)] = uint8_t(bits >> (8 * k));
    }
  }
  void pad_to(size_t align) {
    while (buf_.size() % align) buf_.push_back(0);
  }
  size_t size() const { return buf_.size(); }
  std::vector<uint8_t>& buf() { return buf_; }

 private:
  std::vector<uint8_t> buf_;
};

// Sequential reads inside one section. Section sizes are validated before any
// Reader is made, so running past the end is an internal error; it still
// throws rather than reading out of bounds.
class Reader {
 public:
  Reader(const uint8_t* p, size_t n, std::string where) : p_(p), n_(n), where_(std::move(where)) {}
  uint8_t u8() { return *take(1); }
  uint32_t u32() { return load_u32(take(4)); }
  int32_t i32() { return int32_t(u32()); }
  float f32() { return std::bit_cast<float>(u32()); }
  const uint8_t* take(size_t n) {
    if (n > n_ - pos_) fail("{}: read past the end of the section (internal error)", where_);
    const uint8_t* r = p_ + pos_;
    pos_ += n;
    return r;
  }

 private:
  const uint8_t* p_;
  size_t n_, pos_ = 0;
  std::string where_;
};

uint32_t crc32_of(const uint8_t* p, size_t n) {
  uLong crc = crc32(0L, Z_NULL, 0);
  while (n > 0) {
    uInt chunk = uInt(std::min<size_t>(n, 1u << 30));
    crc = crc32(crc, p, chunk);
    p += chunk;
    n -= chunk;
  }
  return uint32_t(crc);
}

// ---- section encoders ----

void write_bitmap(Writer& w, const Bitmap3& bm) {
  uint64_t n = bitmap_bytes(bm.res());
  for (uint64_t i = 0; i < n; ++i) w.u8(uint8_t(bm.words()[i / 8] >> (8 * (i % 8))));
}

void write_box(Writer& w, const Box3f& b) {
  for (int a = 0; a < 3; ++a) w.f32(b.lo[a]);
  for (int a = 0; a < 3; ++a) w.f32(b.hi[a]);
}

void write_floats(Writer& w, const std::vector<float>& v) { w.f32s(v); }

std::vector<uint8_t> encode_section(const SceneModel& m, int s) {
  Writer w;
  switch (s) {
    case kGrid:
      write_box(w, m.scene_box);
      write_box(w, m.object_aabb);
      w.i32(m.micro_res);
      w.i32(m.feature_channels);
      w.u32(uint32_t(m.block_count()));
      w.u32(uint32_t(m.mlp_count()));
      break;
    case kOcc0:
    case kOcc1:
    case kOcc2:
    case kOcc3:
      write_bitmap(w, m.occupancy[s - kOcc0]);
      break;
    case kBlockIndex:
      for (uint32_t i : m.block_fine_index) w.u32(i);
      break;
    case kMlpIndex:
      for (uint32_t i : m.mlp_coarse_index) w.u32(i);
      break;
    case kFeaturesQ4:
      write_floats(w, m.feature_quant.scale);
      w.bytes(m.feature_quant.zero_point.data(), m.feature_quant.zero_point.size());
      w.bytes(m.features_q4.data(), m.features_q4.size());
      break;
    case kFeaturesF32:
      write_floats(w, m.features_f32);
      break;
    case kMlpShape:
      w.i32(m.mlp_arch.dir_frequencies);
      w.u32(uint32_t(m.mlp_arch.density_widths.size()));
      w.u32(uint32_t(m.mlp_arch.color_widths.size()));
      for (int x : m.mlp_arch.density_widths) w.i32(x);
      for (int x : m.mlp_arch.color_widths) w.i32(x);
      break;
    case kMlpsQ8:
      for (const MlpQ& q : m.mlps_q8)
        for (const auto* net : {&q.density, &q.color})
          for (const DenseQ& l : *net) {
            w.f32(l.in_scale);
            write_floats(w, l.w_scale);
            write_floats(w, l.b);
            w.bytes(l.w.data(), l.w.size());
          }
      break;
    case kMlpsF32:
      for (const MlpF& f : m.mlps_f32)
        for (const auto* net : {&f.density, &f.color})
          for (const DenseF& l : *net) {
            write_floats(w, l.w);
            write_floats(w, l.b);
          }
      break;
    case kMetadata:
      w.bytes(m.metadata_json.data(), m.metadata_json.size());
      break;
  }
  return std::move(w.buf());
}

bool section_present(const SceneModel& m, int s) {
  switch (s) {
    case kFeaturesQ4:
      return !m.features_q4.empty() || !m.feature_quant.scale.empty();
    case kFeaturesF32:
      return !m.features_f32.empty();
    case kMlpShape:
      return m.mlp_count() > 0 || !(m.mlp_arch == MlpArch{});
    case kMlpsQ8:
      return !m.mlps_q8.empty();
    case kMlpsF32:
      return !m.mlps_f32.empty();
    default:
      return true;
  }
}

// ---- section decoders (sizes already checked against the expected ones) ----

struct Span {
  const uint8_t* p = nullptr;
  size_t size = 0;
  bool present = false;
};

Bitmap3 read_bitmap(const Span& sp, int res) {
  Bitmap3 bm(res);
  for (size_t i = 0; i < sp.size; ++i) bm.words()[i / 8] |= uint64_t(sp.p[i]) << (8 * (i % 8));
  return bm;
}

Box3f read_box(Reader& r) {
  Box3f b;
  for (int a = 0; a < 3; ++a) b.lo[a] = r.f32();
  for (int a = 0; a < 3; ++a) b.hi[a] = r.f32();
  return b;
}

std::vector<float> read_floats(Reader& r, size_t n) {
  std::vector<float> v(n);
  for (float& x : v) x = r.f32();
  return v;
}

std::vector<uint32_t> read_index(const Span& sp) {
  std::vector<uint32_t> v(sp.size / 4);
  for (size_t i = 0; i < v.size(); ++i) v[i] = load_u32(sp.p + 4 * i);
  return v;
}

void expect_size(const Span& sp, int s, uint64_t want, const std::string& why, const std::string& src) {
  if (sp.size != want) fail("{}: {} is {} bytes, expected {} {}", src, sec(s), sp.size, want, why);
}

template <class Layer, class ReadLayer>
std::vector<Layer> read_net(const std::vector<int>& widths, ReadLayer read_layer) {
  std::vector<Layer> net(widths.size() - 1);
  for (size_t l = 0; l < net.size(); ++l) {
    net[l].in = widths[l];
    net[l].out = widths[l + 1];
    read_layer(net[l]);
  }
  return net;
}

}  // namespace

std::vector<uint8_t> serialize_model(const SceneModel& model) {
  const std::string src = "cannot save model";
  validate_grid(model, src);
  validate_shapes(model, src);
  validate_content(model, src);

  std::vector<int> kinds;
  for (int s = 0; s < kSectionKinds; ++s)
    if (section_present(model, s)) kinds.push_back(s);
  std::vector<std::vector<uint8_t>> bodies;
  for (int s : kinds) bodies.push_back(encode_section(model, s));

  Writer table;
  uint64_t offset = kModelHeaderBytes + kModelSectionEntryBytes * kinds.size();
  std::vector<uint64_t> offsets;
  for (size_t i = 0; i < kinds.size(); ++i) {
    offset = (offset + kSectionAlignBytes - 1) / kSectionAlignBytes * kSectionAlignBytes;
    offsets.push_back(offset);
    table.bytes(kSectionInfo[kinds[i]].tag, 4);
    table.u32(0);
    table.u64(offset);
    table.u64(bodies[i].size());
    offset += bodies[i].size();
  }
  const uint64_t total = offset;

  Writer out;
  out.bytes(kMagic, 8);
  out.u32(kModelFormatVersion);
  out.u32(uint32_t(kinds.size()));
  out.u64(total);
  out.u32(0);  // CRC, filled in below
  out.u32(0);
  out.bytes(table.buf().data(), table.size());
  for (size_t i = 0; i < kinds.size(); ++i) {
    out.pad_to(kSectionAlignBytes);
    out.bytes(bodies[i].data(), bodies[i].size());
  }
  std::vector<uint8_t>& bytes = out.buf();
  uint32_t crc = crc32_of(bytes.data() + kModelHeaderBytes, bytes.size() - kModelHeaderBytes);
  for (int i = 0; i < 4; ++i) bytes[24 + i] = uint8_t(crc >> (8 * i));
  return std::move(bytes);
}

SceneModel parse_model(const uint8_t* data, size_t size, const std::string& source) {
  return parse_model(data, size, source, ModelLoadOptions{});
}

SceneModel parse_model(const uint8_t* data, size_t size, const std::string& src, const ModelLoadOptions& options) {
  // Header.
  if (size < sizeof kMagic || !std::equal(kMagic, kMagic + 8, data))
    fail("{}: not an edrnr model (the file does not start with the magic \"EDRNRMDL\")", src);
  if (size < kModelHeaderBytes)
    fail("{}: truncated: {} bytes, shorter than the {}-byte header", src, size, kModelHeaderBytes);
  const uint32_t version = load_u32(data + 8);
  if (version > kModelFormatVersion)
    fail("{}: format version {} is newer than this edrnr supports ({})", src, version, kModelFormatVersion);
  if (version == 0) fail("{}: format version 0 is not valid", src);
  const uint32_t section_count = load_u32(data + 12);
  const uint64_t total = load_u64(data + 16);
  if (total != size)
    fail("{}: the header gives a total size of {} bytes but there are {} (truncated or padded file)", src, total, size);
  const uint32_t crc = crc32_of(data + kModelHeaderBytes, size - kModelHeaderBytes);
  if (crc != load_u32(data + 24))
    fail("{}: CRC-32 mismatch (header {:08x}, contents {:08x}): the file is corrupt", src, load_u32(data + 24), crc);
  if (load_u32(data + 28) != 0) fail("{}: the header's reserved field is not zero", src);

  // Section table.
  if (section_count == 0 || section_count > uint32_t(kSectionKinds))
    fail("{}: section count {} is not in 1..{}", src, section_count, int(kSectionKinds));
  const uint64_t table_end = kModelHeaderBytes + uint64_t(kModelSectionEntryBytes) * section_count;
  if (table_end > size) fail("{}: the table of {} sections runs past the end of the file", src, section_count);
  Span spans[kSectionKinds];
  struct Extent {
    uint64_t offset, size;
    int kind;
  };
  std::vector<Extent> extents;
  for (uint32_t i = 0; i < section_count; ++i) {
    const uint8_t* e = data + kModelHeaderBytes + kModelSectionEntryBytes * i;
    int kind = -1;
    for (int s = 0; s < kSectionKinds; ++s)
      if (std::equal(e, e + 4, kSectionInfo[s].tag)) kind = s;
    if (kind < 0) {
      std::string tag;
      for (int k = 0; k < 4; ++k) tag += (e[k] >= 32 && e[k] < 127) ? char(e[k]) : '?';
      fail("{}: section table entry {} has the unknown tag \"{}\"", src, i, tag);
    }
    if (spans[kind].present) fail("{}: {} appears twice in the section table", src, sec(kind));
    if (load_u32(e + 4) != 0) fail("{}: {}: the table entry's reserved field is not zero", src, sec(kind));
    uint64_t off = load_u64(e + 8), len = load_u64(e + 16);
    if (off < table_end || off > size || len > size - off)
      fail("{}: {} at offset {}, {} bytes, lies outside the data area [{}, {}) of the file", src, sec(kind), off, len,
           table_end, size);
    spans[kind] = Span{data + off, size_t(len), true};
    extents.push_back({off, len, kind});
  }
  std::sort(extents.begin(), extents.end(), [](const Extent& a, const Extent& b) { return a.offset < b.offset; });
  for (size_t i = 1; i < extents.size(); ++i)
    if (extents[i - 1].offset + extents[i - 1].size > extents[i].offset)
      fail("{}: {} and {} overlap", src, sec(extents[i - 1].kind), sec(extents[i].kind));
  for (int s = 0; s < kSectionKinds; ++s)
    if (kSectionInfo[s].required && !spans[s].present) fail("{}: required {} is missing", src, sec(s));

  // Grid: everything else is sized from it.
  SceneModel m;
  expect_size(spans[kGrid], kGrid, kGridBytes, "", src);
  Reader grid(spans[kGrid].p, spans[kGrid].size, src);
  m.scene_box = read_box(grid);
  m.object_aabb = read_box(grid);
  m.micro_res = grid.i32();
  m.feature_channels = grid.i32();
  const uint32_t blocks = grid.u32(), mlps = grid.u32();
  validate_grid(m, src);
  const int F = m.feature_channels;
  if (blocks > voxel_count(m.fine_res()))
    fail("{}: {}: block count {} exceeds the {} fine voxels of micro_res {}", src, sec(kGrid), blocks,
         voxel_count(m.fine_res()), m.micro_res);
  if (mlps > voxel_count(m.coarse_res()))
    fail("{}: {}: MLP count {} exceeds the {} coarse voxels of micro_res {}", src, sec(kGrid), mlps,
         voxel_count(m.coarse_res()), m.micro_res);

  // Which optional forms are present, and whether they are enough.
  const bool has_q4 = spans[kFeaturesQ4].present, has_f32 = spans[kFeaturesF32].present;
  const bool has_arch = spans[kMlpShape].present;
  const bool has_mq8 = spans[kMlpsQ8].present, has_mf32 = spans[kMlpsF32].present;
  if (blocks > 0 && !has_q4 && !has_f32)
    fail("{}: the model has {} feature blocks but neither {} nor {}", src, blocks, sec(kFeaturesQ4), sec(kFeaturesF32));
  if (mlps > 0 && !has_arch) fail("{}: the model has {} MLPs but no {}", src, mlps, sec(kMlpShape));
  if ((has_mq8 || has_mf32) && !has_arch)
    fail("{}: {} is present without {}", src, sec(has_mq8 ? kMlpsQ8 : kMlpsF32), sec(kMlpShape));
  if (mlps > 0 && !has_mq8 && !has_mf32)
    fail("{}: the model has {} MLPs but neither {} nor {}", src, mlps, sec(kMlpsQ8), sec(kMlpsF32));

  // MLP shape (needed to size the MLP sections).
  if (has_arch) {
    const Span& sp = spans[kMlpShape];
    if (sp.size < kMlpShapeHeadBytes)
      fail("{}: {} is {} bytes, shorter than its {}-byte head", src, sec(kMlpShape), sp.size, kMlpShapeHeadBytes);
    Reader r(sp.p, sp.size, src);
    m.mlp_arch.dir_frequencies = r.i32();
    uint32_t nd = r.u32(), nc = r.u32();
    for (auto [n, net] : {std::pair{nd, "density"}, std::pair{nc, "colour"}})
      if (n < 2 || n > uint32_t(kMaxMlpLayers) + 1)
        fail("{}: {}: the {} net has {} widths, expected 2..{} (1..{} layers)", src, sec(kMlpShape), net, n,
             kMaxMlpLayers + 1, kMaxMlpLayers);
    expect_size(sp, kMlpShape, kMlpShapeHeadBytes + 4 * uint64_t(nd + nc),
                fmt::format("for {} density and {} colour widths", nd, nc), src);
    m.mlp_arch.density_widths.resize(nd);
    m.mlp_arch.color_widths.resize(nc);
    for (int& x : m.mlp_arch.density_widths) x = r.i32();
    for (int& x : m.mlp_arch.color_widths) x = r.i32();
    validate_arch(m.mlp_arch, F, src);
  }

  // Check every remaining section's size before allocating anything for it.
  for (int t = 0; t < kTierCount; ++t)
    expect_size(spans[kOcc0 + t], kOcc0 + t, bitmap_bytes(m.tier_res(Tier(t))),
                fmt::format("for micro_res {}", m.micro_res), src);
  expect_size(spans[kBlockIndex], kBlockIndex, 4 * uint64_t(blocks), fmt::format("for {} blocks", blocks), src);
  expect_size(spans[kMlpIndex], kMlpIndex, 4 * uint64_t(mlps), fmt::format("for {} MLPs", mlps), src);
  if (has_q4)
    expect_size(spans[kFeaturesQ4], kFeaturesQ4, 5 * uint64_t(F) + q4_code_bytes(blocks, F),
                fmt::format("for {} blocks of {} channels", blocks, F), src);
  if (has_f32)
    expect_size(spans[kFeaturesF32], kFeaturesF32, 4 * feature_values(blocks, F),
                fmt::format("for {} blocks of {} channels", blocks, F), src);
  if (has_mq8)
    expect_size(spans[kMlpsQ8], kMlpsQ8, mlps * mlp_q8_record_bytes(m.mlp_arch),
                fmt::format("for {} MLPs of {} bytes", mlps, mlp_q8_record_bytes(m.mlp_arch)), src);
  if (has_mf32)
    expect_size(spans[kMlpsF32], kMlpsF32, mlps * mlp_f32_record_bytes(m.mlp_arch),
                fmt::format("for {} MLPs of {} bytes", mlps, mlp_f32_record_bytes(m.mlp_arch)), src);

  // Decode.
  for (int t = 0; t < kTierCount; ++t) m.occupancy[t] = read_bitmap(spans[kOcc0 + t], m.tier_res(Tier(t)));
  m.block_fine_index = read_index(spans[kBlockIndex]);
  m.mlp_coarse_index = read_index(spans[kMlpIndex]);
  if (has_q4) {
    Reader r(spans[kFeaturesQ4].p, spans[kFeaturesQ4].size, src);
    m.feature_quant.scale = read_floats(r, size_t(F));
    const uint8_t* zp = r.take(size_t(F));
    m.feature_quant.zero_point.assign(zp, zp + F);
    size_t n = size_t(q4_code_bytes(blocks, F));
    const uint8_t* codes = r.take(n);
    m.features_q4.assign(codes, codes + n);
  }
  if (has_f32) {
    Reader r(spans[kFeaturesF32].p, spans[kFeaturesF32].size, src);
    m.features_f32 = read_floats(r, size_t(feature_values(blocks, F)));
  }
  if (has_mq8) {
    Reader r(spans[kMlpsQ8].p, spans[kMlpsQ8].size, src);
    m.mlps_q8.resize(mlps);
    auto read_layer = [&](DenseQ& l) {
      l.in_scale = r.f32();
      l.w_scale = read_floats(r, size_t(l.out));
      l.b = read_floats(r, size_t(l.out));
      const uint8_t* w = r.take(size_t(l.in) * size_t(l.out));
      l.w.resize(size_t(l.in) * size_t(l.out));
      for (size_t i = 0; i < l.w.size(); ++i) l.w[i] = int8_t(w[i]);
    };
    for (MlpQ& q : m.mlps_q8) {
      q.density = read_net<DenseQ>(m.mlp_arch.density_widths, read_layer);
      q.color = read_net<DenseQ>(m.mlp_arch.color_widths, read_layer);
    }
  }
  if (has_mf32) {
    Reader r(spans[kMlpsF32].p, spans[kMlpsF32].size, src);
    m.mlps_f32.resize(mlps);
    auto read_layer = [&](DenseF& l) {
      l.w = read_floats(r, size_t(l.in) * size_t(l.out));
      l.b = read_floats(r, size_t(l.out));
    };
    for (MlpF& f : m.mlps_f32) {
      f.density = read_net<DenseF>(m.mlp_arch.density_widths, read_layer);
      f.color = read_net<DenseF>(m.mlp_arch.color_widths, read_layer);
    }
  }
  if (spans[kMetadata].present)
    m.metadata_json.assign(reinterpret_cast<const char*>(spans[kMetadata].p), spans[kMetadata].size);

  validate_content(m, src);
  m.finalize();
  if (options.check_invariants) {
    std::vector<std::string> bad = m.check_invariants();
    for (const ModelCheck& c : {check_stray_blocks(m), check_stray_mlps(m)})
      if (!c.passed) bad.push_back(c.detail);
    if (!bad.empty()) fail("{}: the model is corrupt: {}", src, fmt::join(bad, "; "));
  }
  return m;
}

SceneModel load_model(const std::filesystem::path& path) { return load_model(path, ModelLoadOptions{}); }

std::vector<uint8_t> read_model_file(const std::filesystem::path& path) {
  const std::string src = path.string();
  InputFile f(path);
  std::vector<uint8_t> bytes(kModelHeaderBytes);
  bytes.resize(f.read(bytes.data(), kModelHeaderBytes));
  if (bytes.size() < sizeof kMagic || !std::equal(kMagic, kMagic + 8, bytes.data()))
    fail("{}: not an edrnr model (the file does not start with the magic \"EDRNRMDL\")", src);
  if (bytes.size() < kModelHeaderBytes)
    fail("{}: truncated: {} bytes, shorter than the {}-byte header", src, bytes.size(), kModelHeaderBytes);
  const uint64_t total = load_u64(bytes.data() + 16);
  if (total > limits::kMaxModelFileBytes)
    fail("{}: the header gives a total size of {} bytes, over the limit of {} bytes for a model", src, total,
         limits::kMaxModelFileBytes);
  if (f.regular_size() >= 0 && uint64_t(f.regular_size()) != total)
    fail("{}: the header gives a total size of {} bytes but there are {} (truncated or padded file)", src, total,
         f.regular_size());
  if (!f.read_rest(bytes, std::max<uint64_t>(total, kModelHeaderBytes)))
    fail("{}: the file goes on past the total size of {} bytes its header gives (padded file)", src, total);
  return bytes;
}

SceneModel load_model(const std::filesystem::path& path, const ModelLoadOptions& options) {
  std::vector<uint8_t> bytes = read_model_file(path);
  return parse_model(bytes.data(), bytes.size(), path.string(), options);
}

void save_model(const std::filesystem::path& path, const SceneModel& model) {
  write_file_atomic(path, serialize_model(model));
}

}  // namespace edrnr
