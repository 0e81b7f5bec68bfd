#include "chip/rp_buffer.h"

#include <algorithm>
#include <cstdint>
#include <stdexcept>

#include "core/error.h"

namespace edrnr::chip {

void RayState::reset() {
  // Field by field: the vectors keep their storage, and the exit memo's
  // crossings (half the ray's bytes) are not written.
#if defined(__GLIBCXX__) && !defined(_GLIBCXX_DEBUG) && UINTPTR_MAX == UINT64_MAX
  static_assert(sizeof(RayState) == 384, "RayState changed: reset its new fields here, then update the size");
#endif
  valid = false;
  terminated = false;
  ray = {};
  world_dir = {};
  k = 0;
  k_end = 0;
  transmittance = 0;
  color = {};
  dir_code.clear();
  dir_input.x.clear();
  dir_input.saturations = 0;
  dir_input.terms.term.clear();
  dir_input.terms.saturations = 0;
  dir_input.terms_tme = nullptr;
  dir_input.terms_mlp = -1;
  exit_memo_limit = -1;
}

void RayPacket::reset() {
  pixels = PixelQuad{};
  for (RayState& r : rays) r.reset();
  travel_sign = RayPacket{}.travel_sign;
}

uint8_t RayPacket::live_mask() const {
  uint8_t m = 0;
  for (int r = 0; r < kRaysPerPacket; ++r)
    if (rays[size_t(r)].live()) m |= uint8_t(1u << r);
  return m;
}

RpBuffer::RpBuffer(int capacity) {
  if (capacity < 1) fail("RP buffer capacity must be at least 1 (got {})", capacity);
  slots_.resize(size_t(capacity));
  for (std::unique_ptr<RayPacket>& s : slots_) s = std::make_unique<RayPacket>();
  used_.assign(size_t(capacity), 0);
}

std::optional<uint32_t> RpBuffer::allocate() {
  for (size_t i = 0; i < used_.size(); ++i)
    if (!used_[i]) {
      used_[i] = 1;
      peak_ = std::max(peak_, ++in_use_);
      return uint32_t(i);
    }
  return std::nullopt;
}

void RpBuffer::release(uint32_t rp) {
  if (rp >= used_.size() || !used_[rp]) throw std::logic_error("RP buffer release: pointer not allocated");
  used_[rp] = 0;
  --in_use_;
}

}  // namespace edrnr::chip
