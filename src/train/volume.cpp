#include "train/volume.h"

#include <vector>

namespace edrnr::train {

int march_transmittance(const float* raw, int n, float delta, float t_min, float t_in, float* t_out) {
  float T = t_in;
  int i = 0;
  while (i < n) {
    T *= std::exp(-(sigma_of_raw(raw[i]) * delta));
    ++i;
    if (T < t_min) break;
  }
  *t_out = T;
  return i;
}

CompositeResult composite(const float* raw, const float* rgb, int n, float delta, const float background[3]) {
  CompositeResult r;
  float T = 1.f;
  for (int i = 0; i < n; ++i) {
    const float tau = sigma_of_raw(raw[i]) * delta;
    const float w = T * alpha_of_tau(tau);
    for (int c = 0; c < 3; ++c) r.rgb[c] += w * rgb[3 * i + c];
    T *= std::exp(-tau);
  }
  for (int c = 0; c < 3; ++c) r.rgb[c] += T * background[c];
  r.t_final = T;
  return r;
}

void composite_backward(const float* raw, const float* rgb, int n, float delta, const float background[3],
                        const float d_pixel[3], float* d_raw, float* d_rgb) {
  // dC/dsigma_i = delta (T_{i+1} c_i - S_i), S_i = sum_{k>i} w_k c_k + T_final bg.
  // Walk backwards keeping S; T_{i+1} is recovered from the forward values.
  std::vector<float> T(static_cast<size_t>(n) + 1), a(static_cast<size_t>(n));
  T[0] = 1.f;
  for (int i = 0; i < n; ++i) {
    const float tau = sigma_of_raw(raw[i]) * delta;
    a[size_t(i)] = alpha_of_tau(tau);
    T[size_t(i) + 1] = T[size_t(i)] * std::exp(-tau);
  }
  float S[3];
  for (int c = 0; c < 3; ++c) S[c] = T[size_t(n)] * background[c];
  for (int i = n - 1; i >= 0; --i) {
    const float w = T[size_t(i)] * a[size_t(i)];
    float ds = 0.f;
    for (int c = 0; c < 3; ++c) {
      d_rgb[3 * i + c] = w * d_pixel[c];
      ds += d_pixel[c] * (T[size_t(i) + 1] * rgb[3 * i + c] - S[c]);
    }
    const bool inside = raw[i] >= kRawSigmaMin && raw[i] <= kRawSigmaMax;
    d_raw[i] = inside ? delta * ds * sigma_of_raw(raw[i]) : 0.f;
    for (int c = 0; c < 3; ++c) S[c] += w * rgb[3 * i + c];
  }
}

}  // namespace edrnr::train
