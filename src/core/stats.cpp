#include "core/stats.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace edrnr {

void Distribution::add(uint64_t sample) {
  if (sample < kDenseLimit) {
    if (sample >= dense_.size()) dense_.resize(sample + 1, 0);
    ++dense_[sample];
  } else {
    ++sparse_[sample];
  }
  ++count_;
  sum_ += sample;
  min_ = std::min(min_, sample);
  max_ = std::max(max_, sample);
}

uint64_t Distribution::percentile(double p) const {
  if (!(p >= 0.0 && p <= 100.0)) fail("percentile {} is outside [0, 100]", p);
  if (count_ == 0) return 0;
  // Rank of the wanted sample, 1-based: ceil(p/100 * count), at least 1.
  uint64_t rank = static_cast<uint64_t>(std::ceil(p / 100.0 * static_cast<double>(count_)));
  rank = std::clamp<uint64_t>(rank, 1, count_);
  uint64_t seen = 0;
  for (uint64_t v = 0; v < dense_.size(); ++v) {
    seen += dense_[v];
    if (seen >= rank) return v;
  }
  for (const auto& [v, n] : sparse_) {
    seen += n;
    if (seen >= rank) return v;
  }
  return max_;
}

StatsRegistry::Entry& StatsRegistry::add_entry(const std::string& name, const std::string& unit,
                                               const std::string& description, Kind kind) {
  if (name.empty()) fail("statistic name is empty");
  if (name.find_first_of(" \t\n") != std::string::npos) fail("statistic name '{}' contains white space", name);
  if (unit.empty()) fail("statistic '{}' has no unit", name);
  if (index_.count(name)) fail("statistic '{}' is registered twice", name);
  index_[name] = entries_.size();
  Entry& e = entries_.emplace_back();
  e.name = name;
  e.unit = unit;
  e.description = description;
  e.kind = kind;
  return e;
}

Counter& StatsRegistry::counter(const std::string& name, const std::string& unit, const std::string& description) {
  Entry& e = add_entry(name, unit, description, Kind::kCounter);
  e.counter = std::make_unique<Counter>();
  return *e.counter;
}

Value& StatsRegistry::value(const std::string& name, const std::string& unit, const std::string& description) {
  Entry& e = add_entry(name, unit, description, Kind::kValue);
  e.value = std::make_unique<Value>();
  return *e.value;
}

Distribution& StatsRegistry::distribution(const std::string& name, const std::string& unit,
                                          const std::string& description) {
  Entry& e = add_entry(name, unit, description, Kind::kDistribution);
  e.distribution = std::make_unique<Distribution>();
  return *e.distribution;
}

const StatsRegistry::Entry* StatsRegistry::find(const std::string& name) const {
  auto it = index_.find(name);
  return it == index_.end() ? nullptr : &entries_[it->second];
}

bool StatsRegistry::contains(const std::string& name) const { return find(name) != nullptr; }

double StatsRegistry::get(const std::string& name) const {
  const Entry* e = find(name);
  if (!e) fail("no statistic named '{}'", name);
  if (e->kind == Kind::kCounter) return static_cast<double>(e->counter->value);
  if (e->kind == Kind::kValue) return e->value->value;
  fail("statistic '{}' is a distribution; read it through its Distribution", name);
}

namespace {

std::string format_real(double v) {
  if (v == 0.0 || std::isnan(v) || std::isinf(v)) return fmt::format("{}", v);
  double a = std::fabs(v);
  if (a >= 1e-3 && a < 1e15) return fmt::format("{:.3f}", v);
  return fmt::format("{:.4e}", v);
}

struct Row {
  std::string name, value, unit, description;
};

}  // namespace

void StatsRegistry::print_table(std::ostream& out) const {
  std::vector<Row> rows;
  for (const Entry& e : entries_) {
    switch (e.kind) {
      case Kind::kCounter:
        rows.push_back({e.name, fmt::format("{}", e.counter->value), e.unit, e.description});
        break;
      case Kind::kValue:
        rows.push_back({e.name, format_real(e.value->value), e.unit, e.description});
        break;
      case Kind::kDistribution: {
        const Distribution& d = *e.distribution;
        rows.push_back({e.name + ".count", fmt::format("{}", d.count()), "samples", e.description});
        rows.push_back({e.name + ".mean", format_real(d.mean()), e.unit, "mean"});
        rows.push_back({e.name + ".p50", fmt::format("{}", d.percentile(50)), e.unit, "median"});
        rows.push_back({e.name + ".p95", fmt::format("{}", d.percentile(95)), e.unit, "95th percentile"});
        rows.push_back({e.name + ".p99", fmt::format("{}", d.percentile(99)), e.unit, "99th percentile"});
        rows.push_back({e.name + ".max", fmt::format("{}", d.max()), e.unit, "maximum"});
        break;
      }
    }
  }
  size_t wn = 4, wv = 5, wu = 4;  // widths of "name", "value", "unit"
  for (const Row& r : rows) {
    wn = std::max(wn, r.name.size());
    wv = std::max(wv, r.value.size());
    wu = std::max(wu, r.unit.size());
  }
  out << fmt::format("{:<{}}  {:>{}}  {:<{}}  {}\n", "name", wn, "value", wv, "unit", wu, "description");
  out << fmt::format("{:-<{}}  {:->{}}  {:-<{}}  {:-<11}\n", "", wn, "", wv, "", wu, "");
  for (const Row& r : rows) {
    out << fmt::format("{:<{}}  {:>{}}  {:<{}}  {}\n", r.name, wn, r.value, wv, r.unit, wu, r.description);
  }
}

nlohmann::json StatsRegistry::to_json() const {
  nlohmann::json j = nlohmann::json::object();
  for (const Entry& e : entries_) {
    nlohmann::json s = {{"unit", e.unit}, {"description", e.description}};
    switch (e.kind) {
      case Kind::kCounter:
        s["value"] = e.counter->value;
        break;
      case Kind::kValue:
        s["value"] = e.value->value;
        break;
      case Kind::kDistribution: {
        const Distribution& d = *e.distribution;
        s["count"] = d.count();
        s["mean"] = d.mean();
        s["min"] = d.min();
        s["p50"] = d.percentile(50);
        s["p95"] = d.percentile(95);
        s["p99"] = d.percentile(99);
        s["max"] = d.max();
        break;
      }
    }
    j[e.name] = std::move(s);
  }
  return j;
}

}  // namespace edrnr
