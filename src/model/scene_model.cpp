#include "model/scene_model.h"

#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <cmath>

#include "core/error.h"

namespace edrnr {

const char* tier_name(Tier t) {
  switch (t) {
    case Tier::Coarse: return "coarse";
    case Tier::Fine: return "fine";
    case Tier::Leaf: return "leaf";
    case Tier::Micro: return "micro";
  }
  return "?";
}

size_t Bitmap3::count() const {
  size_t n = 0;
  for (uint64_t w : words_) n += size_t(std::popcount(w));
  return n;
}

size_t MlpArch::weight_count() const {
  size_t n = 0;
  for (size_t i = 1; i < density_widths.size(); ++i) n += size_t(density_widths[i - 1]) * density_widths[i];
  for (size_t i = 1; i < color_widths.size(); ++i) n += size_t(color_widths[i - 1]) * color_widths[i];
  return n;
}

size_t MlpArch::bias_count() const {
  size_t n = 0;
  for (size_t i = 1; i < density_widths.size(); ++i) n += size_t(density_widths[i]);
  for (size_t i = 1; i < color_widths.size(); ++i) n += size_t(color_widths[i]);
  return n;
}

int SceneModel::tier_res(Tier t) const {
  switch (t) {
    case Tier::Coarse: return coarse_res();
    case Tier::Fine: return fine_res();
    case Tier::Leaf: return leaf_res();
    case Tier::Micro: return micro_res;
  }
  return 0;
}

void SceneModel::init_grids() {
  if (micro_res <= 0 || micro_res % 32) fail("micro resolution {} is not a positive multiple of 32", micro_res);
  for (int t = 0; t < kTierCount; ++t) occupancy[t] = Bitmap3(tier_res(Tier(t)));
}

void SceneModel::rebuild_upper_tiers() {
  // Each tier from the one below it: leaf from micro, fine from leaf, coarse from fine.
  const int factors[3] = {8, 2, 2};  // coarse<-fine, fine<-leaf, leaf<-micro
  for (int t = kTierCount - 2; t >= 0; --t) {
    const Bitmap3& lo = occupancy[t + 1];
    Bitmap3 hi(tier_res(Tier(t)));
    int f = factors[t];
    int r = lo.res();
    for (int z = 0; z < r; ++z)
      for (int y = 0; y < r; ++y)
        for (int x = 0; x < r; ++x)
          if (lo.get(x, y, z)) hi.set(x / f, y / f, z / f);
    occupancy[t] = std::move(hi);
  }
}

void SceneModel::finalize() {
  fine_to_block.assign(size_t(fine_res()) * fine_res() * fine_res(), -1);
  for (size_t b = 0; b < block_fine_index.size(); ++b) fine_to_block[block_fine_index[b]] = int32_t(b);
  coarse_to_mlp.assign(size_t(coarse_res()) * coarse_res() * coarse_res(), -1);
  for (size_t m = 0; m < mlp_coarse_index.size(); ++m) coarse_to_mlp[mlp_coarse_index[m]] = int32_t(m);
}

uint8_t SceneModel::feature_q(size_t block, int vertex, int channel) const {
  size_t i = (block * kBlockVerts + size_t(vertex)) * size_t(feature_channels) + size_t(channel);
  uint8_t byte = features_q4[i >> 1];
  return (i & 1) ? uint8_t(byte >> 4) : uint8_t(byte & 15);
}

float SceneModel::feature(size_t block, int vertex, int channel) const {
  if (!features_f32.empty())
    return features_f32[(block * kBlockVerts + size_t(vertex)) * size_t(feature_channels) + size_t(channel)];
  int q = feature_q(block, vertex, channel);
  return float(q - int(feature_quant.zero_point[size_t(channel)])) * feature_quant.scale[size_t(channel)];
}

void SceneModel::quantize_features() {
  const size_t F = size_t(feature_channels);
  const size_t n = block_count() * kBlockVerts;
  if (features_f32.size() != n * F) fail("quantize_features: float features missing");
  feature_quant.scale.assign(F, 1.f);
  feature_quant.zero_point.assign(F, 0);
  for (size_t c = 0; c < F; ++c) {
    float lo = 0.f, hi = 0.f;  // the range always includes 0
    for (size_t v = 0; v < n; ++v) {
      lo = std::min(lo, features_f32[v * F + c]);
      hi = std::max(hi, features_f32[v * F + c]);
    }
    float scale = (hi - lo) / 15.f;
    if (!(scale > 0.f)) scale = 1.f;
    int zp = int(std::lround(-lo / scale));
    feature_quant.scale[c] = scale;
    feature_quant.zero_point[c] = uint8_t(std::clamp(zp, 0, 15));
  }
  features_q4.assign((n * F + 1) / 2, 0);
  for (size_t v = 0; v < n; ++v)
    for (size_t c = 0; c < F; ++c) {
      float x = features_f32[v * F + c] / feature_quant.scale[c];
      int q = std::clamp(int(std::lround(x)) + int(feature_quant.zero_point[c]), 0, 15);
      size_t i = v * F + c;
      features_q4[i >> 1] |= uint8_t((i & 1) ? q << 4 : q);
    }
}

void SceneModel::dequantize_features() {
  const size_t F = size_t(feature_channels);
  const size_t n = block_count() * kBlockVerts;
  std::vector<float> out(n * F);
  std::vector<float> saved;
  saved.swap(features_f32);  // so feature() reads the INT4 codes
  for (size_t v = 0; v < n; ++v)
    for (size_t c = 0; c < F; ++c) out[v * F + c] = feature(v / kBlockVerts, int(v % kBlockVerts), int(c));
  features_f32 = std::move(out);
}

void SceneModel::check_structure() const {
  if (micro_res <= 0 || micro_res % 32) fail("model micro resolution {} is not a positive multiple of 32", micro_res);
  for (int a = 0; a < 3; ++a)
    if (!(scene_box.size()[a] > 0.f)) fail("model scene box is empty along axis {}", a);
  for (int t = 0; t < kTierCount; ++t)
    if (occupancy[t].res() != tier_res(Tier(t)))
      fail("model {} bitmap has resolution {}, expected {}", tier_name(Tier(t)), occupancy[t].res(),
           tier_res(Tier(t)));
  const size_t fr = size_t(fine_res()), cr = size_t(coarse_res());
  if (fine_to_block.size() != fr * fr * fr || coarse_to_mlp.size() != cr * cr * cr)
    fail("model lookups are missing (call finalize() after building or editing a model)");
}

std::vector<std::string> SceneModel::check_invariants() const {
  std::vector<std::string> bad;
  // Each tier is the OR of the tier below.
  SceneModel derived;
  derived.micro_res = micro_res;
  derived.init_grids();
  derived.occupancy[int(Tier::Micro)] = occupancy[int(Tier::Micro)];
  derived.rebuild_upper_tiers();
  for (int t = 0; t < kTierCount - 1; ++t)
    if (!(derived.occupancy[t] == occupancy[t]))
      bad.push_back(fmt::format("{} tier is not the OR of the {} tier", tier_name(Tier(t)), tier_name(Tier(t + 1))));
  // Every occupied fine voxel has a block, every occupied CV an MLP.
  const Bitmap3& fine = occupancy[int(Tier::Fine)];
  size_t missing_blocks = 0;
  for (size_t i = 0; i < fine.size(); ++i)
    if (fine.get(i) && (fine_to_block.size() != fine.size() || fine_to_block[i] < 0)) ++missing_blocks;
  if (missing_blocks) bad.push_back(fmt::format("{} occupied fine voxels have no feature block", missing_blocks));
  const Bitmap3& coarse = occupancy[int(Tier::Coarse)];
  size_t missing_mlps = 0;
  for (size_t i = 0; i < coarse.size(); ++i)
    if (coarse.get(i) && (coarse_to_mlp.size() != coarse.size() || coarse_to_mlp[i] < 0)) ++missing_mlps;
  if (missing_mlps) bad.push_back(fmt::format("{} occupied coarse voxels have no MLP", missing_mlps));
  // No occupied micro voxel outside the object AABB.
  const Bitmap3& micro = occupancy[int(Tier::Micro)];
  Vec3f vs = micro_voxel_size();
  size_t outside = 0;
  for (int z = 0; z < micro_res; ++z)
    for (int y = 0; y < micro_res; ++y)
      for (int x = 0; x < micro_res; ++x) {
        if (!micro.get(x, y, z)) continue;
        Vec3f lo = scene_box.lo + vs * Vec3f{float(x), float(y), float(z)};
        Vec3f hi = lo + vs;
        for (int a = 0; a < 3; ++a)
          if (hi[a] <= object_aabb.lo[a] || lo[a] >= object_aabb.hi[a]) {
            ++outside;
            break;
          }
      }
  if (outside) bad.push_back(fmt::format("{} occupied micro voxels lie outside the object AABB", outside));
  return bad;
}

}  // namespace edrnr
