#pragma once
// The global RP buffer (paper Section IV-A): the state of every ray packet
// (RP) in flight, addressed by the RP pointer that travels through the
// pipeline in its place. Its capacity bounds the number of RPs in flight.
#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "chip/chip_ray.h"
#include "chip/tme.h"
#include "chip/zorg.h"

namespace edrnr::chip {

// One ray of a packet.
struct RayState {
  bool valid = false;       // the packet has this ray (its pixel is in the image)
  bool terminated = false;  // the VRU stopped it: transmittance below the threshold
  ChipRay ray;
  Vec3d world_dir;
  int64_t k = 0;      // next candidate to visit
  int64_t k_end = 0;  // first candidate past the traversal box (the ray length)
  // VRU state: transmittance and accumulated colour, Q1.(bits-1) codes.
  int64_t transmittance = 0;
  std::array<int64_t, 3> color{};
  // Direction encoding codes (dir_dims values, Tme::encode_direction), once per ray.
  std::vector<int32_t> dir_code;
  // The TME's direction inputs made from dir_code (Tme::direction_input),
  // kept by a consumer that evaluates the ray's samples in several batches,
  // with the direction terms of its latest MLP.
  TmeDirection dir_input;
  // The FTU's face crossings of this ray (RayMath::ExitMemo), valid for
  // k_limit = exit_memo_limit: kept from one fine traversal to the next.
  RayMath::ExitMemo exit_memo;
  int64_t exit_memo_limit = -1;

  // Still marching: not stopped by the VRU and not past the box.
  bool live() const { return valid && !terminated && k < k_end; }
  // Back to a default-constructed ray, its vectors emptied but keeping
  // their storage, except for the exit memo's crossings: no one reads them
  // while exit_memo_limit is -1 (no ray's k_end), and Ftu::run clears them
  // before it uses them.
  void reset();
};

struct RayPacket {
  PixelQuad pixels;
  std::array<RayState, kRaysPerPacket> rays;
  Vec3i travel_sign{1, 1, 1};  // per axis, the direction sign of the first valid ray (LFAU orientation)

  uint8_t live_mask() const;
  // Back to a default-constructed packet (RayState::reset).
  void reset();
};

class RpBuffer {
 public:
  // Throws Error unless capacity >= 1.
  explicit RpBuffer(int capacity);

  // The lowest free RP pointer, or nothing when the buffer is full.
  std::optional<uint32_t> allocate();
  void release(uint32_t rp);  // throws std::logic_error unless allocated
  RayPacket& operator[](uint32_t rp) { return *slots_[rp]; }
  const RayPacket& operator[](uint32_t rp) const { return *slots_[rp]; }
  // Puts packet p (not null) in slot rp and hands back the packet the slot
  // held, without copying either: each slot's packet lives in its own
  // allocation, which moves with it.
  void exchange(uint32_t rp, std::unique_ptr<RayPacket>& p) { slots_[rp].swap(p); }

  int capacity() const { return int(slots_.size()); }
  int in_use() const { return in_use_; }
  bool full() const { return in_use_ == capacity(); }
  int peak_in_use() const { return peak_; }

 private:
  std::vector<std::unique_ptr<RayPacket>> slots_;
  std::vector<uint8_t> used_;
  int in_use_ = 0, peak_ = 0;
};

}  // namespace edrnr::chip
