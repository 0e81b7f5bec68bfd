#pragma once
// The front end's ray packets built ahead of the simulator's timing model.
//
// A packet depends on its pixel quad only (chip::FrontEnd::build: ray
// generation, ABT, TSPS), so the packets of a frame can be built early, on
// any thread, as long as they are built one at a time and in ZORG order: the
// packets and the front end's counters are then the same as when the timing
// model builds each one when it needs it. With two threads the worker thread
// builds packets whenever it has no batch to evaluate, and the timing thread
// builds them while it waits for a batch; a ring of `capacity` packets bounds
// how far ahead they go.
#include <atomic>
#include <cstdint>
#include <mutex>
#include <vector>

#include "chip/front_end.h"
#include "chip/rp_buffer.h"
#include "chip/vru.h"
#include "chip/zorg.h"

namespace edrnr::sim {

class PacketAhead {
 public:
  struct Entry {
    chip::RayPacket packet;
    uint64_t tsps_position_evals = 0;  // the TSPS's position evaluations for this packet
  };

  // front: the front end every packet is built with (no other caller may use
  // it until the last packet is taken); vru: starts each ray's state; width,
  // height and order: the frame's ZORG scan. capacity >= 1.
  PacketAhead(chip::FrontEnd& front, const chip::Vru& vru, int width, int height, chip::ScanOrder order,
              size_t capacity);

  // Builds the next packet when the ring has room, the frame has one left and
  // no other thread is building. True when it built one. Any thread.
  bool build_one();
  // Moves the next packet in ZORG order into `out`, building it here if no
  // thread has yet. One consumer thread; throws std::logic_error past the
  // frame's last packet.
  void take(Entry& out);

 private:
  bool build_locked();  // build_one's work, with mutex_ held

  chip::FrontEnd& front_;
  const chip::Vru& vru_;
  chip::Zorg zorg_;  // the producers' scan, same order as the timing model's
  std::vector<Entry> ring_;
  std::mutex mutex_;                // held while a packet is built
  std::atomic<uint64_t> built_{0};  // packets built (written under mutex_)
  std::atomic<uint64_t> taken_{0};  // packets taken (written by the consumer)
};

}  // namespace edrnr::sim
