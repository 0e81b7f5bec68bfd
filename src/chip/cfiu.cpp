#include "chip/cfiu.h"

#include <algorithm>
#include <array>
#include <vector>

#include "chip/cfiu_kernel.h"
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
  // zero_point[c] 2^(3 fb): the zero point times the coefficients' sum.
  for (int c = 0; c < channels_; ++c)
    zero_point_sum_.push_back(int64_t(model.feature_quant.zero_point[size_t(c)]) *
                              (int64_t(1) << (3 * numerics.interp_fraction_bits)));
  // The SIMD kernel's sums and their floor or half-up requantization stay in
  // int32 when the sums are below 15 * 2^(3 fb) <= 15 * 2^27, the zero-point
  // terms no larger, the half below 2^(3 fb - 1) and the clamp bounds fit:
  // |sum - zero| + half < 15.5 * 2^27 < 2^31 (weighted_sum's first branch).
  const int fb = numerics.interp_fraction_bits;
  const int shift = 3 * fb - numerics.interp_feature_frac_bits;
  const fx::Rounding mode = numerics.rounding;
  const int64_t zero_bound = int64_t(15) << (3 * fb);
  finish_in_int32_ = channels_ % 2 == 0 && channels_ <= 64 && 3 * fb <= 27 && shift >= 1 && shift <= 27 &&
                     (mode == fx::Rounding::Floor || mode == fx::Rounding::HalfUp) &&
                     numerics.interp_feature_bits >= 1 && numerics.interp_feature_bits <= 32;
  for (int64_t z : zero_point_sum_) finish_in_int32_ = finish_in_int32_ && z >= -zero_bound && z <= zero_bound;
  if (finish_in_int32_) {
    finish_half_ = mode == fx::Rounding::HalfUp ? int32_t(1) << (shift - 1) : 0;
    for (int c = 0; c < channels_; ++c) (c % 2 ? zero_odd_ : zero_even_).push_back(int32_t(zero_point_sum_[size_t(c)]));
  }
}

void Cfiu::interpolate(uint32_t block, const SampleCoord& s, int32_t* out) {
  read_corners(block, s.local);
  weighted_sum(block, s, out);
}

int Cfiu::read_corners(uint32_t block, const Vec3i& local) {
  const int line = cache_.use(block);
  // Each bank serves its corners; the coefficients are reordered to meet them.
  int conflicts = 0;
  if (cache_.layout().corners_one_per_bank()) {
    for (uint64_t& reads : counters_.bank_reads) ++reads;
  } else {
    const std::array<int, 8> banks = cache_.layout().corner_banks(line, local);
    for (int c = 0; c < 8; ++c) ++counters_.bank_reads[size_t(banks[size_t(c)])];
    conflicts = BankLayout::conflict_cycles(banks);
  }
  ++counters_.samples;
  counters_.corner_reads += 8;
  counters_.fetch_cycles += uint64_t(1 + conflicts);
  counters_.conflict_cycles += uint64_t(conflicts);
  return conflicts;
}

void Cfiu::weighted_sum(uint32_t block, const SampleCoord& s, int32_t* out) const {
  const int fb = numerics_.interp_fraction_bits;
  const int64_t one = int64_t(1) << fb;
  // Corner c = dx | dy << 1 | dz << 2: where its codes start and its
  // trilinear coefficient.
  const size_t F = size_t(channels_);
  std::array<size_t, 8> first{};
  std::array<int64_t, 8> coef{};
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = c >> 1 & 1, dz = c >> 2 & 1;
    const int vertex = block_vertex(s.local.x + dx, s.local.y + dy, s.local.z + dz);
    first[size_t(c)] = (size_t(block) * kBlockVerts + size_t(vertex)) * F;
    coef[size_t(c)] =
        (dx ? s.frac[0] : one - s.frac[0]) * (dy ? s.frac[1] : one - s.frac[1]) * (dz ? s.frac[2] : one - s.frac[2]);
  }
  // The coefficients sum to one (2^(3 fb)) exactly, so
  //   sum coef (code - zp) = sum coef code - zp 2^(3 fb),
  // the same integer.
  const int64_t coef_sum = int64_t(1) << (3 * fb);
  const int shift = 3 * fb - numerics_.interp_feature_frac_bits;
  const uint8_t* q4 = model_.features_q4.data();  // two codes a byte, the even index low
  // Whole bytes per corner and sums that fit int32 (15 * 2^(3 fb) < 2^31):
  // the SIMD kernel, channels in pairs, then the same rounding per channel.
  constexpr size_t kKernelChannels = 64;
  const bool in_voxel =
      s.frac[0] >= 0 && s.frac[0] <= one && s.frac[1] >= 0 && s.frac[1] <= one && s.frac[2] >= 0 && s.frac[2] <= one;
  if (F % 2 == 0 && F <= kKernelChannels && 3 * fb <= 27 && in_voxel) {
    std::array<size_t, 8> byte_first;
    std::array<int32_t, 8> coef32;
    for (size_t i = 0; i < 8; ++i) {
      byte_first[i] = first[i] >> 1;
      coef32[i] = int32_t(coef[i]);
    }
    if (finish_in_int32_) {
      cfiu_corner_features(q4, byte_first.data(), coef32.data(), F / 2, zero_even_.data(), zero_odd_.data(),
                           finish_half_, shift, int32_t(fx::min_signed(numerics_.interp_feature_bits)),
                           int32_t(fx::max_signed(numerics_.interp_feature_bits)), out);
      return;
    }
    std::array<int32_t, kKernelChannels / 2> even, odd;
    cfiu_corner_sums(q4, byte_first.data(), coef32.data(), F / 2, even.data(), odd.data());
    const fx::Rounding mode = numerics_.rounding;
    if (shift >= 1 && shift <= 62 && (mode == fx::Rounding::Floor || mode == fx::Rounding::HalfUp)) {
      // fx::shift_right_round in these modes: floor((sum + half) / 2^shift).
      const int64_t half = mode == fx::Rounding::HalfUp ? int64_t(1) << (shift - 1) : 0;
      const int64_t lo = fx::min_signed(numerics_.interp_feature_bits),
                    hi = fx::max_signed(numerics_.interp_feature_bits);
      for (size_t ch = 0; ch < F; ++ch) {
        const int64_t raw = (ch & 1) ? odd[ch >> 1] : even[ch >> 1];
        const int64_t r = (raw - zero_point_sum_[ch] + half) >> shift;
        out[ch] = int32_t(r < lo ? lo : (r > hi ? hi : r));
      }
      return;
    }
    for (size_t ch = 0; ch < F; ++ch) {
      const int64_t raw = (ch & 1) ? odd[ch >> 1] : even[ch >> 1];
      const int64_t sum = raw - zero_point_sum_[ch];
      out[ch] = int32_t(fx::saturate(fx::shift_right_round(sum, shift, mode), numerics_.interp_feature_bits));
    }
    return;
  }
  // Corner by corner, two channels a byte where the codes pair up; integer
  // sums, so the order does not change them.
  constexpr size_t kLocalChannels = 64;
  std::array<int64_t, kLocalChannels> local;
  std::vector<int64_t> heap;
  int64_t* sums = local.data();
  if (F > kLocalChannels) {
    heap.assign(F, 0);
    sums = heap.data();
  } else {
    std::fill_n(sums, F, int64_t(0));
  }
  for (size_t i = 0; i < 8; ++i) {
    const int64_t w = coef[i];
    size_t at = first[i], ch = 0;
    if (at & 1 && F > 0) {
      sums[0] += w * int64_t(q4[at >> 1] >> 4);
      ++at;
      ch = 1;
    }
    const uint8_t* p = q4 + (at >> 1);
    for (; ch + 1 < F; ch += 2, ++p) {
      sums[ch] += w * int64_t(*p & 15);
      sums[ch + 1] += w * int64_t(*p >> 4);
    }
    if (ch < F) sums[ch] += w * int64_t(*p & 15);
  }
  for (size_t ch = 0; ch < F; ++ch) {
    const int64_t sum = sums[ch] - int64_t(model_.feature_quant.zero_point[ch]) * coef_sum;
    out[ch] =
        int32_t(fx::saturate(fx::shift_right_round(sum, shift, numerics_.rounding), numerics_.interp_feature_bits));
  }
}

}  // namespace edrnr::chip
