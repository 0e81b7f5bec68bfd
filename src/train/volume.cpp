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

namespace {

// Weights w_i = T_i alpha_i and transmittances T_0..T_n of a ray.
void ray_weights(const float* raw, int n, float delta, std::vector<float>& w, std::vector<float>& T) {
  w.resize(size_t(n));
  T.resize(size_t(n) + 1);
  T[0] = 1.f;
  for (int i = 0; i < n; ++i) {
    const float tau = sigma_of_raw(raw[i]) * delta;
    w[size_t(i)] = T[size_t(i)] * alpha_of_tau(tau);
    T[size_t(i) + 1] = T[size_t(i)] * std::exp(-tau);
  }
}

}  // namespace

double distortion_loss(const float* raw, const float* t, int n, float delta, float s) {
  std::vector<float> w, T;
  ray_weights(raw, n, delta, w, T);
  double L = 0;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) L += double(w[size_t(i)]) * w[size_t(j)] * std::fabs(double(t[i]) - t[j]);
    L += double(w[size_t(i)]) * w[size_t(i)] * s / 3.0;
  }
  return L;
}

void distortion_backward(const float* raw, const float* t, int n, float delta, float s, float scale, float* d_raw) {
  if (n <= 0) return;
  std::vector<float> w, T;
  ray_weights(raw, n, delta, w, T);
  // dL/dw_i = 2 sum_j w_j |t_i - t_j| + 2/3 w_i s; with t sorted the sum is
  // t_i W_before - WT_before + WT_after - t_i W_after (prefix sums).
  double W_all = 0, WT_all = 0;
  for (int i = 0; i < n; ++i) {
    W_all += w[size_t(i)];
    WT_all += double(w[size_t(i)]) * t[i];
  }
  std::vector<double> g(static_cast<size_t>(n));
  double W_before = 0, WT_before = 0;
  for (int i = 0; i < n; ++i) {
    const double wi = w[size_t(i)], ti = t[i];
    const double W_after = W_all - W_before - wi, WT_after = WT_all - WT_before - wi * ti;
    g[size_t(i)] = 2.0 * (ti * W_before - WT_before + WT_after - ti * W_after) + 2.0 / 3.0 * wi * s;
    W_before += wi;
    WT_before += wi * ti;
  }
  // w_i = T_i alpha_i with T_i = exp(-sum_{k<i} tau_k): dw_i/dtau_k = -w_i
  // (k < i), T_{i+1} (k = i), 0 (k > i). So dL/dtau_k = g_k T_{k+1} - sum_{i>k} g_i w_i.
  double after = 0;
  for (int k = n - 1; k >= 0; --k) {
    const double d_tau = g[size_t(k)] * T[size_t(k) + 1] - after;
    after += g[size_t(k)] * w[size_t(k)];
    const bool inside = raw[k] >= kRawSigmaMin && raw[k] <= kRawSigmaMax;
    if (inside) d_raw[k] += scale * float(d_tau * double(delta) * double(sigma_of_raw(raw[k])));
  }
}

}  // namespace edrnr::train
