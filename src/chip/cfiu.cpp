#include "chip/cfiu.h"

#include "core/error.h"

namespace edrnr::chip {

Cfiu::Cfiu(const SceneModel& model, const ChipNumerics& numerics, const FeatureCacheConfig& cache)
    : model_(model), numerics_(numerics), cache_(cache), channels_(model.feature_channels) {
  const size_t values = model.block_count() * kBlockVerts * size_t(channels_);
  if (model.block_count() > 0 && model.features_q4.size() != (values + 1) / 2)
    fail("model has no INT4 features for its {} blocks (the chip reads only the quantized form)", model.block_count());
  if (model.feature_quant.zero_point.size() != size_t(channels_))
    fail("model feature quantization has {} zero points for {} channels", model.feature_quant.zero_point.size(),
         channels_);
}

void Cfiu::interpolate(uint32_t block, const SampleCoord& s, int32_t* out) {
  read_corners(block, s);
  weighted_sum(block, s, out);
}

int Cfiu::read_corners(uint32_t block, const SampleCoord& s) {
  const int line = cache_.use(block);
  // Each bank serves its corners; the coefficients are reordered to meet them.
  const std::array<int, 8> banks = cache_.layout().corner_banks(line, s.local);
  for (int c = 0; c < 8; ++c) ++counters_.bank_reads[size_t(banks[size_t(c)])];
  const int conflicts = BankLayout::conflict_cycles(banks);
  ++counters_.samples;
  counters_.corner_reads += 8;
  counters_.fetch_cycles += uint64_t(1 + conflicts);
  counters_.conflict_cycles += uint64_t(conflicts);
  return conflicts;
}

void Cfiu::weighted_sum(uint32_t block, const SampleCoord& s, int32_t* out) const {
  const int fb = numerics_.interp_fraction_bits;
  const int64_t one = int64_t(1) << fb;
  // Corner c = dx | dy << 1 | dz << 2: its vertex and trilinear coefficient.
  std::array<int, 8> vertex{};
  std::array<int64_t, 8> coef{};
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = c >> 1 & 1, dz = c >> 2 & 1;
    vertex[size_t(c)] = block_vertex(s.local.x + dx, s.local.y + dy, s.local.z + dz);
    coef[size_t(c)] =
        (dx ? s.frac[0] : one - s.frac[0]) * (dy ? s.frac[1] : one - s.frac[1]) * (dz ? s.frac[2] : one - s.frac[2]);
  }
  const int shift = 3 * fb - numerics_.interp_feature_frac_bits;
  for (int ch = 0; ch < channels_; ++ch) {
    const int zp = model_.feature_quant.zero_point[size_t(ch)];
    int64_t sum = 0;
    for (int i = 0; i < 8; ++i) sum += coef[size_t(i)] * (int64_t(model_.feature_q(block, vertex[size_t(i)], ch)) - zp);
    out[ch] =
        int32_t(fx::saturate(fx::shift_right_round(sum, shift, numerics_.rounding), numerics_.interp_feature_bits));
  }
}

}  // namespace edrnr::chip
