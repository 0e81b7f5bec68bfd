#include "sim/memory_system.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "core/error.h"
#include "model/footprint.h"

namespace edrnr::sim {

namespace {
constexpr uint64_t kRegionAlign = 4096;
constexpr uint64_t kGranule = 8;

uint64_t round_up(uint64_t v, uint64_t a) { return (v + a - 1) / a * a; }
}  // namespace

const char* data_type_name(DataType t) {
  switch (t) {
    case DataType::Bitmaps:
      return "bitmaps";
    case DataType::MicroGrid:
      return "micro_grid";
    case DataType::Features:
      return "features";
    case DataType::MlpWeights:
      return "mlp_weights";
    case DataType::RpOutput:
      return "rp_output";
  }
  return "?";
}

AddressMap make_address_map(const SceneModel& model, uint64_t mlp_bytes, uint64_t mlp_align_bytes,
                            uint64_t output_records, uint64_t output_record_bytes, uint64_t dram_capacity_bytes) {
  AddressMap m;
  const uint64_t cr = uint64_t(model.coarse_res()), fr = uint64_t(model.fine_res());
  m.bitmap_bytes = (cr * cr * cr + 7) / 8 + (fr * fr * fr + 7) / 8;
  m.feature_block_bytes = feature_block_q4_bytes(model.feature_channels);
  m.feature_stride_bytes = round_up(m.feature_block_bytes, 64);
  m.mlp_bytes = mlp_bytes;
  m.mlp_stride_bytes = round_up(mlp_bytes, std::max<uint64_t>(mlp_align_bytes, 1));
  m.output_record_bytes = output_record_bytes;
  m.bytes = {m.bitmap_bytes, m.micro_word_bytes * model.block_count(), m.feature_stride_bytes * model.block_count(),
             m.mlp_stride_bytes * model.mlp_count(), output_records * output_record_bytes};
  uint64_t at = 0;
  for (int t = 0; t < kDataTypes; ++t) {
    m.base[size_t(t)] = at;
    at = round_up(at + m.bytes[size_t(t)], kRegionAlign);
  }
  if (m.end() > dram_capacity_bytes)
    fail("the model and the frame need {} bytes of DRAM, more than the configured DRAM's {} bytes", m.end(),
         dram_capacity_bytes);
  return m;
}

MemorySystem::MemorySystem(const DramConfig& dram, double core_clock_MHz, uint32_t max_request_bytes,
                           const AddressMap& map, StatsRegistry& stats)
    : dram_(dram, stats, "dram"),
      map_(map),
      max_request_bytes_(max_request_bytes),
      dram_rejections_(stats.counter("mem.dram_queue_full_cycles", "cycles",
                                     "core cycles in which the DRAM controller queue refused a request")) {
  if (!(core_clock_MHz > 0.0) || !std::isfinite(core_clock_MHz))
    fail("core clock {} MHz must be a positive number", core_clock_MHz);
  core_hz_ = uint64_t(std::llround(core_clock_MHz * 1e6));
  dram_hz_ = uint64_t(std::llround(1e9 / dram.tCK_ns));
  if (core_hz_ == 0) fail("core clock {} MHz rounds to 0 Hz", core_clock_MHz);
  dram_per_core_ = dram_hz_ / core_hz_;
  dram_per_core_rem_ = dram_hz_ % core_hz_;
  if (max_request_bytes == 0) fail("max_request_bytes must be at least 1");
  // Every request must fit the controller queue, whatever its alignment.
  const uint64_t worst_bursts = (uint64_t(max_request_bytes) + dram.burst_bytes() - 1) / dram.burst_bytes() + 1;
  if (worst_bursts > dram.queue_depth_bursts)
    fail("max_request_bytes {} can need {} DRAM bursts, more than the controller queue's {}", max_request_bytes,
         worst_bursts, dram.queue_depth_bursts);
  for (int t = 0; t < kDataTypes; ++t) {
    const std::string p = std::string("mem.") + data_type_name(DataType(t));
    PerType& x = per_type_[size_t(t)];
    x.reads = &stats.counter(p + ".reads", "transfers", "reads of this data type (before splitting into requests)");
    x.read_bytes = &stats.counter(p + ".read_bytes", "bytes", "bytes read from DRAM (as requested)");
    x.writes = &stats.counter(p + ".writes", "transfers", "writes of this data type");
    x.write_bytes = &stats.counter(p + ".write_bytes", "bytes", "bytes written to DRAM");
    x.unique_read_bytes = &stats.value(p + ".unique_read_bytes", "bytes", "distinct bytes of the region read");
    x.read_latency = &stats.distribution(p + ".read_latency", "cycles",
                                         "core cycles from a read's start until its data can be used");
    x.touched.assign(size_t((map.bytes[size_t(t)] + kGranule - 1) / kGranule), 0);
  }
}

void MemorySystem::start(DataType type, bool write, uint64_t addr, uint32_t bytes, uint64_t tag, uint64_t cycle) {
  if (bytes == 0) fail("memory transfer of 0 bytes at address {}", addr);
  sync();  // the DRAM as it ends the cycle before
  uint32_t index;
  if (free_transfers_.empty()) {
    index = uint32_t(transfers_.size());
    transfers_.emplace_back();
  } else {
    index = free_transfers_.back();
    free_transfers_.pop_back();
  }
  Transfer& t = transfers_[index];
  t = Transfer{type, write, tag, 0, cycle};
  for (uint64_t a = addr, end = addr + bytes; a < end;) {
    const uint32_t n = uint32_t(std::min<uint64_t>(max_request_bytes_, end - a));
    waiting_.push_back({index, a, n, write});
    if (request_observer_) request_observer_(dram_.cycle(), write ? DramOp::kWrite : DramOp::kRead, a, n);
    ++t.requests_left;
    a += n;
  }
  ++transfers_in_flight_;
  PerType& x = per_type_[size_t(type)];
  if (write) {
    ++*x.writes;
    *x.write_bytes += bytes;
    return;
  }
  ++*x.reads;
  *x.read_bytes += bytes;
  const uint64_t base = map_.base[size_t(type)];
  for (uint64_t a = std::max(addr, base), end = std::min(addr + bytes, base + map_.bytes[size_t(type)]); a < end;) {
    const uint64_t g = (a - base) / kGranule, in = (a - base) % kGranule;
    const uint64_t n = std::min(kGranule - in, end - a);
    x.touched[size_t(g)] |= uint8_t(((1u << n) - 1) << in);
    a += n;
  }
}

void MemorySystem::read(DataType type, uint64_t addr, uint32_t bytes, uint64_t tag, uint64_t cycle) {
  start(type, false, addr, bytes, tag, cycle);
}

void MemorySystem::write(DataType type, uint64_t addr, uint32_t bytes, uint64_t cycle) {
  start(type, true, addr, bytes, 0, cycle);
}

const DramSystem& MemorySystem::dram() const {
  if (idle_pending_) throw std::logic_error("MemorySystem::dram() const: call sync() first");
  return dram_;
}

void MemorySystem::run_idle() {
  // Nothing to hand over and nothing in flight: the same clocks in bulk.
  idle_pending_ = false;
  dram_.advance_idle(dram_target(idle_through_));
}

void MemorySystem::advance_busy(uint64_t cycle, std::vector<MemoryCompletion>& done) {
  // Nothing is left for later here: a transfer starts with sync().
  const uint64_t target = dram_target(cycle);
  bool refused = false;
  while (dram_.cycle() < target) {
    while (!waiting_.empty()) {
      const Request& r = waiting_.front();
      if (!dram_.enqueue(r.write ? DramOp::kWrite : DramOp::kRead, r.addr, r.bytes, r.transfer)) {
        refused = true;
        break;
      }
      waiting_.pop_front();
    }
    // With nothing left to hand over, the DRAM runs to the target in one go
    // (it ticks where something can happen); else one clock, then retry.
    if (waiting_.empty())
      dram_.advance_quiet(target);
    else
      dram_.tick();
    while (auto c = dram_.pop_completion()) {
      Transfer& t = transfers_[size_t(c->id)];
      if (--t.requests_left > 0) continue;
      --transfers_in_flight_;
      free_transfers_.push_back(uint32_t(c->id));
      if (t.write) continue;
      per_type_[size_t(t.type)].read_latency->add(cycle + 1 - t.start_cycle);
      done.push_back({t.type, t.tag});
    }
  }
  if (refused) ++dram_rejections_;
}

uint64_t MemorySystem::advance_through(uint64_t first, uint64_t last, std::vector<MemoryCompletion>& done) {
  if (!waiting_.empty()) throw std::logic_error("MemorySystem::advance_through with requests waiting");
  const uint64_t in_flight = transfers_in_flight_;
  for (uint64_t c = first;;) {
    // Nothing changes but the clocks before core cycle quiet_until(c - 1).
    const uint64_t e = std::max(c, quiet_until(c - 1));
    advance(std::min(e, last), done);
    if (e >= last || transfers_in_flight_ != in_flight) return std::min(e, last);
    c = e + 1;
  }
}

uint64_t MemorySystem::dram_target(uint64_t cycle) {
  // floor((cycle + 1) dram_hz / core_hz): from the last cycle's quotient and
  // remainder when the cycles follow each other (no division per cycle).
  if (cycle == target_cycle_ + 1) {
    target_ += dram_per_core_;
    target_rem_ += dram_per_core_rem_;
    if (target_rem_ >= core_hz_) {
      target_rem_ -= core_hz_;
      ++target_;
    }
  } else {
    const unsigned __int128 x = (unsigned __int128)(cycle + 1) * dram_hz_;
    target_ = uint64_t(x / core_hz_);
    target_rem_ = uint64_t(x % core_hz_);
  }
  target_cycle_ = cycle;
  return target_;
}

uint64_t MemorySystem::quiet_until(uint64_t cycle) const {
  if (!waiting_.empty()) return cycle + 1;
  if (idle()) return UINT64_MAX;  // nothing can complete (refreshes run in bulk)
  const uint64_t e = dram_.next_event_cycle();
  if (e == UINT64_MAX) return UINT64_MAX;
  // advance(c) runs the DRAM up to floor((c + 1) dram_hz / core_hz); it ticks
  // DRAM cycle e from the first c with (c + 1) dram_hz >= (e + 1) core_hz.
  uint64_t c = 0;
  if (e < UINT64_MAX / core_hz_ - 1) {
    c = ((e + 1) * core_hz_ + dram_hz_ - 1) / dram_hz_ - 1;
  } else {
    const unsigned __int128 need = (unsigned __int128)(e + 1) * core_hz_;
    c = uint64_t((need + dram_hz_ - 1) / dram_hz_) - 1;
  }
  return std::max(c, cycle + 1);
}

uint64_t MemorySystem::unique_read_bytes(DataType t) const {
  // The set bits, eight masks at a time (the portable build has no popcount
  // instruction: std::popcount would be a library call per mask).
  const std::vector<uint8_t>& m = per_type_[size_t(t)].touched;
  uint64_t n = 0;
  size_t i = 0;
  for (; i + 8 <= m.size(); i += 8) {
    uint64_t w;
    std::memcpy(&w, &m[i], 8);
    w = w - ((w >> 1) & 0x5555555555555555ull);
    w = (w & 0x3333333333333333ull) + ((w >> 2) & 0x3333333333333333ull);
    w = (w + (w >> 4)) & 0x0F0F0F0F0F0F0F0Full;
    n += (w * 0x0101010101010101ull) >> 56;
  }
  for (; i < m.size(); ++i) n += uint64_t(std::popcount(m[i]));
  return n;
}

void MemorySystem::update_stats() {
  sync();
  dram_.update_stats();
  for (int t = 0; t < kDataTypes; ++t)
    per_type_[size_t(t)].unique_read_bytes->set(double(unique_read_bytes(DataType(t))));
}

}  // namespace edrnr::sim
