#include "sim/cache.h"

#include <algorithm>

#include "core/error.h"

namespace edrnr::sim {

std::string_view replacement_name(Replacement r) {
  switch (r) {
    case Replacement::Lru:
      return "lru";
    case Replacement::Fifo:
      return "fifo";
    case Replacement::Random:
      return "random";
    case Replacement::TreePlru:
      return "plru";
  }
  return "?";
}

Replacement parse_replacement(std::string_view text, std::string_view field) {
  for (Replacement r : {Replacement::Lru, Replacement::Fifo, Replacement::Random, Replacement::TreePlru})
    if (text == replacement_name(r)) return r;
  fail("{}: unknown replacement policy '{}' (expected lru, fifo, random or plru)", field, text);
}

void validate(const CacheConfig& c) {
  if (c.line_bytes == 0) fail("cache '{}': line_bytes must be at least 1", c.name);
  if (c.size_bytes == 0) fail("cache '{}': size_bytes must be at least 1", c.name);
  if (c.size_bytes % c.line_bytes != 0)
    fail("cache '{}': size_bytes ({}) is not a multiple of line_bytes ({})", c.name, c.size_bytes, c.line_bytes);
  uint64_t lines = c.size_bytes / c.line_bytes;
  uint64_t ways = c.ways == kFullyAssociative ? lines : c.ways;
  if (ways > lines) fail("cache '{}': ways ({}) exceeds the number of lines ({})", c.name, ways, lines);
  if (lines % ways != 0) fail("cache '{}': the line count ({}) is not a multiple of ways ({})", c.name, lines, ways);
  if (c.replacement == Replacement::TreePlru && (ways & (ways - 1)) != 0)
    fail("cache '{}': replacement plru needs ways to be a power of two, got {}", c.name, ways);
  if (c.banks == 0) fail("cache '{}': banks must be at least 1", c.name);
  if (c.mshr_entries == 0) fail("cache '{}': mshr_entries must be at least 1", c.name);
}

CacheConfig micro_grid_cache_config() {
  CacheConfig c;
  c.name = "micro_grid";
  c.size_bytes = 8 * 1024;
  c.line_bytes = 64;
  c.ways = 4;
  c.banks = 1;
  c.mshr_entries = 4;
  return c;
}

CacheConfig feature_cache_config() {
  CacheConfig c;
  c.name = "feature";
  c.size_bytes = 256 * 1024;
  c.line_bytes = 1024;         // one fine-voxel block (125 vertices x 8 bytes) padded to 1 KB
  c.ways = kFullyAssociative;  // as the CFIU's functional feature cache (src/chip/feature_cache.h)
  c.banks = 8;
  c.bank_interleave_bytes = 8;  // one 16-channel INT4 vertex vector per bank word
  c.mshr_entries = 16;
  return c;
}

CacheConfig mlp_cache_config() {
  CacheConfig c;
  c.name = "mlp";
  c.size_bytes = 8448;  // 8.25 KB
  c.line_bytes = 64;
  c.ways = kFullyAssociative;
  c.banks = 1;
  c.mshr_entries = 4;
  return c;
}

BankCycleResult count_bank_conflicts(std::span<const BankAccess> accesses) {
  std::vector<std::pair<uint64_t, uint64_t>> distinct;
  distinct.reserve(accesses.size());
  for (const BankAccess& a : accesses) distinct.emplace_back(a.bank, a.row);
  std::sort(distinct.begin(), distinct.end());
  distinct.erase(std::unique(distinct.begin(), distinct.end()), distinct.end());
  BankCycleResult r;
  size_t i = 0;
  while (i < distinct.size()) {
    size_t j = i;
    while (j < distinct.size() && distinct[j].first == distinct[i].first) ++j;
    uint64_t rows = j - i;
    r.conflicts += rows - 1;
    r.cycles = std::max(r.cycles, rows);
    i = j;
  }
  return r;
}

Cache::Cache(const CacheConfig& config)
    : config_(config), mshr_(config.name, std::max<size_t>(config.mshr_entries, 1)) {
  validate(config_);
  uint64_t lines = config_.size_bytes / config_.line_bytes;
  ways_ = config_.ways == kFullyAssociative ? lines : config_.ways;
  sets_ = lines / ways_;
  interleave_bytes_ = config_.bank_interleave_bytes ? config_.bank_interleave_bytes : config_.line_bytes;
  ways_store_.resize(sets_ * ways_);
  if (config_.replacement == Replacement::TreePlru) plru_bits_.assign(sets_ * (ways_ - 1), 0);
  random_state_ = config_.random_seed;
  where_.reserve(lines);
}

BankAccess Cache::bank_of(uint64_t addr) const {
  uint64_t word = addr / interleave_bytes_;
  return BankAccess{word % config_.banks, word / config_.banks};
}

bool Cache::lookup(uint64_t addr) const { return where_.count(line_number(addr)) != 0; }

bool Cache::reserved_line(uint64_t line) const { return reserved_.count(line) != 0; }

uint64_t Cache::next_random() {
  // splitmix64: the same sequence on every platform for a given seed.
  uint64_t z = (random_state_ += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

void Cache::touch(uint64_t set, uint64_t way) {
  way_ptr(set, way)->last_use = ++stamp_;
  if (config_.replacement != Replacement::TreePlru || ways_ == 1) return;
  // Heap-ordered tree: node n has children 2n and 2n+1, leaves are ways_ + way.
  // Each node's bit points to the half holding the next victim: away from `way`.
  uint8_t* bits = &plru_bits_[set * (ways_ - 1)];
  uint64_t node = ways_ + way;
  while (node > 1) {
    uint64_t parent = node / 2;
    bits[parent - 1] = (node % 2 == 0) ? 1 : 0;  // came from the left: point right
    node = parent;
  }
}

uint64_t Cache::plru_victim(uint64_t set) {
  if (ways_ == 1) return 0;
  // Eligible ways per subtree, so the walk can avoid halves that are all reserved.
  std::vector<uint64_t>& count = plru_count_;
  count.assign(2 * ways_, 0);
  for (uint64_t w = 0; w < ways_; ++w) count[ways_ + w] = eligible_[w] ? 1 : 0;
  for (uint64_t n = ways_ - 1; n >= 1; --n) count[n] = count[2 * n] + count[2 * n + 1];
  const uint8_t* bits = &plru_bits_[set * (ways_ - 1)];
  uint64_t node = 1;
  while (node < ways_) {
    uint64_t preferred = 2 * node + bits[node - 1];
    uint64_t other = preferred ^ 1;
    node = count[preferred] > 0 ? preferred : other;
  }
  return node - ways_;
}

uint64_t Cache::choose_victim(uint64_t set) {
  for (uint64_t w = 0; w < ways_; ++w)
    if (!way_ptr(set, w)->valid) return w;
  // Eligible ways: those holding no reserved line (no lookups when nothing is reserved).
  const bool any_reserved = !reserved_.empty();
  eligible_.assign(ways_, 1);
  uint64_t n_eligible = ways_;
  if (any_reserved)
    for (uint64_t w = 0; w < ways_; ++w)
      if (reserved_line(way_ptr(set, w)->line)) {
        eligible_[w] = 0;
        --n_eligible;
      }
  if (n_eligible == 0) return ways_;
  uint64_t best = ways_;
  switch (config_.replacement) {
    case Replacement::Lru:
    case Replacement::Fifo: {
      // The eligible way with the smallest stamp (stamps are unique).
      const bool lru = config_.replacement == Replacement::Lru;
      uint64_t best_key = 0;
      for (uint64_t w = 0; w < ways_; ++w) {
        if (!eligible_[w]) continue;
        const Way* a = way_ptr(set, w);
        const uint64_t key = lru ? a->last_use : a->filled;
        if (best == ways_ || key < best_key) {
          best = w;
          best_key = key;
        }
      }
      return best;
    }
    case Replacement::Random: {
      uint64_t pick = next_random() % n_eligible;
      for (uint64_t w = 0; w < ways_; ++w)
        if (eligible_[w] && pick-- == 0) return w;
      return ways_;
    }
    case Replacement::TreePlru:
      return plru_victim(set);
  }
  return best;
}

void Cache::record(uint64_t cycle, bool hit) {
  ++stats_.accesses;
  if (hit)
    ++stats_.hits;
  else
    ++stats_.misses;
  uint64_t window = config_.hit_rate_window_cycles;
  if (window == 0) return;
  uint64_t index = cycle / window;
  while (series_.size() <= index) series_.push_back(HitRateWindow{series_.size() * window, 0, 0});
  ++series_[index].accesses;
  if (hit) ++series_[index].hits;
}

CacheOutcome Cache::access(uint64_t addr, uint64_t cycle) {
  uint64_t line = line_number(addr);
  if (auto it = where_.find(line); it != where_.end()) {
    touch(it->second / ways_, it->second % ways_);
    record(cycle, true);
    return CacheOutcome::Hit;
  }
  switch (mshr_.on_miss(line, cycle)) {
    case MshrOutcome::Full:
      ++stats_.mshr_full_stalls;
      return CacheOutcome::MissStalled;
    case MshrOutcome::Merged:
      ++stats_.misses_merged;
      record(cycle, false);
      return CacheOutcome::MissMerged;
    case MshrOutcome::Allocated:
      break;
  }
  ++stats_.misses_issued;
  record(cycle, false);
  return CacheOutcome::MissIssued;
}

CacheOutcome Cache::prefetch(uint64_t addr, uint64_t cycle) {
  const uint64_t line = line_number(addr);
  if (where_.count(line)) return CacheOutcome::Hit;
  if (mshr_.outstanding(line)) return CacheOutcome::MissMerged;
  if (mshr_.full()) return CacheOutcome::MissStalled;
  mshr_.on_miss(line, cycle);
  ++stats_.prefetches_issued;
  return CacheOutcome::MissIssued;
}

bool Cache::access_and_fill(uint64_t addr, uint64_t cycle) {
  uint64_t line = line_number(addr);
  if (auto it = where_.find(line); it != where_.end()) {
    touch(it->second / ways_, it->second % ways_);
    record(cycle, true);
    return true;
  }
  ++stats_.misses_issued;
  record(cycle, false);
  fill(addr, cycle);
  return false;
}

void Cache::schedule_fill(uint64_t addr, uint64_t fill_cycle) {
  uint64_t line = line_number(addr);
  if (!mshr_.outstanding(line))
    fail("cache '{}': schedule_fill for line {}, which has no outstanding miss", name(), line);
  mshr_.schedule_fill(line, fill_cycle);
}

FillResult Cache::fill(uint64_t addr, uint64_t cycle) {
  uint64_t line = line_number(addr);
  FillResult r;
  if (where_.count(line)) {
    if (mshr_.outstanding(line)) mshr_.retire(line, cycle);
    r.filled = true;
    return r;
  }
  uint64_t set = line % sets_;
  uint64_t w = choose_victim(set);
  if (w == ways_) {
    ++stats_.fill_stalls;
    return r;
  }
  Way* way = way_ptr(set, w);
  if (way->valid) {
    r.evicted = true;
    r.victim_line = way->line;
    where_.erase(way->line);
    ++stats_.evictions;
  }
  way->valid = true;
  way->line = line;
  way->filled = ++stamp_;
  touch(set, w);
  where_[line] = set * ways_ + w;
  ++stats_.fills;
  if (mshr_.outstanding(line)) mshr_.retire(line, cycle);
  r.filled = true;
  return r;
}

std::vector<uint64_t> Cache::tick(uint64_t cycle) {
  std::vector<uint64_t> filled;
  for (uint64_t line : mshr_.arrived(cycle))
    if (fill(line * config_.line_bytes, cycle).filled) filled.push_back(line);
  return filled;
}

void Cache::reserve(uint64_t addr) { ++reserved_[line_number(addr)]; }

void Cache::release(uint64_t addr) {
  uint64_t line = line_number(addr);
  auto it = reserved_.find(line);
  if (it == reserved_.end()) fail("cache '{}': release of line {}, which holds no reservation", name(), line);
  if (--it->second == 0) reserved_.erase(it);
}

uint32_t Cache::reservations(uint64_t addr) const {
  auto it = reserved_.find(line_number(addr));
  return it == reserved_.end() ? 0 : it->second;
}

BankCycleResult Cache::present_cycle(std::span<const uint64_t> addrs) {
  std::vector<BankAccess> accesses;
  accesses.reserve(addrs.size());
  for (uint64_t a : addrs) accesses.push_back(bank_of(a));
  return present_cycle(std::span<const BankAccess>(accesses));
}

BankCycleResult Cache::present_cycle(std::span<const BankAccess> accesses) {
  for (const BankAccess& a : accesses)
    if (a.bank >= config_.banks)
      fail("cache '{}': bank {} out of range (the cache has {} banks)", name(), a.bank, config_.banks);
  BankCycleResult r = count_bank_conflicts(accesses);
  if (!accesses.empty()) {
    ++stats_.bank_access_cycles;
    stats_.bank_accesses += accesses.size();
    stats_.bank_conflicts += r.conflicts;
    stats_.bank_conflict_cycles += r.cycles - 1;
  }
  return r;
}

void Cache::export_stats(StatsRegistry& registry, const std::string& prefix) const {
  auto counter = [&](const char* name, const char* unit, const char* description, uint64_t v) {
    registry.counter(prefix + "." + name, unit, description).value = v;
  };
  counter("size_bytes", "bytes", "capacity", config_.size_bytes);
  counter("accesses", "requests", "requests served (hits + misses; stalled retries excluded)", stats_.accesses);
  counter("hits", "requests", "requests that found their line resident", stats_.hits);
  counter("misses", "requests", "requests that did not (issued + merged)", stats_.misses);
  registry.value(prefix + ".hit_rate", "ratio", "hits / accesses").set(stats_.hit_rate());
  counter("misses_issued", "lines", "misses that opened an MSHR entry: DRAM line requests", stats_.misses_issued);
  counter("misses_merged", "requests", "misses merged into an outstanding MSHR entry", stats_.misses_merged);
  counter("mshr_full_stalls", "attempts", "requests refused because the MSHR was full", stats_.mshr_full_stalls);
  counter("fills", "lines", "lines allocated", stats_.fills);
  counter("evictions", "lines", "valid lines replaced by a fill", stats_.evictions);
  counter("fill_stalls", "attempts", "fills refused because every way of the set was reserved", stats_.fill_stalls);
  counter("prefetches_issued", "lines", "prefetches that fetched a line from DRAM", stats_.prefetches_issued);
  counter("bank_access_cycles", "cycles", "cycles with at least one bank access", stats_.bank_access_cycles);
  counter("bank_accesses", "accesses", "bank accesses presented", stats_.bank_accesses);
  counter("bank_conflicts", "accesses", "accesses delayed behind another row of the same bank", stats_.bank_conflicts);
  counter("bank_conflict_cycles", "cycles", "extra cycles spent on bank conflicts", stats_.bank_conflict_cycles);
  const MshrStats& m = mshr_.stats();
  counter("mshr_max_occupancy", "entries", "most MSHR entries outstanding at once", m.max_occupancy);
  registry.value(prefix + ".mshr_mean_latency", "cycles", "miss latency, MSHR allocation to fill, averaged")
      .set(m.mean_latency_cycles());
}

nlohmann::json hit_rate_series_json(const std::vector<HitRateWindow>& series, uint64_t window_cycles) {
  nlohmann::json windows = nlohmann::json::array();
  for (const HitRateWindow& w : series) {
    nlohmann::json row = {{"start_cycle", w.start_cycle}, {"hits", w.hits}, {"accesses", w.accesses}};
    row["hit_rate"] = w.accesses ? nlohmann::json(double(w.hits) / double(w.accesses)) : nlohmann::json(nullptr);
    windows.push_back(std::move(row));
  }
  return {{"window_cycles", window_cycles}, {"windows", std::move(windows)}};
}

}  // namespace edrnr::sim
