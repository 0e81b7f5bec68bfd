#pragma once
// Cycle-level DDR3 memory system: channels of ranks of banks with row buffers,
// the JEDEC command timing constraints, all-bank refresh, an open-page FR-FCFS
// controller per channel with a bounded queue, and current-based energy
// (Micron TN-41-01). Everything advances per DRAM clock (tCK from the config);
// a client with another clock calls tick() at the DRAM's rate.
//
// Client protocol:
//   if (dram.enqueue(DramOp::kRead, address, bytes, id)) { ...accepted... } else { ...retry later... }
//   dram.tick();                                  // one DRAM clock
//   while (auto done = dram.pop_completion()) ... // requests whose last data moved
// A request covers every burst (burst_bytes() aligned block) that overlaps
// [address, address + bytes); it completes when the data of its last burst has
// crossed the bus. Its latency is done_cycle - arrival_cycle, where arrival is
// the cycle() at which enqueue accepted it.
#include <cstdint>
#include <deque>
#include <optional>
#include <queue>
#include <string>
#include <vector>

#include "core/stats.h"
#include "sim/dram_config.h"

namespace edrnr::sim {

enum class DramOp : uint8_t { kRead, kWrite };

// DRAM commands, for counts and the optional command log.
enum class DramCommand : uint8_t { kActivate, kPrecharge, kRead, kWrite, kRefresh };
const char* dram_command_name(DramCommand c);

struct DramCompletion {
  uint64_t id = 0;
  DramOp op = DramOp::kRead;
  uint64_t address = 0;
  uint32_t bytes = 0;
  uint64_t arrival_cycle = 0;
  uint64_t done_cycle = 0;
  uint64_t latency_cycles() const { return done_cycle - arrival_cycle; }
};

// Where one burst lives.
struct DramLocation {
  uint32_t channel = 0, rank = 0, bank = 0, row = 0, column = 0;  // column counts bursts within the row
};

// One issued command (for tests and debugging; off unless enabled).
struct DramCommandRecord {
  uint64_t cycle = 0;
  DramCommand command = DramCommand::kActivate;
  DramLocation location;  // row/column meaningful for ACT and RD/WR
};

// Energy in pJ, from the TN-41-01 current-based method, per rank of
// devices_per_rank() devices (an I * V * cycles product times tCK_ns is pJ).
struct DramEnergy {
  double activate_pJ = 0;    // VDD*(IDD0*tRC - IDD3N*tRAS - IDD2N*(tRC-tRAS))*tCK per activate (includes its precharge)
  double read_pJ = 0;        // VDD*(IDD4R-IDD3N)*tBURST*tCK per read burst
  double write_pJ = 0;       // VDD*(IDD4W-IDD3N)*tBURST*tCK per write burst
  double refresh_pJ = 0;     // VDD*(IDD5-IDD3N)*tRFC*tCK per refresh
  double background_pJ = 0;  // VDD*IDD3N (a bank open or refreshing) or VDD*IDD2N (all closed) per cycle
  double io_pJ = 0;          // io_pJ_per_bit * bits moved
  double total_pJ() const { return activate_pJ + read_pJ + write_pJ + refresh_pJ + background_pJ + io_pJ; }
};

class DramSystem {
 public:
  // Validates the config (throws Error) and registers its statistics under
  // "<prefix>." in `stats`, which must outlive this object.
  DramSystem(const DramConfig& config, StatsRegistry& stats, const std::string& prefix = "dram");

  const DramConfig& config() const { return config_; }
  uint64_t cycle() const { return cycle_; }  // DRAM clocks ticked so far

  // Maps a byte address to its burst's location (the address must be below
  // capacity_bytes()).
  DramLocation locate(uint64_t address) const;

  // True if enqueue would accept the request now (room in every channel queue
  // it touches). A request needing more bursts in one channel than
  // queue_depth_bursts can never be accepted: enqueue throws Error for it.
  bool can_accept(uint64_t address, uint32_t bytes) const;
  // Accepts the request at cycle() and returns true, or returns false
  // (back-pressure: nothing changed). Throws Error if bytes == 0, the range
  // runs past capacity_bytes(), or the request can never fit (see above).
  bool enqueue(DramOp op, uint64_t address, uint32_t bytes, uint64_t id);

  // Advances one DRAM clock: each channel issues at most one command, then
  // requests whose data has finished become completions.
  void tick();
  // Advances to cycle `target` while no request is in flight, with the same
  // result as ticking there one clock at a time (refreshes, background
  // cycles, statistics), but jumping over the stretches in which nothing can
  // happen. Returns at once if a request is in flight.
  void advance_idle(uint64_t target);
  // Advances to cycle `target` with the same result as ticking there one
  // clock at a time, ticking only in the cycles in which a command may issue
  // or a request may complete and counting the cycles between in bulk.
  void advance_quiet(uint64_t target);
  // The first cycle >= cycle() whose tick may issue a command or complete a
  // request (UINT64_MAX when none can until a request arrives).
  uint64_t next_event_cycle() const;

  // Completed requests in completion order (ties: the order their last bursts
  // were issued).
  std::optional<DramCompletion> pop_completion();
  size_t completions_waiting() const { return completions_.size(); }

  // Requests accepted but not yet completed.
  uint64_t requests_in_flight() const { return requests_in_flight_; }
  bool idle() const { return requests_in_flight_ == 0; }

  DramEnergy energy() const;

  // Writes the derived statistics (bandwidth, hit rate, energy, latencies in
  // ns) into the registry. Call before printing the registry.
  void update_stats();

  // Records every issued command into command_log() (for tests; costs memory).
  void enable_command_log(bool on) { log_commands_ = on; }
  const std::vector<DramCommandRecord>& command_log() const { return command_log_; }

 private:
  static constexpr uint32_t kClosed = UINT32_MAX;

  struct Bank {
    uint32_t open_row = kClosed;
    uint64_t act_ready = 0;  // earliest ACT (tRC, tRP, tRFC)
    uint64_t pre_ready = 0;  // earliest PRE (tRAS, tRTP, write recovery)
    uint64_t cas_ready = 0;  // earliest RD/WR (tRCD)
    // Bursts of this bank in the channel queue, and those of them that hit
    // the open row, by operation (kept as bursts arrive and commands issue).
    uint32_t queued = 0, hit_reads = 0, hit_writes = 0;
    bool has_hit() const { return hit_reads + hit_writes > 0; }
  };
  struct Rank {
    std::vector<Bank> banks;
    uint32_t open_banks = 0;
    uint64_t act_ready = 0;                  // tRRD
    uint64_t rd_ready = 0;                   // tCCD, write-to-read
    uint64_t wr_ready = 0;                   // tCCD, read-to-write
    uint64_t ref_ready = 0;                  // tRP after the last precharge
    uint64_t act_history[4] = {0, 0, 0, 0};  // cycles of the last four ACTs (ring)
    uint32_t act_count = 0;                  // ACTs issued so far (saturating use: >= 4 enables tFAW)
    uint64_t refresh_due = 0;
    uint64_t refresh_end = 0;  // REF issued: busy until this cycle
    bool refresh_pending = false;
  };
  // Queued bursts of one request that follow each other in the queue and
  // differ only in the column (consecutive): they share every readiness
  // condition, so the scheduler meets the first of them before the others
  // and they issue in order. One entry stands for them all.
  struct Burst {
    uint64_t request = 0;  // index into requests_ slot
    DramOp op = DramOp::kRead;
    DramLocation loc;               // of the first burst of the run
    uint32_t count = 1;             // bursts in the run (columns loc.column, loc.column + 1, ...)
    bool caused_activate = false;   // the first burst's ACT / PRE (the rest
    bool caused_precharge = false;  // then hit the row it opened)
  };
  struct Channel {
    std::vector<Rank> ranks;
    std::deque<Burst> queue;     // arrival order, as runs of bursts
    uint32_t queued_bursts = 0;  // bursts in the queue
    // schedule() issues nothing before this cycle: it rescans the queue only
    // then, or when a burst arrives or a command issues in the channel.
    uint64_t wake = 0;
  };
  struct Request {
    DramCompletion info;
    uint32_t bursts_left = 0;
    uint64_t last_done = 0;
  };
  struct Pending {  // an issued burst whose data ends at done_cycle
    uint64_t done_cycle;
    uint64_t sequence;
    uint64_t request;
    bool operator>(const Pending& o) const {
      return done_cycle != o.done_cycle ? done_cycle > o.done_cycle : sequence > o.sequence;
    }
  };

  // Issues at most one command in the channel (refresh, then FR-FCFS), unless
  // nothing can be ready before the channel's wake cycle.
  void schedule(uint32_t channel_index);
  bool issue_one(uint32_t channel_index);  // true if a command issued
  // The earliest cycle after cycle_ at which issue_one() could issue a
  // command in the channel, given that no burst arrives there before (every
  // readiness time it compares with is fixed until a command issues).
  uint64_t channel_wake(uint32_t channel_index) const;
  bool try_refresh(uint32_t channel_index);
  bool cas_ready(const Channel& ch, const Burst& b) const;
  bool act_ready(const Rank& rank, const Bank& bank) const;
  // Advances k cycles in which no command issues and nothing completes.
  void skip_quiet(uint64_t k);
  void issue_activate(uint32_t ch, Burst& b);
  void issue_precharge(uint32_t ch, uint32_t rank, uint32_t bank);
  void issue_cas(uint32_t ch, const Burst& b);
  void issue_refresh(uint32_t ch, uint32_t rank);
  void log(DramCommand c, const DramLocation& loc);
  uint64_t allocate_request();

  DramConfig config_;
  std::vector<Channel> channels_;
  // Field widths and shifts for locate(), indexed by AddressField.
  uint32_t field_bits_[5] = {};
  uint32_t field_shift_[5] = {};
  uint32_t burst_shift_ = 0;

  std::vector<Request> requests_;
  std::vector<uint64_t> free_requests_;
  uint64_t requests_in_flight_ = 0;
  std::priority_queue<Pending, std::vector<Pending>, std::greater<Pending>> pending_;
  uint64_t pending_sequence_ = 0;
  std::deque<DramCompletion> completions_;
  mutable std::vector<uint32_t> channel_count_;  // scratch for can_accept() and enqueue()

  uint64_t cycle_ = 0;
  bool log_commands_ = false;
  std::vector<DramCommandRecord> command_log_;

  // Statistics.
  Counter& cycles_;
  Counter& reads_;
  Counter& writes_;
  Counter& read_bytes_;
  Counter& write_bytes_;
  Counter& read_bursts_;
  Counter& write_bursts_;
  Counter& row_hits_;
  Counter& row_misses_;
  Counter& row_conflicts_;
  Counter& cmd_act_;
  Counter& cmd_pre_;
  Counter& cmd_rd_;
  Counter& cmd_wr_;
  Counter& cmd_ref_;
  Counter& active_rank_cycles_;      // sum over ranks of cycles with a bank open or refreshing
  Counter& precharged_rank_cycles_;  // sum over ranks of cycles with all banks closed
  Counter& rejected_;
  Distribution& read_latency_;
  Distribution& write_latency_;
  Value& bandwidth_;
  Value& peak_bandwidth_;
  Value& bus_utilisation_;
  Value& hit_rate_;
  Value& read_latency_mean_ns_;
  Value& read_latency_p50_ns_;
  Value& read_latency_p99_ns_;
  Value& read_latency_max_ns_;
  Value& energy_act_;
  Value& energy_rd_;
  Value& energy_wr_;
  Value& energy_ref_;
  Value& energy_bg_;
  Value& energy_io_;
  Value& energy_total_;
  Value& energy_per_bit_;
  Value& power_mW_;
};

}  // namespace edrnr::sim
