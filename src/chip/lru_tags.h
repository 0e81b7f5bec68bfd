#pragma once
// A fully associative tag store with least-recently-used replacement: the
// hit/miss state of a small cache (the micro-grid bitmap cache, for one).
// No data and no time: access() says whether a tag was present and makes it
// the most recent, evicting the least recent tag when full.
//
// Allocation-free after construction: the tags sit in `capacity` nodes
// chained most recent first (indices, not pointers), found through an
// open-addressing table with linear probing (at most half full; a removed
// entry's cluster is shifted back, so no tombstones).
#include <cstddef>
#include <cstdint>
#include <vector>

namespace edrnr::chip {

class LruTags {
 public:
  // capacity 0: nothing is ever cached (every access misses).
  explicit LruTags(size_t capacity = 0);

  bool access(uint64_t tag);
  bool contains(uint64_t tag) const { return find(tag) != kNone; }
  size_t capacity() const { return nodes_.size(); }
  uint64_t hits() const { return hits_; }
  uint64_t misses() const { return misses_; }

 private:
  static constexpr uint32_t kNone = UINT32_MAX;
  struct Node {
    uint64_t tag = 0;
    uint32_t prev = kNone, next = kNone;  // toward the most / least recent
  };

  size_t home(uint64_t tag) const { return size_t((tag * 0x9E3779B97F4A7C15ull) >> shift_); }
  uint32_t find(uint64_t tag) const;  // the node holding tag, or kNone
  void unlink(uint32_t n);
  void push_front(uint32_t n);
  void erase_slot(size_t slot);  // removes a table entry, shifting its cluster back

  std::vector<Node> nodes_;
  size_t used_ = 0;                       // nodes holding a tag: [0, used_)
  uint32_t head_ = kNone, tail_ = kNone;  // most and least recent
  std::vector<uint32_t> table_;           // node index per slot, kNone when empty
  int shift_ = 64;                        // 64 - log2(table size)
  uint64_t hits_ = 0, misses_ = 0;
};

}  // namespace edrnr::chip
