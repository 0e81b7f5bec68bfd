#include "chip/vru.h"

#include <cmath>

#include "core/error.h"

namespace edrnr::chip {

Vru::Vru(const ChipNumerics& numerics, double transmittance_min, const float background[3]) : n_(numerics) {
  if (!(transmittance_min >= 0.0 && transmittance_min <= 1.0))
    fail("transmittance threshold {} is outside [0, 1]", transmittance_min);
  const int tb = n_.transmittance_bits;
  threshold_ = int64_t(std::ceil(std::ldexp(transmittance_min, tb - 1)));
  for (int c = 0; c < 3; ++c) {
    if (!(background[c] >= 0.f && background[c] <= 1.f))
      fail("background component {} = {} is outside [0, 1]", c, background[c]);
    background_[size_t(c)] = fx::to_fixed_unsigned(background[c], n_.color_bits - 1, n_.color_bits, n_.rounding);
  }
}

void Vru::start(RayState& ray) const {
  ray.transmittance = unit_one(n_.transmittance_bits);
  ray.color = {0, 0, 0};
  ray.terminated = ray.transmittance < threshold_;
}

void Vru::composite(RayState& ray, int64_t alpha, const std::array<int64_t, 3>& rgb) {
  if (ray.terminated) {
    ++counters_.samples_skipped;
    return;
  }
  ++counters_.samples;
  const int ab = n_.alpha_bits - 1, cb = n_.color_bits - 1, tb = n_.transmittance_bits - 1;
  const int64_t one_alpha = unit_one(n_.alpha_bits);
  // w = T alpha in colour units; C += w rgb; T *= 1 - alpha.
  const int64_t w = fx::shift_right_round(ray.transmittance * alpha, ab + tb - cb, n_.rounding);
  for (int c = 0; c < 3; ++c) {
    const int64_t add = fx::shift_right_round(w * rgb[size_t(c)], cb, n_.rounding);
    ray.color[size_t(c)] = fx::saturate_unsigned(ray.color[size_t(c)] + add, n_.color_bits);
  }
  ray.transmittance = fx::shift_right_round(ray.transmittance * (one_alpha - alpha), ab, n_.rounding);
  if (ray.transmittance < threshold_) {
    ray.terminated = true;
    ++counters_.rays_terminated;
  }
}

std::array<float, 3> Vru::pixel(const RayState& ray) const {
  const int cb = n_.color_bits - 1, tb = n_.transmittance_bits - 1;
  std::array<float, 3> out{};
  for (int c = 0; c < 3; ++c) {
    const int64_t bg = fx::shift_right_round(ray.transmittance * background_[size_t(c)], tb, n_.rounding);
    const int64_t v =
        std::min(fx::saturate_unsigned(ray.color[size_t(c)] + bg, n_.color_bits), unit_one(n_.color_bits));
    out[size_t(c)] = float(fx::from_fixed(v, cb));
  }
  return out;
}

}  // namespace edrnr::chip
