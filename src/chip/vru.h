#pragma once
// VRU, the volume rendering unit (paper eq. (1)-(2), Section IV-A), in fixed
// point. Per ray it keeps the transmittance T and the accumulated colour C,
// both unsigned Q1.(bits-1), and for each sample (alpha, rgb):
//   w = round(T alpha)        C += round(w rgb)        T = round(T (1 - alpha))
// The ray stops (retires) once T falls below the threshold, exactly when the
// reference renderer stops: T >= transmittance_min is T_code >=
// ceil(transmittance_min 2^(bits-1)). The pixel is C + round(T background).
#include <array>
#include <cstdint>

#include "chip/numerics.h"
#include "chip/rp_buffer.h"

namespace edrnr::chip {

struct VruCounters {
  uint64_t samples = 0;          // samples composited
  uint64_t samples_skipped = 0;  // samples of rays already stopped
  uint64_t rays_terminated = 0;  // rays stopped by the transmittance threshold
};

class Vru {
 public:
  // Throws Error unless 0 <= transmittance_min <= 1 and background in [0, 1].
  Vru(const ChipNumerics& numerics, double transmittance_min, const float background[3]);

  void start(RayState& ray) const;  // T = 1, C = 0
  // Composites one sample onto the ray (nothing if the ray has stopped).
  void composite(RayState& ray, int64_t alpha, const std::array<int64_t, 3>& rgb);
  // The ray's pixel, as floats in [0, 1].
  std::array<float, 3> pixel(const RayState& ray) const;

  int64_t threshold_code() const { return threshold_; }
  const VruCounters& counters() const { return counters_; }

 private:
  ChipNumerics n_;
  int64_t threshold_;
  std::array<int64_t, 3> background_{};
  VruCounters counters_;
};

}  // namespace edrnr::chip
