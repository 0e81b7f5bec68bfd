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

namespace edrnr {
namespace {

constexpr char kMagic[8] = {'E', 'D', 'R', 'N', 'R', 'M', 'D', 'L'};
constexpr size_t kGridBytes = 64;
constexpr size_t kMlpShapeHeadBytes = 12;
constexpr size_t kSectionAlignBytes = 8;

// Section kinds, in the order they are written.
enum Section : int {
  kGrid,
  kOcc0,  // coarse; kOcc0 + Tier gives the tier's bitmap
  kOcc1,
  kOcc2,
  kOcc3,
  kBlockIndex,
  kMlpIndex,
  kFeaturesQ4,
  kFeaturesF32,
  kMlpShape,
  kMlpsQ8,
  kMlpsF32,
  kMetadata,
  kSectionKinds
};

struct SectionInfo {
  char tag[5];
  const char* what;
  bool required;
};

constexpr SectionInfo kSectionInfo[kSectionKinds] = {
    {"GRID", "grid", true},           {"OCC0", "coarse occupancy", true}, {"OCC1", "fine occupancy", true},
    {"OCC2", "leaf occupancy", true}, {"OCC3", "micro occupancy", true},  {"BIDX", "block index", true},
    {"MIDX", "MLP index", true},      {"FEQ4", "INT4 features", false},   {"FE32", "float features", false},
    {"MARC", "MLP shape", false},     {"MLQ8", "INT8 MLPs", false},       {"ML32", "float MLPs", false},
    {"META", "metadata", false},
};

std::string sec(int s) { return fmt::format("section {} ({})", kSectionInfo[s].tag, kSectionInfo[s].what); }

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

// ---- sizes, all derived from validated small numbers, in 64 bits ----

uint64_t voxel_count(int res) { return uint64_t(res) * uint64_t(res) * uint64_t(res); }
uint64_t bitmap_bytes(int res) { return (voxel_count(res) + 7) / 8; }
uint64_t feature_values(uint64_t blocks, int channels) { return blocks * kBlockVerts * uint64_t(channels); }
uint64_t q4_code_bytes(uint64_t blocks, int channels) { return (feature_values(blocks, channels) + 1) / 2; }

// Bytes of one MLP in section MLQ8: per layer in_scale, w_scale[out], b[out], w[out*in].
uint64_t mlp_q8_record_bytes(const MlpArch& a) {
  uint64_t n = 0;
  for (const auto* widths : {&a.density_widths, &a.color_widths})
    for (size_t i = 1; i < widths->size(); ++i) {
      uint64_t in = uint64_t((*widths)[i - 1]), out = uint64_t((*widths)[i]);
      n += 4 + 8 * out + in * out;
    }
  return n;
}
// Bytes of one MLP in section ML32: per layer w[out*in], b[out], all f32.
uint64_t mlp_f32_record_bytes(const MlpArch& a) {
  uint64_t n = 0;
  for (const auto* widths : {&a.density_widths, &a.color_widths})
    for (size_t i = 1; i < widths->size(); ++i) {
      uint64_t in = uint64_t((*widths)[i - 1]), out = uint64_t((*widths)[i]);
      n += 4 * (in * out + out);
    }
  return n;
}

// ---- validation shared by saving and loading ----

// The deepest nesting of objects and arrays in JSON text (brackets inside
// strings do not count). Tools that print the metadata recurse this deep.
int json_nesting_depth(const std::string& text) {
  int depth = 0, deepest = 0;
  bool in_string = false, escaped = false;
  for (char c : text) {
    if (in_string) {
      if (escaped)
        escaped = false;
      else if (c == '\\')
        escaped = true;
      else if (c == '"')
        in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '{' || c == '[') {
      deepest = std::max(deepest, ++depth);
    } else if (c == '}' || c == ']') {
      --depth;
    }
  }
  return deepest;
}

void validate_grid(const SceneModel& m, const std::string& src) {
  const char* names[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    float lo = m.scene_box.lo[a], hi = m.scene_box.hi[a];
    if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo < hi))
      fail("{}: {}: scene box {} range [{}, {}] is not finite with lo < hi", src, sec(kGrid), names[a], lo, hi);
    lo = m.object_aabb.lo[a], hi = m.object_aabb.hi[a];
    if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo <= hi))
      fail("{}: {}: object AABB {} range [{}, {}] is not finite with lo <= hi", src, sec(kGrid), names[a], lo, hi);
  }
  if (m.micro_res <= 0 || m.micro_res % 32 != 0 || m.micro_res > kMaxMicroRes)
    fail("{}: {}: micro_res {} is not a positive multiple of 32 up to {}", src, sec(kGrid), m.micro_res, kMaxMicroRes);
  if (m.feature_channels < 1 || m.feature_channels > kMaxFeatureChannels)
    fail("{}: {}: feature_channels {} is not in 1..{}", src, sec(kGrid), m.feature_channels, kMaxFeatureChannels);
}

void validate_widths(const std::vector<int>& widths, const char* net, const std::string& src) {
  if (widths.size() < 2 || widths.size() > size_t(kMaxMlpLayers) + 1)
    fail("{}: {}: the {} net has {} widths, expected 2..{} (1..{} layers)", src, sec(kMlpShape), net, widths.size(),
         kMaxMlpLayers + 1, kMaxMlpLayers);
  for (size_t i = 0; i < widths.size(); ++i)
    if (widths[i] < 1 || widths[i] > kMaxMlpWidth)
      fail("{}: {}: the {} net's width {} is {}, expected 1..{}", src, sec(kMlpShape), net, i, widths[i], kMaxMlpWidth);
}

void validate_arch(const MlpArch& a, int feature_channels, const std::string& src) {
  if (a.dir_frequencies < 0 || a.dir_frequencies > kMaxDirFrequencies)
    fail("{}: {}: dir_frequencies {} is not in 0..{}", src, sec(kMlpShape), a.dir_frequencies, kMaxDirFrequencies);
  validate_widths(a.density_widths, "density", src);
  validate_widths(a.color_widths, "colour", src);
  if (a.density_widths.front() != feature_channels)
    fail("{}: {}: the density net's input width {} differs from feature_channels {}", src, sec(kMlpShape),
         a.density_widths.front(), feature_channels);
  int want = a.geo_width() + a.dir_dims();
  if (a.color_widths.front() != want)
    fail("{}: {}: the colour net's input width {} differs from {} (density outputs {} + direction encoding {})", src,
         sec(kMlpShape), a.color_widths.front(), want, a.geo_width(), a.dir_dims());
  if (a.color_widths.back() != 3)
    fail("{}: {}: the colour net's output width {} is not 3 (rgb)", src, sec(kMlpShape), a.color_widths.back());
}

void validate_ascending(const std::vector<uint32_t>& index, uint64_t limit, int section, const char* voxel,
                        const std::string& src) {
  for (size_t i = 0; i < index.size(); ++i) {
    if (index[i] >= limit)
      fail("{}: {}: entry {} is {} voxel {}, but there are only {}", src, sec(section), i, voxel, index[i], limit);
    if (i > 0 && index[i] <= index[i - 1])
      fail("{}: {}: entry {} ({}) is not above entry {} ({}); indices must be strictly ascending", src, sec(section), i,
           index[i], i - 1, index[i - 1]);
  }
}

void validate_finite(const std::vector<float>& v, int section, const char* field, size_t record,
                     const std::string& src) {
  for (size_t i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i])) fail("{}: {}: MLP {}: {} value {} is not finite", src, sec(section), record, field, i);
}

void validate_mlps(const SceneModel& m, const std::string& src) {
  for (size_t k = 0; k < m.mlps_q8.size(); ++k)
    for (const auto* net : {&m.mlps_q8[k].density, &m.mlps_q8[k].color})
      for (const DenseQ& l : *net) {
        if (!std::isfinite(l.in_scale) || !(l.in_scale > 0.f))
          fail("{}: {}: MLP {}: input scale {} is not finite and positive", src, sec(kMlpsQ8), k, l.in_scale);
        validate_finite(l.w_scale, kMlpsQ8, "weight scale", k, src);
        validate_finite(l.b, kMlpsQ8, "bias", k, src);
      }
  for (size_t k = 0; k < m.mlps_f32.size(); ++k)
    for (const auto* net : {&m.mlps_f32[k].density, &m.mlps_f32[k].color})
      for (const DenseF& l : *net) {
        validate_finite(l.w, kMlpsF32, "weight", k, src);
        validate_finite(l.b, kMlpsF32, "bias", k, src);
      }
}

// Checks the values of a model whose array sizes already match its counts.
void validate_content(const SceneModel& m, const std::string& src) {
  for (int t = 0; t < kTierCount; ++t) {
    const Bitmap3& bm = m.occupancy[t];
    size_t used_bits = bm.size() % 64;
    if (used_bits && (bm.words().back() >> used_bits) != 0)
      fail("{}: {}: bits past the last of its {} voxels are set", src, sec(kOcc0 + t), bm.size());
  }
  validate_ascending(m.block_fine_index, voxel_count(m.fine_res()), kBlockIndex, "fine", src);
  validate_ascending(m.mlp_coarse_index, voxel_count(m.coarse_res()), kMlpIndex, "coarse", src);

  const FeatureQuant& fq = m.feature_quant;
  for (size_t c = 0; c < fq.scale.size(); ++c) {
    if (!std::isfinite(fq.scale[c]) || !(fq.scale[c] > 0.f))
      fail("{}: {}: channel {} scale {} is not finite and positive", src, sec(kFeaturesQ4), c, fq.scale[c]);
    if (fq.zero_point[c] > 15)
      fail("{}: {}: channel {} zero point {} is not in 0..15", src, sec(kFeaturesQ4), c, fq.zero_point[c]);
  }
  if (!m.features_q4.empty() && feature_values(m.block_count(), m.feature_channels) % 2 == 1 &&
      (m.features_q4.back() >> 4) != 0)
    fail("{}: {}: the unused high nibble of the last byte is not zero", src, sec(kFeaturesQ4));
  for (size_t i = 0; i < m.features_f32.size(); ++i)
    if (!std::isfinite(m.features_f32[i]))
      fail("{}: {}: value {} (block {}, vertex {}, channel {}) is not finite", src, sec(kFeaturesF32), i,
           i / (kBlockVerts * size_t(m.feature_channels)), i / size_t(m.feature_channels) % kBlockVerts,
           i % size_t(m.feature_channels));

  if (m.mlp_count() > 0 || !(m.mlp_arch == MlpArch{})) validate_arch(m.mlp_arch, m.feature_channels, src);
  validate_mlps(m, src);

  const std::string& meta = m.metadata_json;
  size_t first = meta.find_first_not_of(" \t\r\n");
  if (first == std::string::npos || meta[first] != '{' || !nlohmann::json::accept(meta))
    fail("{}: {}: the text is not a JSON object", src, sec(kMetadata));
  const int depth = json_nesting_depth(meta);
  if (depth > limits::kMaxMetadataDepth)
    fail("{}: {}: the JSON nests {} levels deep, over the limit of {}", src, sec(kMetadata), depth,
         limits::kMaxMetadataDepth);
}

// Checks that array sizes match the counts (the loader builds models this way).
void validate_shapes(const SceneModel& m, const std::string& src) {
  for (int t = 0; t < kTierCount; ++t)
    if (m.occupancy[t].res() != m.tier_res(Tier(t)))
      fail("{}: {} bitmap has resolution {}, expected {} for micro_res {}", src, tier_name(Tier(t)),
           m.occupancy[t].res(), m.tier_res(Tier(t)), m.micro_res);
  const size_t blocks = m.block_count(), F = size_t(m.feature_channels);
  if (!m.features_f32.empty() && m.features_f32.size() != feature_values(blocks, m.feature_channels))
    fail("{}: features_f32 has {} values, expected {} ({} blocks x 125 x {} channels)", src, m.features_f32.size(),
         feature_values(blocks, m.feature_channels), blocks, F);
  if (!m.features_q4.empty() && m.features_q4.size() != q4_code_bytes(blocks, m.feature_channels))
    fail("{}: features_q4 has {} bytes, expected {} for {} blocks of {} channels", src, m.features_q4.size(),
         q4_code_bytes(blocks, m.feature_channels), blocks, F);
  const FeatureQuant& fq = m.feature_quant;
  bool has_quant = !fq.scale.empty() || !fq.zero_point.empty();
  if ((!m.features_q4.empty() || has_quant) && (fq.scale.size() != F || fq.zero_point.size() != F))
    fail("{}: feature_quant has {} scales and {} zero points, expected {} each", src, fq.scale.size(),
         fq.zero_point.size(), F);
  if (has_quant && m.features_q4.empty() && blocks > 0) fail("{}: feature_quant is set but features_q4 is empty", src);
  if (blocks > 0 && m.features_q4.empty() && m.features_f32.empty())
    fail("{}: the model has {} feature blocks but no features (neither INT4 nor float)", src, blocks);

  const size_t mlps = m.mlp_count();
  if (!m.mlps_q8.empty() && m.mlps_q8.size() != mlps)
    fail("{}: mlps_q8 has {} MLPs, expected {} (one per entry of mlp_coarse_index)", src, m.mlps_q8.size(), mlps);
  if (!m.mlps_f32.empty() && m.mlps_f32.size() != mlps)
    fail("{}: mlps_f32 has {} MLPs, expected {} (one per entry of mlp_coarse_index)", src, m.mlps_f32.size(), mlps);
  if (mlps > 0 && m.mlps_q8.empty() && m.mlps_f32.empty())
    fail("{}: the model has {} MLP indices but no MLPs (neither INT8 nor float)", src, mlps);
  if (mlps == 0) return;
  validate_arch(m.mlp_arch, m.feature_channels, src);
  const MlpArch& a = m.mlp_arch;
  auto check_layers = [&](const auto& layers, const std::vector<int>& widths, const char* form, const char* net,
                          size_t k) {
    if (layers.size() != widths.size() - 1)
      fail("{}: {} MLP {}: the {} net has {} layers, expected {}", src, form, k, net, layers.size(), widths.size() - 1);
    for (size_t l = 0; l < layers.size(); ++l) {
      const auto& L = layers[l];
      size_t in = size_t(widths[l]), out = size_t(widths[l + 1]);
      bool ok = L.in == int(in) && L.out == int(out) && L.w.size() == in * out && L.b.size() == out;
      if constexpr (requires { L.w_scale; }) ok = ok && L.w_scale.size() == out;
      if (!ok) fail("{}: {} MLP {}: the {} net's layer {} does not have shape {} -> {}", src, form, k, net, l, in, out);
    }
  };
  for (size_t k = 0; k < m.mlps_q8.size(); ++k) {
    check_layers(m.mlps_q8[k].density, a.density_widths, "INT8", "density", k);
    check_layers(m.mlps_q8[k].color, a.color_widths, "INT8", "colour", k);
  }
  for (size_t k = 0; k < m.mlps_f32.size(); ++k) {
    check_layers(m.mlps_f32[k].density, a.density_widths, "float", "density", k);
    check_layers(m.mlps_f32[k].color, a.color_widths, "float", "colour", k);
  }
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

// ---- model checks ----

// Marks the voxels named by `index` (entries past the bitmap are ignored).
Bitmap3 index_bitmap(const std::vector<uint32_t>& index, int res) {
  Bitmap3 bm(res);
  for (uint32_t i : index)
    if (i < bm.size()) bm.set(size_t(i));
  return bm;
}

// Voxels set in `a` but not in `b`.
size_t count_and_not(const Bitmap3& a, const Bitmap3& b) {
  size_t n = 0;
  for (size_t w = 0; w < a.words().size(); ++w) n += size_t(std::popcount(a.words()[w] & ~b.words()[w]));
  return n;
}

ModelCheck check_stray_blocks(const SceneModel& m) {
  const Bitmap3& fine = m.occupancy[int(Tier::Fine)];
  size_t n = count_and_not(index_bitmap(m.block_fine_index, fine.res()), fine);
  return {"every feature block lies in an occupied fine voxel", n == 0,
          n ? fmt::format("{} feature blocks lie in empty fine voxels", n) : ""};
}

ModelCheck check_stray_mlps(const SceneModel& m) {
  const Bitmap3& coarse = m.occupancy[int(Tier::Coarse)];
  size_t n = count_and_not(index_bitmap(m.mlp_coarse_index, coarse.res()), coarse);
  return {"every MLP lies in an occupied coarse voxel", n == 0,
          n ? fmt::format("{} MLPs lie in empty coarse voxels", n) : ""};
}

}  // namespace

std::vector<ModelCheck> model_checks(const SceneModel& m) {
  std::vector<ModelCheck> out;
  // Each tier against the OR of the tier below, recomputed from the micro tier.
  SceneModel derived;
  derived.micro_res = m.micro_res;
  derived.init_grids();
  derived.occupancy[int(Tier::Micro)] = m.occupancy[int(Tier::Micro)];
  derived.rebuild_upper_tiers();
  for (int t = kTierCount - 2; t >= 0; --t) {
    const Bitmap3& have = m.occupancy[t];
    const Bitmap3& want = derived.occupancy[t];
    ModelCheck c;
    c.name = fmt::format("{} tier is the OR of the {} tier", tier_name(Tier(t)), tier_name(Tier(t + 1)));
    if (have.res() != want.res()) {
      c.passed = false;
      c.detail = fmt::format("{} tier has resolution {}, expected {}", tier_name(Tier(t)), have.res(), want.res());
    } else if (!(have == want)) {
      size_t n = count_and_not(have, want) + count_and_not(want, have);
      c.passed = false;
      c.detail = fmt::format("{} of {} {} voxels differ from the OR of the {} tier", n, have.size(), tier_name(Tier(t)),
                             tier_name(Tier(t + 1)));
    }
    out.push_back(std::move(c));
  }

  const Bitmap3& fine = m.occupancy[int(Tier::Fine)];
  size_t n = count_and_not(fine, index_bitmap(m.block_fine_index, fine.res()));
  out.push_back({"every occupied fine voxel has a feature block", n == 0,
                 n ? fmt::format("{} occupied fine voxels have no feature block", n) : ""});
  out.push_back(check_stray_blocks(m));
  const Bitmap3& coarse = m.occupancy[int(Tier::Coarse)];
  n = count_and_not(coarse, index_bitmap(m.mlp_coarse_index, coarse.res()));
  out.push_back({"every occupied coarse voxel has an MLP", n == 0,
                 n ? fmt::format("{} occupied coarse voxels have no MLP", n) : ""});
  out.push_back(check_stray_mlps(m));

  // A micro voxel is outside the AABB when it shares no volume with it (as in check_invariants).
  const Bitmap3& micro = m.occupancy[int(Tier::Micro)];
  const Vec3f vs = m.micro_voxel_size();
  size_t outside = 0;
  for (size_t w = 0; w < micro.words().size(); ++w)
    for (uint64_t bits = micro.words()[w]; bits; bits &= bits - 1) {
      size_t i = w * 64 + size_t(std::countr_zero(bits));
      int xyz[3] = {int(i % size_t(m.micro_res)), int(i / size_t(m.micro_res) % size_t(m.micro_res)),
                    int(i / (size_t(m.micro_res) * size_t(m.micro_res)))};
      for (int a = 0; a < 3; ++a) {
        float lo = m.scene_box.lo[a] + vs[a] * float(xyz[a]);
        float hi = lo + vs[a];
        if (hi <= m.object_aabb.lo[a] || lo >= m.object_aabb.hi[a]) {
          ++outside;
          break;
        }
      }
    }
  out.push_back({"no occupied micro voxel lies outside the object AABB", outside == 0,
                 outside ? fmt::format("{} occupied micro voxels lie outside the object AABB", outside) : ""});
  return out;
}

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
