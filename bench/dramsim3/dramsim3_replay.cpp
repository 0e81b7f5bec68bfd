// Replays a DRAM trace in edrnr's format (src/sim/dram_trace.h:
// "0xADDRESS READ|WRITE CYCLE", one burst a line) through DRAMsim3, with the
// entry rule of edrnr's workload driver (run_dram_workload): requests enter
// in trace order, each at its cycle or as soon after as the controller
// accepts it, and a refused request holds back the ones behind it.
//
// Built by run-crosscheck.sh against a DRAMsim3 source checkout; not part of
// the project's build. Usage:
//   dramsim3_replay CONFIG.ini TRACE OUTPUT_DIR
// Prints "name value" lines: requests, reads, writes, bytes, cycles (until the
// last read has returned and the last request has entered), read latency
// (mean, p50, p99, max in DRAM cycles from entry to the read callback, as
// DRAMsim3 counts it) and the same from the trace's arrival cycle (waiting for
// room included), bandwidth_GBps (bytes / (cycles * tCK)), and from DRAMsim3's
// own statistics the row-buffer hit rate and command counts.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "json.hpp"  // nlohmann::json as DRAMsim3 bundles it (ext/headers)
#include "memory_system.h"

namespace {

struct Request {
  uint64_t address = 0;
  bool write = false;
  uint64_t cycle = 0;
};

[[noreturn]] void die(const std::string& what) {
  std::fprintf(stderr, "dramsim3_replay: %s\n", what.c_str());
  std::exit(1);
}

std::vector<Request> read_trace(const std::string& path) {
  std::ifstream in(path);
  if (!in) die("cannot open trace '" + path + "'");
  std::vector<Request> out;
  std::string line, addr, type;
  uint64_t line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    std::istringstream words(line);
    Request r;
    if (!(words >> addr) || addr[0] == '#') continue;
    if (!(words >> type >> r.cycle)) die(path + ":" + std::to_string(line_no) + ": malformed line");
    r.address = std::stoull(addr, nullptr, addr.size() > 2 && addr[1] == 'x' ? 16 : 10);
    if (type == "WRITE" || type == "write") {
      r.write = true;
    } else if (type != "READ" && type != "read") {
      die(path + ":" + std::to_string(line_no) + ": type must be READ or WRITE");
    }
    if (!out.empty() && r.cycle < out.back().cycle) die(path + ":" + std::to_string(line_no) + ": cycle decreases");
    out.push_back(r);
  }
  return out;
}

// Nearest-rank percentile, as edrnr's Distribution::percentile computes it.
uint64_t percentile(std::vector<uint64_t>& sorted, double p) {
  if (sorted.empty()) return 0;
  const size_t rank = std::max<size_t>(1, size_t(std::ceil(p / 100.0 * double(sorted.size()))));
  return sorted[std::min(rank, sorted.size()) - 1];
}

uint64_t stat(const nlohmann::json& channel, const char* name) {
  auto it = channel.find(name);
  return it == channel.end() ? 0 : it->get<uint64_t>();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 4) die("usage: dramsim3_replay CONFIG.ini TRACE OUTPUT_DIR");
  const std::vector<Request> trace = read_trace(argv[2]);
  std::string out_dir = argv[3];
  if (out_dir.back() != '/') out_dir += '/';

  uint64_t clk = 0;
  // Entry cycles of reads not yet returned, per address (DRAMsim3 returns
  // reads of one address together, oldest first).
  // Entry and arrival cycles of the reads in flight, per address.
  std::unordered_map<uint64_t, std::deque<std::pair<uint64_t, uint64_t>>> pending;
  std::vector<uint64_t> latencies, from_arrival;
  latencies.reserve(trace.size());
  from_arrival.reserve(trace.size());
  uint64_t reads_pending = 0, last_callback = 0;
  auto on_read = [&](uint64_t address) {
    auto it = pending.find(address);
    if (it == pending.end() || it->second.empty()) die("read callback for an address never read");
    latencies.push_back(clk - it->second.front().first);
    from_arrival.push_back(clk - it->second.front().second);
    it->second.pop_front();
    --reads_pending;
    last_callback = clk;
  };
  auto on_write = [&](uint64_t) { last_callback = clk; };
  auto* mem = new dramsim3::MemorySystem(argv[1], out_dir, on_read, on_write);
  const double tCK_ns = mem->GetTCK();
  const uint64_t burst_bytes = uint64_t(mem->GetBusBits() / 8 * mem->GetBurstLength());

  size_t next = 0;
  uint64_t reads = 0, writes = 0, last_entry = 0;
  while (next < trace.size() || reads_pending > 0) {
    // Nothing in flight until the next arrival: DRAMsim3 still ticks (refresh).
    while (next < trace.size() && trace[next].cycle <= clk) {
      const Request& r = trace[next];
      const uint64_t a = r.address - r.address % burst_bytes;
      if (!mem->WillAcceptTransaction(a, r.write)) break;
      mem->AddTransaction(a, r.write);
      last_entry = clk;
      if (r.write) {
        ++writes;
      } else {
        ++reads;
        ++reads_pending;
        pending[a].emplace_back(clk, r.cycle);
      }
      ++next;
    }
    mem->ClockTick();  // read callbacks of this cycle run inside, with clk unchanged
    ++clk;
  }
  const uint64_t cycles = std::max(last_callback, last_entry) + 1;
  mem->PrintStats();

  std::ifstream stats_in(out_dir + "dramsim3.json");
  if (!stats_in) die("DRAMsim3 wrote no " + out_dir + "dramsim3.json");
  const nlohmann::json stats = nlohmann::json::parse(stats_in);
  uint64_t rd = 0, wr = 0, rd_hits = 0, wr_hits = 0, act = 0, pre = 0, ref = 0;
  for (const auto& [name, channel] : stats.items()) {
    rd += stat(channel, "num_read_cmds");
    wr += stat(channel, "num_write_cmds");
    rd_hits += stat(channel, "num_read_row_hits");
    wr_hits += stat(channel, "num_write_row_hits");
    act += stat(channel, "num_act_cmds");
    pre += stat(channel, "num_pre_cmds");
    ref += stat(channel, "num_ref_cmds");
  }

  const uint64_t bytes = (reads + writes) * burst_bytes;
  std::printf("requests %zu\nreads %llu\nwrites %llu\nbytes %llu\ncycles %llu\n", trace.size(),
              (unsigned long long)reads, (unsigned long long)writes, (unsigned long long)bytes,
              (unsigned long long)cycles);
  for (auto [name, samples] : {std::pair{"read_latency", &latencies}, std::pair{"arrival_latency", &from_arrival}}) {
    std::vector<uint64_t>& v = *samples;
    std::sort(v.begin(), v.end());
    double mean = 0;
    for (uint64_t x : v) mean += double(x);
    if (!v.empty()) mean /= double(v.size());
    std::printf("%s_mean %.4f\n%s_p50 %llu\n%s_p99 %llu\n%s_max %llu\n", name, mean, name,
                (unsigned long long)percentile(v, 50), name, (unsigned long long)percentile(v, 99), name,
                (unsigned long long)(v.empty() ? 0 : v.back()));
  }
  std::printf("bandwidth_GBps %.6f\n", double(bytes) / (double(cycles) * tCK_ns));
  std::printf("rd_cmds %llu\nwr_cmds %llu\nrow_hit_rate %.6f\nact_cmds %llu\npre_cmds %llu\nref_cmds %llu\n",
              (unsigned long long)rd, (unsigned long long)wr,
              rd + wr ? double(rd_hits + wr_hits) / double(rd + wr) : 0.0, (unsigned long long)act,
              (unsigned long long)pre, (unsigned long long)ref);
  delete mem;
  return 0;
}
