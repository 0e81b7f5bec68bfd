// Checks of a scene model that saving and loading both make, and the model
// checks `edrnr inspect` prints (model_io.h).
#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/limits.h"
#include "model/model_format.h"
#include "model/model_io.h"

namespace edrnr {
namespace {
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

}  // namespace

namespace model_format {

// The deepest nesting of objects and arrays in JSON text (brackets inside
// strings do not count). Tools that print the metadata recurse this deep.
static int json_nesting_depth(const std::string& text) {
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

static void validate_widths(const std::vector<int>& widths, const char* net, const std::string& src) {
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

static void validate_mlps(const SceneModel& m, const std::string& src) {
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

}  // namespace model_format

std::vector<ModelCheck> model_checks(const SceneModel& m) {
  using namespace model_format;
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

}  // namespace edrnr
