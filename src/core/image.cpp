#include "core/image.h"

#include <spng.h>

#include <cmath>
#include <memory>

#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"

namespace edrnr {

namespace {
struct CtxDeleter {
  void operator()(spng_ctx* c) const { spng_ctx_free(c); }
};
using Ctx = std::unique_ptr<spng_ctx, CtxDeleter>;
}  // namespace

Image read_png_rgba(const std::filesystem::path& path) {
  std::vector<uint8_t> bytes = read_file_bytes(path, limits::kMaxPngFileBytes);
  Ctx ctx(spng_ctx_new(0));
  if (!ctx) fail("out of memory decoding '{}'", path.string());
  spng_set_crc_action(ctx.get(), SPNG_CRC_ERROR, SPNG_CRC_ERROR);
  spng_set_image_limits(ctx.get(), 0x7fffffff, 0x7fffffff);  // the size is checked below, with a clearer message
  spng_set_chunk_limits(ctx.get(), 1 << 26, 1 << 26);
  if (int e = spng_set_png_buffer(ctx.get(), bytes.data(), bytes.size()))
    fail("'{}' is not a PNG: {}", path.string(), spng_strerror(e));
  spng_ihdr ihdr;
  if (int e = spng_get_ihdr(ctx.get(), &ihdr)) fail("'{}' is not a valid PNG: {}", path.string(), spng_strerror(e));
  // The size the header claims, before anything of that size is allocated.
  limits::check_image_size(int64_t(ihdr.width), int64_t(ihdr.height), fmt::format("PNG '{}':", path.string()));
  // 16-bit PNGs decode at 16 bits; all others at 8 bits, which is faster.
  // Either way a sample s of maximum m becomes s / m (k / 255 == 257 k / 65535).
  bool wide = ihdr.bit_depth == 16;
  int fmt = wide ? SPNG_FMT_RGBA16 : SPNG_FMT_RGBA8;
  size_t out_size = 0;
  if (int e = spng_decoded_image_size(ctx.get(), fmt, &out_size)) fail("'{}': {}", path.string(), spng_strerror(e));
  auto decode = [&](void* out) {
    if (int e = spng_decode_image(ctx.get(), out, out_size, fmt, SPNG_DECODE_TRNS))
      fail("cannot decode '{}': {}", path.string(), spng_strerror(e));
  };
  Image img(int(ihdr.width), int(ihdr.height), 4);
  if (wide) {
    std::vector<uint16_t> pix(out_size / 2);  // host byte order
    decode(pix.data());
    for (size_t i = 0; i < img.data.size(); ++i) img.data[i] = pix[i] / 65535.f;
  } else {
    std::vector<uint8_t> pix(out_size);
    decode(pix.data());
    float level[256];
    for (int k = 0; k < 256; ++k) level[k] = k / 255.f;
    for (size_t i = 0; i < img.data.size(); ++i) img.data[i] = level[pix[i]];
  }
  return img;
}

Image composite_rgba(const Image& rgba, const float background[3]) {
  if (rgba.channels != 4) fail("composite_rgba: expected 4 channels, got {}", rgba.channels);
  Image out(rgba.width, rgba.height, 3);
  size_t n = size_t(rgba.width) * rgba.height;
  for (size_t i = 0; i < n; ++i) {
    const float* p = &rgba.data[i * 4];
    for (int c = 0; c < 3; ++c) out.data[i * 3 + c] = p[c] * p[3] + background[c] * (1.f - p[3]);
  }
  return out;
}

Image downscale(const Image& img, int factor) {
  if (factor < 1) fail("downscale factor must be a positive integer, got {}", factor);
  if (factor == 1) return img;
  if (img.width % factor || img.height % factor)
    fail("cannot downscale {}x{} by {}: the size must divide", img.width, img.height, factor);
  Image out(img.width / factor, img.height / factor, img.channels);
  float norm = 1.f / float(factor * factor);
  for (int y = 0; y < out.height; ++y)
    for (int x = 0; x < out.width; ++x)
      for (int c = 0; c < img.channels; ++c) {
        float s = 0;
        for (int dy = 0; dy < factor; ++dy)
          for (int dx = 0; dx < factor; ++dx) s += img.at(x * factor + dx, y * factor + dy)[c];
        out.at(x, y)[c] = s * norm;
      }
  return out;
}

void write_png(const std::filesystem::path& path, const Image& img) {
  if (img.channels != 3 && img.channels != 4) fail("write_png: {} channels not supported", img.channels);
  if (img.width < 1 || img.height < 1 || img.data.size() != size_t(img.width) * img.height * img.channels)
    fail("write_png '{}': the image is empty or its data does not match {}x{}x{}", path.string(), img.width, img.height,
         img.channels);
  std::vector<uint8_t> pix(img.data.size());
  for (size_t i = 0; i < pix.size(); ++i) {
    float v = std::fmin(1.f, std::fmax(0.f, img.data[i]));
    pix[i] = uint8_t(std::lround(v * 255.f));
  }
  Ctx ctx(spng_ctx_new(SPNG_CTX_ENCODER));
  if (!ctx) fail("out of memory encoding '{}'", path.string());
  spng_set_option(ctx.get(), SPNG_ENCODE_TO_BUFFER, 1);
  spng_ihdr ihdr{};
  ihdr.width = uint32_t(img.width);
  ihdr.height = uint32_t(img.height);
  ihdr.bit_depth = 8;
  ihdr.color_type = img.channels == 4 ? SPNG_COLOR_TYPE_TRUECOLOR_ALPHA : SPNG_COLOR_TYPE_TRUECOLOR;
  spng_set_ihdr(ctx.get(), &ihdr);
  if (int e = spng_encode_image(ctx.get(), pix.data(), pix.size(), SPNG_FMT_PNG, SPNG_ENCODE_FINALIZE))
    fail("cannot encode '{}': {}", path.string(), spng_strerror(e));
  size_t len = 0;
  int e = 0;
  void* buf = spng_get_png_buffer(ctx.get(), &len, &e);
  if (!buf) fail("cannot encode '{}': {}", path.string(), spng_strerror(e));
  std::string bytes(static_cast<char*>(buf), len);
  std::free(buf);
  write_file_atomic(path, bytes);
}

}  // namespace edrnr
