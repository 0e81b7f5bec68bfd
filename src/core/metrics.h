#pragma once
// Image quality metrics as the NeRF literature computes them.
#include "core/image.h"

namespace edrnr {

// PSNR in dB over all channels, for images with values in [0, 1]:
// -10 log10(MSE). Infinity for identical images.
double psnr(const Image& a, const Image& b);

// SSIM with an 11x11 Gaussian window (sigma 1.5), K1 = 0.01, K2 = 0.03, data
// range 1, computed per channel over 'valid' windows and averaged.
double ssim(const Image& a, const Image& b);

}  // namespace edrnr
