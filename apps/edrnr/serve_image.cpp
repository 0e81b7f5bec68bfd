#include "serve_image.h"

#include <spng.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

#include "core/error.h"

namespace edrnr::serve {

namespace {

uint8_t to_byte(float v) { return uint8_t(std::lround(std::clamp(v, 0.f, 1.f) * 255.f)); }

struct CtxDeleter {
  void operator()(spng_ctx* c) const { spng_ctx_free(c); }
};

}  // namespace

std::string to_rgba8(const Image& img) {
  std::string out(size_t(img.width) * img.height * 4, '\xff');
  const size_t pixels = size_t(img.width) * img.height;
  const int c = img.channels;
  for (size_t i = 0; i < pixels; ++i)
    for (int k = 0; k < std::min(c, 3); ++k) out[i * 4 + k] = char(to_byte(img.data[i * c + k]));
  return out;
}

std::string encode_png(const Image& img) {
  if (img.channels != 3) fail("PNG encoding: a 3-channel image is expected, got {} channels", img.channels);
  std::vector<uint8_t> rgb(size_t(img.width) * img.height * 3);
  for (size_t i = 0; i < rgb.size(); ++i) rgb[i] = to_byte(img.data[i]);
  std::unique_ptr<spng_ctx, CtxDeleter> ctx(spng_ctx_new(SPNG_CTX_ENCODER));
  if (!ctx) fail("PNG encoding: out of memory");
  spng_set_option(ctx.get(), SPNG_ENCODE_TO_BUFFER, 1);
  spng_ihdr ihdr{};
  ihdr.width = uint32_t(img.width);
  ihdr.height = uint32_t(img.height);
  ihdr.bit_depth = 8;
  ihdr.color_type = SPNG_COLOR_TYPE_TRUECOLOR;
  spng_set_ihdr(ctx.get(), &ihdr);
  if (int e = spng_encode_image(ctx.get(), rgb.data(), rgb.size(), SPNG_FMT_PNG, SPNG_ENCODE_FINALIZE))
    fail("PNG encoding: {}", spng_strerror(e));
  size_t len = 0;
  int e = 0;
  void* buf = spng_get_png_buffer(ctx.get(), &len, &e);
  if (!buf || e) fail("PNG encoding: {}", spng_strerror(e));
  std::string out(static_cast<const char*>(buf), len);
  free(buf);
  return out;
}

}  // namespace edrnr::serve
