#include "sim/packet_ahead.h"

#include <stdexcept>

#include "core/error.h"

namespace edrnr::sim {

PacketAhead::PacketAhead(chip::FrontEnd& front, const chip::Vru& vru, int width, int height, chip::ScanOrder order,
                         size_t capacity)
    : front_(front), vru_(vru), zorg_(width, height, order), ring_(capacity) {
  if (capacity < 1) fail("packet ring capacity must be at least 1");
}

bool PacketAhead::build_locked() {
  const uint64_t b = built_.load(std::memory_order_relaxed);  // written only under mutex_
  if (zorg_.done() || b - taken_.load(std::memory_order_acquire) >= ring_.size()) return false;
  Entry& e = ring_[size_t(b % ring_.size())];
  const chip::PixelQuad quad = zorg_.next();
  const uint64_t before = front_.tsps_position_evals();
  e.packet = front_.build(quad, vru_);
  e.tsps_position_evals = front_.tsps_position_evals() - before;
  built_.store(b + 1, std::memory_order_release);
  return true;
}

bool PacketAhead::build_one() {
  std::unique_lock lock(mutex_, std::try_to_lock);
  return lock.owns_lock() && build_locked();
}

void PacketAhead::take(Entry& out) {
  const uint64_t t = taken_.load(std::memory_order_relaxed);
  while (built_.load(std::memory_order_acquire) <= t) {
    const std::lock_guard lock(mutex_);
    if (built_.load(std::memory_order_relaxed) <= t && !build_locked())
      throw std::logic_error("packet ring: no packet left to take");
  }
  out = std::move(ring_[size_t(t % ring_.size())]);
  taken_.store(t + 1, std::memory_order_release);
}

}  // namespace edrnr::sim
