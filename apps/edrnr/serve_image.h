#pragma once
// Images as `edrnr serve` sends them: 8-bit RGBA pixels for a canvas, or PNG.
#include <string>

#include "core/image.h"

namespace edrnr::serve {

// width * height * 4 bytes, top row first; each channel clamped to [0, 1] and
// rounded to nearest, alpha 255 (as write_png rounds).
std::string to_rgba8(const Image& img);

// An 8-bit RGB PNG of a 3-channel image, in memory. Throws Error if encoding fails.
std::string encode_png(const Image& img);

}  // namespace edrnr::serve
