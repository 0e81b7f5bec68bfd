#pragma once
// The chip's external memory as the cycle simulator sees it: where each kind
// of data lives in DRAM (the address map), and transfers of any size between
// the core clock and the DDR3 model's own clock.
//
// A transfer is split into DRAM requests of at most max_request_bytes, queued
// in order and handed to the DRAM as its controller accepts them. The DRAM
// ticks at its own rate: by the end of core cycle c it has ticked
// floor((c + 1) f_dram / f_core) times (exact integer arithmetic on the clock
// rates in Hz), so a faster core sees a DRAM that is slower in core cycles.
// A read is complete when its last request has completed; it is reported by
// the advance() of that core cycle and its data are usable from the next one.
#include <array>
#include <cstdint>
#include <deque>
#include <functional>
#include <string>
#include <vector>

#include "core/stats.h"
#include "model/scene_model.h"
#include "sim/dram.h"
#include "sim/dram_config.h"

namespace edrnr::sim {

// The kinds of data that cross the chip boundary.
enum class DataType : uint8_t {
  Bitmaps,     // coarse and fine occupancy bitmaps (read once per frame)
  MicroGrid,   // 64-bit micro-grid words, one per occupied fine voxel
  Features,    // INT4 feature blocks, one per occupied fine voxel
  MlpWeights,  // INT8 MLPs, one per occupied coarse voxel
  RpOutput,    // finished ray packets: four pixels and their coordinates (writes)
};
inline constexpr int kDataTypes = 5;
const char* data_type_name(DataType t);  // "bitmaps", "micro_grid", "features", "mlp_weights", "rp_output"

// Byte addresses of the model in DRAM: one region per data type, in the order
// above, each starting on a 4 KB boundary.
struct AddressMap {
  std::array<uint64_t, kDataTypes> base{};
  std::array<uint64_t, kDataTypes> bytes{};  // region sizes
  uint64_t bitmap_bytes = 0;                 // coarse + fine bitmaps, densely packed
  uint64_t micro_word_bytes = 8;             // one word per occupied fine voxel, in block order
  uint64_t feature_block_bytes = 0;          // one INT4 block (125 F / 2 bytes)
  uint64_t feature_stride_bytes = 0;         // block_bytes rounded up to 64
  uint64_t mlp_bytes = 0;                    // one MLP as stored
  uint64_t mlp_stride_bytes = 0;             // rounded up to mlp_align_bytes
  uint64_t output_record_bytes = 0;
  uint64_t end() const { return base[kDataTypes - 1] + bytes[kDataTypes - 1]; }

  uint64_t micro_word(uint32_t block) const { return base[1] + uint64_t(block) * micro_word_bytes; }
  uint64_t feature_block(uint32_t block) const { return base[2] + uint64_t(block) * feature_stride_bytes; }
  uint64_t mlp(uint32_t index) const { return base[3] + uint64_t(index) * mlp_stride_bytes; }
  uint64_t output_record(uint64_t rp_sequence) const { return base[4] + rp_sequence * output_record_bytes; }
};

// Lays the model out. output_records: RPs in one frame. Throws Error if it
// does not fit dram_capacity_bytes.
AddressMap make_address_map(const SceneModel& model, uint64_t mlp_bytes, uint64_t mlp_align_bytes,
                            uint64_t output_records, uint64_t output_record_bytes, uint64_t dram_capacity_bytes);

// A finished read: its type and the caller's tag.
struct MemoryCompletion {
  DataType type = DataType::Bitmaps;
  uint64_t tag = 0;
};

// Sees one DRAM request: the DRAM clock at which it is offered, read or
// write, its byte address and size.
using DramRequestObserver = std::function<void(uint64_t dram_cycle, DramOp op, uint64_t address, uint32_t bytes)>;

class MemorySystem {
 public:
  // Registers "dram.*" (the DDR3 model) and "mem.<type>.*" in `stats`, which
  // must outlive this object. Throws Error for a core clock <= 0 or a
  // max_request_bytes the DRAM queue could never accept.
  MemorySystem(const DramConfig& dram, double core_clock_MHz, uint32_t max_request_bytes, const AddressMap& map,
               StatsRegistry& stats);

  // Starts a read of [addr, addr + bytes) in core cycle `cycle`; the completion
  // carries `tag`. Throws Error for 0 bytes.
  void read(DataType type, uint64_t addr, uint32_t bytes, uint64_t tag, uint64_t cycle);
  // Starts a write (no completion is reported).
  void write(DataType type, uint64_t addr, uint32_t bytes, uint64_t cycle);

  // Runs the DRAM through the end of core cycle `cycle` and appends the reads
  // that completed to `done` (in completion order). With no transfer in
  // flight the DRAM's clocks (refreshes, background cycles) are run later,
  // in one go, before the next transfer starts or the DRAM is looked at.
  void advance(uint64_t cycle, std::vector<MemoryCompletion>& done) {
    if (idle()) {
      idle_through_ = cycle;
      idle_pending_ = true;
      return;
    }
    advance_busy(cycle, done);
  }
  // Runs the clocks advance() left for later (call before reading the DRAM's
  // state through dram() const).
  void sync() {
    if (idle_pending_) run_idle();
  }

  // Optional observer of the DRAM requests: called once per request as a
  // transfer is split, with the DRAM clock at which the request is first
  // offered to the controller (advance() hands it over before the DRAM's next
  // tick). An empty function stops it. `edrnr simulate --dram-trace` writes
  // the requests as a trace (sim/dram_trace.h) with it.
  void set_request_observer(DramRequestObserver observer) { request_observer_ = std::move(observer); }

  // advance() for core cycles first, first + 1, ..., last, in one call with
  // no transfer waiting to be handed over (requests_waiting() false): the
  // DRAM runs from event to event and stops at the end of the first cycle
  // in which a transfer completes (its reads appended to `done`). Returns
  // that cycle, or `last`.
  uint64_t advance_through(uint64_t first, uint64_t last, std::vector<MemoryCompletion>& done);
  // Requests of started transfers that the DRAM's queue has not taken yet.
  bool requests_waiting() const { return !waiting_.empty(); }

  // After advance(cycle): the first later core cycle whose advance() may
  // complete a transfer or change the DRAM other than by counting clocks
  // (UINT64_MAX: none until a request comes). The calls for the cycles
  // between may be replaced by one advance() for the last of them.
  uint64_t quiet_until(uint64_t cycle) const;

  // No transfer waiting or in flight.
  bool idle() const { return transfers_in_flight_ == 0; }
  uint64_t transfers_in_flight() const { return transfers_in_flight_; }
  // The DRAM as of the last advance(). The const form throws
  // std::logic_error while clocks are left for later (call sync() first).
  const DramSystem& dram() const;
  DramSystem& dram() {
    sync();
    return dram_;
  }

  // Bytes read and written per type (as requested, not rounded to bursts).
  uint64_t read_bytes(DataType t) const { return per_type_[size_t(t)].read_bytes->value; }
  uint64_t write_bytes(DataType t) const { return per_type_[size_t(t)].write_bytes->value; }
  // Distinct bytes read per type (inside the type's region).
  uint64_t unique_read_bytes(DataType t) const;

  // Writes the derived statistics (DRAM bandwidth, energy, unique bytes).
  void update_stats();

 private:
  // The DRAM clock that ends core cycle `cycle`: floor((cycle + 1) dram_hz / core_hz).
  uint64_t dram_target(uint64_t cycle);
  struct Transfer {
    DataType type = DataType::Bitmaps;
    bool write = false;
    uint64_t tag = 0;
    uint32_t requests_left = 0;
    uint64_t start_cycle = 0;
  };
  struct Request {
    uint32_t transfer = 0;
    uint64_t addr = 0;
    uint32_t bytes = 0;
    bool write = false;
  };
  struct PerType {
    Counter* reads = nullptr;
    Counter* read_bytes = nullptr;
    Counter* writes = nullptr;
    Counter* write_bytes = nullptr;
    Value* unique_read_bytes = nullptr;
    Distribution* read_latency = nullptr;
    std::vector<uint8_t> touched;  // per 8 bytes of the region, a mask of the bytes read
  };
  void start(DataType type, bool write, uint64_t addr, uint32_t bytes, uint64_t tag, uint64_t cycle);
  void advance_busy(uint64_t cycle, std::vector<MemoryCompletion>& done);
  void run_idle();  // the clocks through idle_through_ (nothing in flight)

  DramSystem dram_;
  AddressMap map_;
  uint64_t core_hz_ = 0, dram_hz_ = 0;
  // dram_target's running quotient and remainder for core cycle
  // target_cycle_; they start as those of cycle -1 (UINT64_MAX), 0 and 0.
  uint64_t dram_per_core_ = 0, dram_per_core_rem_ = 0;
  uint64_t target_cycle_ = UINT64_MAX, target_ = 0, target_rem_ = 0;
  // advance() with nothing in flight: the DRAM is still to run through the
  // end of core cycle idle_through_.
  bool idle_pending_ = false;
  uint64_t idle_through_ = 0;
  uint32_t max_request_bytes_;
  std::vector<Transfer> transfers_;
  std::vector<uint32_t> free_transfers_;
  std::deque<Request> waiting_;  // not yet accepted by the DRAM controller
  uint64_t transfers_in_flight_ = 0;
  std::array<PerType, kDataTypes> per_type_;
  Counter& dram_rejections_;
  DramRequestObserver request_observer_;
};

}  // namespace edrnr::sim
