#include "chip/rp_buffer.h"

#include <algorithm>
#include <stdexcept>

#include "core/error.h"

namespace edrnr::chip {

void RayState::reset() {
  std::vector<int32_t> code = std::move(dir_code), x = std::move(dir_input.x);
  std::vector<int64_t> term = std::move(dir_input.terms.term);
  *this = RayState{};
  code.clear();
  x.clear();
  term.clear();
  dir_code = std::move(code);
  dir_input.x = std::move(x);
  dir_input.terms.term = std::move(term);
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
