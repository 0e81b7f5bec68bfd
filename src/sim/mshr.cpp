#include "sim/mshr.h"

#include <algorithm>
#include <utility>

#include "core/error.h"

namespace edrnr::sim {

Mshr::Mshr(std::string name, size_t entries) : name_(std::move(name)), capacity_(entries) {
  if (entries == 0) fail("mshr '{}': entries must be at least 1", name_);
  entries_.reserve(entries);
}

const Mshr::Entry* Mshr::find(uint64_t line_addr) const {
  for (const Entry& e : entries_)
    if (e.line_addr == line_addr) return &e;
  return nullptr;
}

Mshr::Entry* Mshr::find(uint64_t line_addr) {
  for (Entry& e : entries_)
    if (e.line_addr == line_addr) return &e;
  return nullptr;
}

MshrOutcome Mshr::on_miss(uint64_t line_addr, uint64_t cycle) {
  if (Entry* e = find(line_addr)) {
    ++e->waiters;
    ++stats_.merges;
    return MshrOutcome::Merged;
  }
  if (full()) {
    ++stats_.full_stalls;
    return MshrOutcome::Full;
  }
  entries_.push_back(Entry{line_addr, cycle, kNotScheduled, 1});
  ++stats_.allocations;
  stats_.max_occupancy = std::max(stats_.max_occupancy, entries_.size());
  return MshrOutcome::Allocated;
}

uint32_t Mshr::waiters(uint64_t line_addr) const {
  const Entry* e = find(line_addr);
  return e ? e->waiters : 0;
}

uint64_t Mshr::fill_cycle(uint64_t line_addr) const {
  const Entry* e = find(line_addr);
  if (!e) fail("mshr '{}': line {} is not outstanding", name_, line_addr);
  return e->fill_cycle;
}

void Mshr::schedule_fill(uint64_t line_addr, uint64_t fill_cycle) {
  Entry* e = find(line_addr);
  if (!e) fail("mshr '{}': schedule_fill for line {}, which is not outstanding", name_, line_addr);
  e->fill_cycle = fill_cycle;
}

std::vector<uint64_t> Mshr::arrived(uint64_t cycle) const {
  std::vector<uint64_t> out;
  for (const Entry& e : entries_)
    if (e.fill_cycle != kNotScheduled && e.fill_cycle <= cycle) out.push_back(e.line_addr);
  return out;
}

void Mshr::retire(uint64_t line_addr, uint64_t cycle) {
  auto it = std::find_if(entries_.begin(), entries_.end(), [&](const Entry& e) { return e.line_addr == line_addr; });
  if (it == entries_.end()) fail("mshr '{}': retire of line {}, which is not outstanding", name_, line_addr);
  ++stats_.retired;
  stats_.latency_cycles_sum += cycle >= it->alloc_cycle ? cycle - it->alloc_cycle : 0;
  entries_.erase(it);
}

}  // namespace edrnr::sim
