#pragma once
// Adam (Kingma & Ba) with bias correction, applied one parameter at a time so
// that callers can update only the parameters a step touched ("lazy" Adam for
// the sparse feature grids).
#include <cmath>
#include <cstdint>
#if defined(__SSE2__)
#include <immintrin.h>
#endif

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

  // Four consecutive parameters at once, then zeroes their gradients. The
  // same arithmetic as update(), element by element (IEEE square root and
  // division are correctly rounded in both forms).
  void update4(float* p, float* m, float* v, float* g) const {
#if defined(__SSE2__)
    const __m128 G = _mm_loadu_ps(g);
    __m128 M = _mm_add_ps(_mm_mul_ps(_mm_set1_ps(beta1), _mm_loadu_ps(m)), _mm_mul_ps(_mm_set1_ps(1.f - beta1), G));
    __m128 V = _mm_add_ps(_mm_mul_ps(_mm_set1_ps(beta2), _mm_loadu_ps(v)),
                          _mm_mul_ps(_mm_set1_ps(1.f - beta2), _mm_mul_ps(G, G)));
    const __m128 num = _mm_mul_ps(_mm_set1_ps(lr), _mm_mul_ps(M, _mm_set1_ps(c1)));
    const __m128 den = _mm_add_ps(_mm_sqrt_ps(_mm_mul_ps(V, _mm_set1_ps(c2))), _mm_set1_ps(eps));
    _mm_storeu_ps(p, _mm_sub_ps(_mm_loadu_ps(p), _mm_div_ps(num, den)));
    _mm_storeu_ps(m, M);
    _mm_storeu_ps(v, V);
    _mm_storeu_ps(g, _mm_setzero_ps());
#else
    for (int k = 0; k < 4; ++k) {
      update(p[k], m[k], v[k], g[k]);
      g[k] = 0.f;
    }
#endif
  }
};

}  // namespace edrnr::train
