#pragma once
// Adam (Kingma & Ba) with bias correction, applied one parameter at a time so
// that callers can update only the parameters a step touched ("lazy" Adam for
// the sparse feature grids).
#include <cmath>
#include <cstdint>

namespace edrnr::train {

struct AdamSettings {
  float beta1 = 0.9f;
  float beta2 = 0.99f;
  float eps = 1e-15f;
};

// The per-step constants: learning rate and the bias corrections of step t (t >= 1).
struct AdamStep {
  float lr = 0.f;
  float c1 = 1.f, c2 = 1.f;  // 1 / (1 - beta^t)
  float beta1 = 0.9f, beta2 = 0.99f, eps = 1e-15f;

  AdamStep() = default;
  AdamStep(const AdamSettings& s, float lr_, int64_t t)
      : lr(lr_),
        c1(float(1.0 / (1.0 - std::pow(double(s.beta1), double(t))))),
        c2(float(1.0 / (1.0 - std::pow(double(s.beta2), double(t))))),
        beta1(s.beta1),
        beta2(s.beta2),
        eps(s.eps) {}

  void update(float& p, float& m, float& v, float g) const {
    m = beta1 * m + (1.f - beta1) * g;
    v = beta2 * v + (1.f - beta2) * (g * g);
    p -= lr * (m * c1) / (std::sqrt(v * c2) + eps);
  }
};

}  // namespace edrnr::train
