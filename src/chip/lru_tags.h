#pragma once
// A fully associative tag store with least-recently-used replacement: the
// hit/miss state of a small cache (the micro-grid bitmap cache, for one).
// No data and no time: access() says whether a tag was present and makes it
// the most recent, evicting the least recent tag when full.
#include <cstdint>
#include <list>
#include <unordered_map>

namespace edrnr::chip {

class LruTags {
 public:
  // capacity 0: nothing is ever cached (every access misses).
  explicit LruTags(size_t capacity = 0) : capacity_(capacity) {}

  bool access(uint64_t tag) {
    auto it = where_.find(tag);
    if (it != where_.end()) {
      order_.splice(order_.begin(), order_, it->second);
      ++hits_;
      return true;
    }
    ++misses_;
    if (capacity_ == 0) return false;
    if (where_.size() == capacity_) {
      where_.erase(order_.back());
      order_.pop_back();
    }
    order_.push_front(tag);
    where_[tag] = order_.begin();
    return false;
  }
  bool contains(uint64_t tag) const { return where_.count(tag) != 0; }
  size_t capacity() const { return capacity_; }
  uint64_t hits() const { return hits_; }
  uint64_t misses() const { return misses_; }

 private:
  size_t capacity_;
  std::list<uint64_t> order_;  // most recent first
  std::unordered_map<uint64_t, std::list<uint64_t>::iterator> where_;
  uint64_t hits_ = 0, misses_ = 0;
};

}  // namespace edrnr::chip
