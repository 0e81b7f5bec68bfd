#include "chip/feature_cache.h"

#include <algorithm>
#include <stdexcept>

#include "core/error.h"

namespace edrnr::chip {

const char* bank_mapping_name(BankMapping m) {
  switch (m) {
    case BankMapping::Balanced:
      return "balanced";
    case BankMapping::Direct:
      return "direct";
    case BankMapping::Linear:
      return "linear";
  }
  return "?";
}

BankMapping parse_bank_mapping(const std::string& name, const std::string& what) {
  if (name == "balanced") return BankMapping::Balanced;
  if (name == "direct") return BankMapping::Direct;
  if (name == "linear") return BankMapping::Linear;
  fail("{}: unknown bank mapping '{}' (expected balanced, direct or linear)", what, name);
}

int vertex_type(int vertex) {
  int i = vertex % kBlockVertsPerAxis, j = vertex / kBlockVertsPerAxis % kBlockVertsPerAxis,
      k = vertex / (kBlockVertsPerAxis * kBlockVertsPerAxis);
  return (i & 1) | (j & 1) << 1 | (k & 1) << 2;
}

BankLayout::BankLayout(BankMapping mapping, int lines) : mapping_(mapping), lines_(lines) {
  for (int v = 0; v < kBlockVerts; ++v) rank_[size_t(v)] = type_count_[size_t(vertex_type(v))]++;
  for (int rot = 0; rot < kFeatureBanks; ++rot)
    for (int b = 0; b < kFeatureBanks; ++b) {
      int offset = 0;
      for (int r = 0; r < rot; ++r) offset += type_count_[size_t(b ^ r)];
      group_offset_[size_t(rot)][size_t(b)] = offset;
    }
  for (int line = 0; line < lines; ++line)
    for (int b = 0; b < kFeatureBanks; ++b) depth_[size_t(b)] += rows_used(line, b);
}

int BankLayout::bank(int line, int vertex) const {
  switch (mapping_) {
    case BankMapping::Balanced:
      return vertex_type(vertex) ^ (line % kFeatureBanks);
    case BankMapping::Direct:
      return vertex_type(vertex);
    case BankMapping::Linear:
      return vertex % kFeatureBanks;
  }
  return 0;
}

int BankLayout::row(int line, int vertex) const {
  const int t = vertex_type(vertex);
  switch (mapping_) {
    case BankMapping::Balanced: {
      const int rot = line % kFeatureBanks, b = t ^ rot;
      return line / kFeatureBanks * kBlockVerts + group_offset_[size_t(rot)][size_t(b)] + rank_[size_t(vertex)];
    }
    case BankMapping::Direct:
      return line * type_count_[size_t(t)] + rank_[size_t(vertex)];
    case BankMapping::Linear:
      return line * ((kBlockVerts + kFeatureBanks - 1) / kFeatureBanks) + vertex / kFeatureBanks;
  }
  return 0;
}

int BankLayout::rows_used(int line, int bank_index) const {
  int n = 0;
  for (int v = 0; v < kBlockVerts; ++v) n += bank(line, v) == bank_index;
  return n;
}

std::array<int, 8> BankLayout::corner_banks(int line, const Vec3i& m) const {
  std::array<int, 8> out{};
  for (int c = 0; c < 8; ++c)
    out[size_t(c)] = bank(line, block_vertex(m.x + (c & 1), m.y + (c >> 1 & 1), m.z + (c >> 2 & 1)));
  return out;
}

int BankLayout::conflict_cycles(const std::array<int, 8>& banks) {
  std::array<int, kFeatureBanks> n{};
  for (int b : banks) ++n[size_t(b)];
  return *std::max_element(n.begin(), n.end()) - 1;
}

FeatureCache::FeatureCache(const FeatureCacheConfig& config)
    : config_(config), layout_(config.mapping, std::max(config.lines, 0)) {
  if (config.lines < 1) fail("feature cache lines must be at least 1 (got {})", config.lines);
  if (config.mshr_entries < 1) fail("feature cache MSHR entries must be at least 1 (got {})", config.mshr_entries);
  lines_.resize(size_t(config.lines));
}

int FeatureCache::find(uint32_t block) const { return block < line_of_.size() ? line_of_[block] : -1; }

bool FeatureCache::present(uint32_t block) const {
  int l = find(block);
  return l >= 0 && lines_[size_t(l)].state == State::Valid;
}

bool FeatureCache::pending(uint32_t block) const {
  int l = find(block);
  return l >= 0 && lines_[size_t(l)].state == State::Pending;
}

std::optional<int> FeatureCache::line_of(uint32_t block) const {
  int l = find(block);
  return l < 0 ? std::nullopt : std::optional<int>(l);
}

int FeatureCache::reservations(uint32_t block) const {
  int l = find(block);
  return l < 0 ? 0 : lines_[size_t(l)].reserved;
}

CacheAccess FeatureCache::request(uint32_t block) {
  ++counters_.requests;
  int l = find(block);
  if (l >= 0) {
    Line& line = lines_[size_t(l)];
    ++line.reserved;
    if (line.state == State::Valid) {
      ++counters_.hits;
      return CacheAccess::Hit;
    }
    ++counters_.merged_misses;
    return CacheAccess::MissMerged;
  }
  if (mshr_.size() >= size_t(config_.mshr_entries)) {
    ++counters_.stalls;
    return CacheAccess::Stall;
  }
  // Victim: an invalid line (lowest index), else the least recently used
  // valid line that no requester has reserved.
  int victim = -1;
  for (int i = 0; i < lines() && victim < 0; ++i)
    if (lines_[size_t(i)].state == State::Invalid) victim = i;
  if (victim < 0)
    for (int i = 0; i < lines(); ++i) {
      const Line& c = lines_[size_t(i)];
      if (c.state == State::Valid && c.reserved == 0 && (victim < 0 || c.last_use < lines_[size_t(victim)].last_use))
        victim = i;
    }
  if (victim < 0) {
    ++counters_.stalls;
    return CacheAccess::Stall;
  }
  Line& line = lines_[size_t(victim)];
  if (line.state == State::Valid) {
    line_of_[line.block] = -1;
    ++counters_.evictions;
  }
  line.state = State::Pending;
  line.block = block;
  line.reserved = 1;
  line.last_use = ++clock_;
  if (block >= line_of_.size()) line_of_.resize(size_t(block) + 1, -1);
  line_of_[block] = victim;
  mshr_.push_back(block);
  ++counters_.misses;
  counters_.peak_mshr_used = std::max<uint64_t>(counters_.peak_mshr_used, mshr_.size());
  uint64_t reserved = 0;
  for (const Line& c : lines_) reserved += c.reserved > 0;
  counters_.peak_reserved_lines = std::max(counters_.peak_reserved_lines, reserved);
  return CacheAccess::MissAllocated;
}

FeatureCache::Line& FeatureCache::line_for(uint32_t block, const char* op) {
  int l = find(block);
  if (l < 0) throw std::logic_error(std::string("feature cache ") + op + ": block not in the cache");
  return lines_[size_t(l)];
}

void FeatureCache::fill(uint32_t block) {
  auto it = std::find(mshr_.begin(), mshr_.end(), block);
  if (it == mshr_.end()) throw std::logic_error("feature cache fill: no MSHR entry for the block");
  mshr_.erase(it);
  line_for(block, "fill").state = State::Valid;
  ++counters_.fills;
}

int FeatureCache::use(uint32_t block) {
  Line& line = line_for(block, "use");
  if (line.state != State::Valid || line.reserved == 0)
    throw std::logic_error("feature cache use: line not valid or not reserved");
  line.last_use = ++clock_;
  return find(block);
}

void FeatureCache::release(uint32_t block) {
  Line& line = line_for(block, "release");
  if (line.reserved == 0) throw std::logic_error("feature cache release: line not reserved");
  --line.reserved;
}

}  // namespace edrnr::chip
