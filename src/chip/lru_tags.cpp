#include "chip/lru_tags.h"

#include <bit>

namespace edrnr::chip {

LruTags::LruTags(size_t capacity) : nodes_(capacity) {
  if (capacity == 0) return;
  const size_t slots = std::bit_ceil(2 * capacity);  // at most half full
  table_.assign(slots, kNone);
  shift_ = 64 - std::countr_zero(slots);
}

uint32_t LruTags::find(uint64_t tag) const {
  if (table_.empty()) return kNone;
  const size_t mask = table_.size() - 1;
  for (size_t s = home(tag);; s = (s + 1) & mask) {
    const uint32_t n = table_[s];
    if (n == kNone || nodes_[n].tag == tag) return n;
  }
}

void LruTags::unlink(uint32_t n) {
  Node& x = nodes_[n];
  (x.prev != kNone ? nodes_[x.prev].next : head_) = x.next;
  (x.next != kNone ? nodes_[x.next].prev : tail_) = x.prev;
  x.prev = x.next = kNone;
}

void LruTags::push_front(uint32_t n) {
  Node& x = nodes_[n];
  x.prev = kNone;
  x.next = head_;
  (head_ != kNone ? nodes_[head_].prev : tail_) = n;
  head_ = n;
}

void LruTags::erase_slot(size_t slot) {
  // Backward-shift deletion: move later entries of the cluster into the hole
  // unless their home lies cyclically in (hole, entry].
  const size_t mask = table_.size() - 1;
  size_t hole = slot;
  for (size_t s = (slot + 1) & mask;; s = (s + 1) & mask) {
    const uint32_t n = table_[s];
    if (n == kNone) break;
    const size_t h = home(nodes_[n].tag);
    const bool stays = hole <= s ? (h > hole && h <= s) : (h > hole || h <= s);
    if (stays) continue;
    table_[hole] = n;
    hole = s;
  }
  table_[hole] = kNone;
}

bool LruTags::access(uint64_t tag) {
  if (nodes_.empty()) {
    ++misses_;
    return false;
  }
  const size_t mask = table_.size() - 1;
  size_t s = home(tag);
  for (; table_[s] != kNone; s = (s + 1) & mask) {
    const uint32_t n = table_[s];
    if (nodes_[n].tag != tag) continue;
    if (head_ != n) {
      unlink(n);
      push_front(n);
    }
    ++hits_;
    return true;
  }
  ++misses_;
  uint32_t n;
  if (used_ < nodes_.size()) {
    n = uint32_t(used_++);
  } else {
    // Full: the least recent tag's node is reused.
    n = tail_;
    const size_t m = table_.size() - 1;
    size_t t = home(nodes_[n].tag);
    while (table_[t] != n) t = (t + 1) & m;
    erase_slot(t);
    unlink(n);
    // The hole may have moved the probe's empty slot: find it again.
    s = home(tag);
    while (table_[s] != kNone) s = (s + 1) & mask;
  }
  nodes_[n].tag = tag;
  table_[s] = n;
  push_front(n);
  return false;
}

}  // namespace edrnr::chip
