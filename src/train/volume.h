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

// The distortion loss of one ray (Barron et al., mip-NeRF 360):
//   L = sum_i sum_j w_i w_j |t_i - t_j| + 1/3 sum_i w_i^2 s
// over its n samples (weights w_i = T_i alpha_i as composite() makes them),
// t_i the samples' positions along the ray in increasing order and s the
// length of the interval each sample stands for, in any one unit. It pulls a
// ray's weight together into one short stretch (a surface) and away from
// floaters spread along the ray.
double distortion_loss(const float* raw, const float* t, int n, float delta, float s);
// Adds scale * dL/draw of distortion_loss to d_raw (n), with the same clamp
// rule as composite_backward.
void distortion_backward(const float* raw, const float* t, int n, float delta, float s, float scale, float* d_raw);

}  // namespace edrnr::train
