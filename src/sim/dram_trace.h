#pragma once
// Workloads for running the DRAM model on its own: the common trace format
// (as DRAMsim3 reads it) and synthetic random / streaming traffic.
//
// Trace format, one request a line:  0xADDRESS READ|WRITE CYCLE
// CYCLE is the DRAM clock at which the request arrives; lines must be in
// non-decreasing cycle order. Blank lines and lines starting with '#' are
// skipped. Each request is one burst: the burst_bytes() block that contains
// ADDRESS.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "core/stats.h"
#include "sim/dram.h"

namespace edrnr::sim {

struct DramTraceRecord {
  uint64_t address = 0;
  DramOp op = DramOp::kRead;
  uint64_t cycle = 0;  // arrival, in DRAM clocks
  uint64_t line = 0;   // line number in the trace file (0 for synthetic traffic)
};

// Parses a whole trace. Throws Error naming `origin` and the line number for a
// malformed line or a cycle smaller than the previous line's.
std::vector<DramTraceRecord> parse_dram_trace(std::string_view text, const std::string& origin);
std::vector<DramTraceRecord> load_dram_trace(const std::filesystem::path& path);

// Appends to `out` one trace line per burst_bytes-aligned block that
// [address, address + bytes) overlaps, all arriving at `cycle` (DRAM clocks):
// the request as the DRAM model splits it into bursts. bytes == 0 appends
// nothing.
void append_dram_trace(std::string& out, uint64_t address, uint64_t bytes, DramOp op, uint64_t cycle,
                       uint64_t burst_bytes);

// A source of requests in arrival order: writes the next one and returns true,
// or returns false when there are no more.
using DramRequestSource = std::function<bool(DramTraceRecord& next)>;

DramRequestSource trace_source(std::vector<DramTraceRecord> records);
// `count` one-burst requests at uniformly random burst addresses over the
// whole capacity, all arriving at cycle 0 (so they enter as fast as the queue
// accepts them). Each is a write with probability write_ratio. Deterministic
// for a given seed.
DramRequestSource random_source(const DramConfig& config, uint64_t count, double write_ratio, uint64_t seed);
// `count` one-burst requests at consecutive burst addresses from 0 (wrapping
// at the capacity), all arriving at cycle 0; writes chosen as above.
DramRequestSource stream_source(const DramConfig& config, uint64_t count, double write_ratio, uint64_t seed);

// Feeds the source into `dram` (in order; a request enters at its cycle or as
// soon after as the queue has room) and ticks until every request has
// completed. Returns the number of requests. Throws Error naming the trace
// line if an address is beyond the capacity, or if the model stops making
// progress (an internal fault). If `read_latency_from_arrival` is given, it
// gets each read's DRAM clocks from its arrival cycle in the source to its
// last data: the latency its client sees, waiting for room in the queue
// included (the model's own read latency counts from entry).
uint64_t run_dram_workload(DramSystem& dram, const DramRequestSource& source,
                           Distribution* read_latency_from_arrival = nullptr);

}  // namespace edrnr::sim
