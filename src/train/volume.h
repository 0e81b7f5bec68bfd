#pragma once
// Volume rendering of one ray, eq. (1)-(2), exactly as the reference renderer
// composites (render/reference.cpp): sigma = exp(clamp(raw)), tau = sigma
// delta, alpha = -expm1(-tau), T_{i+1} = T_i exp(-tau); marching stops after
// the sample that brings T below transmittance_min; pixel = sum T_i alpha_i
// c_i + T_final background. And its exact gradient.
#include <cmath>

#include "model/mlp.h"

namespace edrnr::train {

inline float sigma_of_raw(float raw) { return std::exp(std::clamp(raw, kRawSigmaMin, kRawSigmaMax)); }
inline float alpha_of_tau(float tau) { return -std::expm1(-tau); }

// Transmittance after n samples of raw density starting from T = t_in. Returns
// the number of samples used: the index of the first sample after which T <
// t_min, plus one, or n if T stays above. *t_out receives T after them.
int march_transmittance(const float* raw, int n, float delta, float t_min, float t_in, float* t_out);

struct CompositeResult {
  float rgb[3] = {0, 0, 0};
  float t_final = 1.f;
};

// Forward: n samples (raw density, rgb in [0, 1], 3 per sample) in ray order,
// already truncated at termination.
CompositeResult composite(const float* raw, const float* rgb, int n, float delta, const float background[3]);

// Backward: given dL/dpixel, writes dL/draw (n) and dL/drgb (3 n). raw values
// outside [kRawSigmaMin, kRawSigmaMax] get zero gradient (the clamp).
void composite_backward(const float* raw, const float* rgb, int n, float delta, const float background[3],
                        const float d_pixel[3], float* d_raw, float* d_rgb);

}  // namespace edrnr::train
