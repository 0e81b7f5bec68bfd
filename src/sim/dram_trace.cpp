#include "sim/dram_trace.h"

#include <fmt/format.h>

#include <charconv>
#include <iterator>
#include <memory>
#include <random>
#include <unordered_map>

#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"

namespace edrnr::sim {
namespace {

// Splits a line into white-space separated words.
std::vector<std::string_view> split_words(std::string_view line) {
  std::vector<std::string_view> words;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t' && line[i] != '\r') ++i;
    if (i > start) words.push_back(line.substr(start, i - start));
  }
  return words;
}

bool parse_u64(std::string_view s, int base, uint64_t& out) {
  if (s.empty()) return false;
  auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out, base);
  return ec == std::errc() && ptr == s.data() + s.size();
}

// A uniformly distributed double in [0, 1) from the top 53 bits (the same on
// every platform, unlike std::uniform_real_distribution).
double unit_real(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

}  // namespace

std::vector<DramTraceRecord> parse_dram_trace(std::string_view text, const std::string& origin) {
  std::vector<DramTraceRecord> records;
  uint64_t line_no = 0;
  size_t pos = 0;
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(pos, end - pos);
    pos = end + 1;
    ++line_no;
    std::vector<std::string_view> w = split_words(line);
    if (w.empty() || w[0][0] == '#') continue;
    if (w.size() != 3) {
      fail("{}:{}: expected '0xADDRESS READ|WRITE CYCLE', got {} fields", origin, line_no, w.size());
    }
    DramTraceRecord r;
    r.line = line_no;
    std::string_view a = w[0];
    bool hex = a.size() > 2 && a[0] == '0' && (a[1] == 'x' || a[1] == 'X');
    if (!parse_u64(hex ? a.substr(2) : a, hex ? 16 : 10, r.address)) {
      fail("{}:{}: address '{}' is not a hexadecimal (0x...) or decimal number", origin, line_no, a);
    }
    if (w[1] == "READ" || w[1] == "read") {
      r.op = DramOp::kRead;
    } else if (w[1] == "WRITE" || w[1] == "write") {
      r.op = DramOp::kWrite;
    } else {
      fail("{}:{}: request type '{}' must be READ or WRITE", origin, line_no, w[1]);
    }
    if (!parse_u64(w[2], 10, r.cycle)) fail("{}:{}: cycle '{}' is not a whole number", origin, line_no, w[2]);
    if (r.cycle > limits::kMaxDramTraceCycle)
      fail("{}:{}: cycle {} is over the limit of {} DRAM clocks for a trace request", origin, line_no, r.cycle,
           limits::kMaxDramTraceCycle);
    if (!records.empty() && r.cycle < records.back().cycle) {
      fail("{}:{}: cycle {} is earlier than the previous request's cycle {} (the trace must be in time order)", origin,
           line_no, r.cycle, records.back().cycle);
    }
    records.push_back(r);
  }
  return records;
}

std::vector<DramTraceRecord> load_dram_trace(const std::filesystem::path& path) {
  return parse_dram_trace(read_file_text(path, limits::kMaxTraceFileBytes), path.string());
}

void append_dram_trace(std::string& out, uint64_t address, uint64_t bytes, DramOp op, uint64_t cycle,
                       uint64_t burst_bytes) {
  if (bytes == 0 || burst_bytes == 0) return;
  const char* type = op == DramOp::kWrite ? "WRITE" : "READ";
  const uint64_t last = address + (bytes - 1);  // the last byte (no overflow past it)
  for (uint64_t a = address - address % burst_bytes;; a += burst_bytes) {
    fmt::format_to(std::back_inserter(out), "0x{:x} {} {}\n", a, type, cycle);
    if (last - a < burst_bytes) break;
  }
}

DramRequestSource trace_source(std::vector<DramTraceRecord> records) {
  auto shared = std::make_shared<std::vector<DramTraceRecord>>(std::move(records));
  auto next_index = std::make_shared<size_t>(0);
  return [shared, next_index](DramTraceRecord& next) {
    if (*next_index >= shared->size()) return false;
    next = (*shared)[(*next_index)++];
    return true;
  };
}

DramRequestSource random_source(const DramConfig& config, uint64_t count, double write_ratio, uint64_t seed) {
  auto rng = std::make_shared<std::mt19937_64>(seed);
  auto issued = std::make_shared<uint64_t>(0);
  const uint64_t bursts = config.capacity_bytes() / config.burst_bytes();
  const uint64_t burst_bytes = config.burst_bytes();
  return [=](DramTraceRecord& next) {
    if (*issued >= count) return false;
    ++*issued;
    next = DramTraceRecord{};
    next.address = ((*rng)() % bursts) * burst_bytes;
    next.op = unit_real(*rng) < write_ratio ? DramOp::kWrite : DramOp::kRead;
    return true;
  };
}

DramRequestSource stream_source(const DramConfig& config, uint64_t count, double write_ratio, uint64_t seed) {
  auto rng = std::make_shared<std::mt19937_64>(seed);
  auto issued = std::make_shared<uint64_t>(0);
  const uint64_t bursts = config.capacity_bytes() / config.burst_bytes();
  const uint64_t burst_bytes = config.burst_bytes();
  return [=](DramTraceRecord& next) {
    if (*issued >= count) return false;
    next = DramTraceRecord{};
    next.address = (*issued % bursts) * burst_bytes;
    next.op = unit_real(*rng) < write_ratio ? DramOp::kWrite : DramOp::kRead;
    ++*issued;
    return true;
  };
}

uint64_t run_dram_workload(DramSystem& dram, const DramRequestSource& source, Distribution* read_latency_from_arrival) {
  const DramConfig& c = dram.config();
  const uint64_t burst_bytes = c.burst_bytes();
  // Far longer than any legal wait: a refresh plus a full queue of conflicts.
  const uint64_t stall_limit =
      1000 + 4ull * (c.tREFI + c.tRFC) + uint64_t{c.queue_depth_bursts} * c.channels * (c.tRC + c.tFAW + c.tWR + 64);
  DramTraceRecord next;
  bool have = source(next);
  uint64_t accepted = 0;
  uint64_t last_progress = dram.cycle();
  std::unordered_map<uint64_t, uint64_t> read_arrival;  // id -> arrival cycle, reads in flight
  while (have || !dram.idle()) {
    // Nothing in flight until the next arrival: jump there (exactly as ticking).
    if (have && dram.idle() && next.cycle > dram.cycle()) dram.advance_idle(next.cycle);
    while (have && next.cycle <= dram.cycle()) {
      uint64_t address = next.address - next.address % burst_bytes;
      if (address >= c.capacity_bytes()) {
        fail("trace line {}: address 0x{:x} is beyond the DRAM capacity of {} bytes (0x{:x})", next.line, next.address,
             c.capacity_bytes(), c.capacity_bytes());
      }
      if (!dram.enqueue(next.op, address, static_cast<uint32_t>(burst_bytes), accepted)) break;
      if (read_latency_from_arrival && next.op == DramOp::kRead) read_arrival.emplace(accepted, next.cycle);
      ++accepted;
      last_progress = dram.cycle();
      have = source(next);
    }
    dram.tick();
    while (const auto done = dram.pop_completion()) {
      last_progress = dram.cycle();
      if (read_latency_from_arrival && done->op == DramOp::kRead) {
        const auto it = read_arrival.find(done->id);
        read_latency_from_arrival->add(done->done_cycle - it->second);
        read_arrival.erase(it);
      }
    }
    if (!dram.idle() && dram.cycle() - last_progress > stall_limit) {
      fail("DRAM model made no progress for {} cycles with {} requests in flight (internal fault)", stall_limit,
           dram.requests_in_flight());
    }
  }
  return accepted;
}

}  // namespace edrnr::sim
