#pragma once
// Self-describing statistics. A component registers each statistic once, with a
// dotted name ("dram.read_bytes"), a unit ("bytes", "cycles", "pJ") and a
// one-line description, and keeps the returned reference. On the hot path it
// then touches a plain uint64_t or double through that reference: no lookups,
// no allocation. The registry prints everything as a table for people
// (print_table) and as JSON for tools (to_json), in registration order.
//
// Usage:
//   StatsRegistry stats;
//   Counter& reads = stats.counter("dram.reads", "requests", "read requests completed");
//   Distribution& lat = stats.distribution("dram.read_latency", "cycles", "read latency, arrival to last data");
//   ++reads; lat.add(26);
//   stats.print_table(std::cout);
#include <cstdint>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <ostream>
#include <string>
#include <vector>

namespace edrnr {

// An event count. Increment with ++c, c += n or c.add(n).
struct Counter {
  uint64_t value = 0;
  Counter& operator++() {
    ++value;
    return *this;
  }
  Counter& operator+=(uint64_t n) {
    value += n;
    return *this;
  }
  void add(uint64_t n = 1) { value += n; }
};

// A real-valued statistic that the component sets (a rate, an energy, a ratio).
struct Value {
  double value = 0.0;
  void set(double v) { value = v; }
  Value& operator+=(double v) {
    value += v;
    return *this;
  }
};

// Exact distribution of non-negative integer samples (latencies in cycles,
// sizes in bytes). Samples below kDenseLimit cost one array increment; larger
// ones go to an ordered map. Percentiles are exact (nearest-rank definition).
class Distribution {
 public:
  static constexpr uint64_t kDenseLimit = 1u << 16;

  void add(uint64_t sample);

  uint64_t count() const { return count_; }
  uint64_t sum() const { return sum_; }
  uint64_t min() const { return count_ ? min_ : 0; }  // 0 when empty
  uint64_t max() const { return max_; }               // 0 when empty
  double mean() const { return count_ ? static_cast<double>(sum_) / static_cast<double>(count_) : 0.0; }
  // Nearest-rank percentile, p in [0, 100]: the smallest sample v such that at
  // least ceil(p/100 * count) samples are <= v (p = 0 gives the minimum).
  // Returns 0 when empty. Throws Error for p outside [0, 100].
  uint64_t percentile(double p) const;

 private:
  std::vector<uint64_t> dense_;          // dense_[v] = number of samples equal to v
  std::map<uint64_t, uint64_t> sparse_;  // samples >= kDenseLimit
  uint64_t count_ = 0;
  uint64_t sum_ = 0;
  uint64_t min_ = UINT64_MAX;
  uint64_t max_ = 0;
};

class StatsRegistry {
 public:
  StatsRegistry() = default;
  StatsRegistry(const StatsRegistry&) = delete;  // handed-out references point into it
  StatsRegistry& operator=(const StatsRegistry&) = delete;

  // Register a statistic and return a reference that stays valid for the
  // registry's lifetime. Throws Error if the name is empty, contains a space,
  // or is already registered, or if the unit is empty.
  Counter& counter(const std::string& name, const std::string& unit, const std::string& description);
  Value& value(const std::string& name, const std::string& unit, const std::string& description);
  Distribution& distribution(const std::string& name, const std::string& unit, const std::string& description);

  bool contains(const std::string& name) const;
  size_t size() const { return entries_.size(); }

  // Reads back a counter or value by name (for tests and reports). Throws
  // Error if the name is unknown or names a distribution.
  double get(const std::string& name) const;

  // One row per statistic: name, value, unit, description. A distribution
  // prints rows name.count, name.mean, name.p50, name.p95, name.p99, name.max.
  void print_table(std::ostream& out) const;

  // {"name": {"unit": ..., "description": ..., "value": ...}, ...}; a
  // distribution has count, mean, min, p50, p95, p99, max instead of value.
  nlohmann::json to_json() const;

 private:
  enum class Kind { kCounter, kValue, kDistribution };
  struct Entry {
    std::string name, unit, description;
    Kind kind;
    std::unique_ptr<Counter> counter;
    std::unique_ptr<Value> value;
    std::unique_ptr<Distribution> distribution;
  };
  Entry& add_entry(const std::string& name, const std::string& unit, const std::string& description, Kind kind);
  const Entry* find(const std::string& name) const;

  std::vector<Entry> entries_;
  std::map<std::string, size_t> index_;  // name -> position in entries_
};

}  // namespace edrnr
