#include "sim/dram.h"

#include <algorithm>
#include <bit>

#include "core/error.h"

namespace edrnr::sim {
namespace {

uint32_t log2_exact(uint64_t v) { return static_cast<uint32_t>(std::countr_zero(v)); }

// t + delta, but never earlier than the next cycle (for constraints whose
// formula can go to zero or below, such as write-to-read across ranks).
uint64_t after(uint64_t t, int64_t delta) { return t + static_cast<uint64_t>(std::max<int64_t>(delta, 1)); }

}  // namespace

const char* dram_command_name(DramCommand c) {
  switch (c) {
    case DramCommand::kActivate:
      return "ACT";
    case DramCommand::kPrecharge:
      return "PRE";
    case DramCommand::kRead:
      return "RD";
    case DramCommand::kWrite:
      return "WR";
    case DramCommand::kRefresh:
      return "REF";
  }
  return "?";
}

DramSystem::DramSystem(const DramConfig& config, StatsRegistry& stats, const std::string& prefix)
    : config_(config),
      cycles_(stats.counter(prefix + ".cycles", "cycles", "DRAM clock cycles simulated")),
      reads_(stats.counter(prefix + ".reads", "requests", "read requests completed")),
      writes_(stats.counter(prefix + ".writes", "requests", "write requests completed")),
      read_bytes_(stats.counter(prefix + ".read_bytes", "bytes", "bytes read over the data bus (whole bursts)")),
      write_bytes_(stats.counter(prefix + ".write_bytes", "bytes", "bytes written over the data bus (whole bursts)")),
      read_bursts_(stats.counter(prefix + ".read_bursts", "bursts", "read bursts (one RD command each)")),
      write_bursts_(stats.counter(prefix + ".write_bursts", "bursts", "write bursts (one WR command each)")),
      row_hits_(stats.counter(prefix + ".row_hits", "bursts", "bursts served from an already open row")),
      row_misses_(stats.counter(prefix + ".row_misses", "bursts", "bursts that had to activate a closed bank")),
      row_conflicts_(
          stats.counter(prefix + ".row_conflicts", "bursts", "bursts that had to close another open row first")),
      cmd_act_(stats.counter(prefix + ".cmd_activate", "commands", "ACT commands issued")),
      cmd_pre_(stats.counter(prefix + ".cmd_precharge", "commands", "PRE commands issued")),
      cmd_rd_(stats.counter(prefix + ".cmd_read", "commands", "RD commands issued")),
      cmd_wr_(stats.counter(prefix + ".cmd_write", "commands", "WR commands issued")),
      cmd_ref_(stats.counter(prefix + ".cmd_refresh", "commands", "REF commands issued (all banks of a rank)")),
      active_rank_cycles_(stats.counter(prefix + ".active_rank_cycles", "rank-cycles",
                                        "cycles summed over ranks with a bank open or refreshing (IDD3N)")),
      precharged_rank_cycles_(stats.counter(prefix + ".precharged_rank_cycles", "rank-cycles",
                                            "cycles summed over ranks with every bank closed (IDD2N)")),
      rejected_(stats.counter(prefix + ".rejected_enqueues", "requests", "enqueue calls refused for a full queue")),
      read_latency_(stats.distribution(prefix + ".read_latency", "cycles", "read latency, acceptance to last data")),
      write_latency_(stats.distribution(prefix + ".write_latency", "cycles", "write latency, acceptance to last data")),
      bandwidth_(stats.value(prefix + ".bandwidth_GBps", "GB/s", "achieved data bandwidth over the simulated time")),
      peak_bandwidth_(stats.value(prefix + ".peak_bandwidth_GBps", "GB/s", "peak data bandwidth, 2*bus_bytes/tCK")),
      bus_utilisation_(stats.value(prefix + ".bus_utilisation", "ratio", "fraction of cycles the data bus is busy")),
      hit_rate_(stats.value(prefix + ".row_hit_rate", "ratio", "row hits / bursts")),
      read_latency_mean_ns_(stats.value(prefix + ".read_latency_mean_ns", "ns", "mean read latency")),
      read_latency_p50_ns_(stats.value(prefix + ".read_latency_p50_ns", "ns", "median read latency")),
      read_latency_p99_ns_(stats.value(prefix + ".read_latency_p99_ns", "ns", "99th percentile read latency")),
      read_latency_max_ns_(stats.value(prefix + ".read_latency_max_ns", "ns", "maximum read latency")),
      energy_act_(stats.value(prefix + ".energy_activate_pJ", "pJ", "activate + precharge energy")),
      energy_rd_(stats.value(prefix + ".energy_read_pJ", "pJ", "read burst energy")),
      energy_wr_(stats.value(prefix + ".energy_write_pJ", "pJ", "write burst energy")),
      energy_ref_(stats.value(prefix + ".energy_refresh_pJ", "pJ", "refresh energy")),
      energy_bg_(stats.value(prefix + ".energy_background_pJ", "pJ", "active and precharge standby energy")),
      energy_io_(stats.value(prefix + ".energy_io_pJ", "pJ", "flat I/O energy, io_pJ_per_bit * bits")),
      energy_total_(stats.value(prefix + ".energy_pJ", "pJ", "total DRAM energy")),
      energy_per_bit_(stats.value(prefix + ".energy_per_bit_pJ", "pJ/bit", "total energy / data bits moved")),
      power_mW_(stats.value(prefix + ".power_mW", "mW", "average power over the simulated time")) {
  config_.validate();
  channels_.resize(config_.channels);
  for (Channel& ch : channels_) {
    ch.ranks.resize(config_.ranks);
    for (uint32_t r = 0; r < config_.ranks; ++r) {
      Rank& rank = ch.ranks[r];
      rank.banks.resize(config_.banks);
      // Ranks refresh staggered over one interval: rank r first at tREFI*(r+1)/ranks.
      rank.refresh_due = uint64_t{config_.tREFI} * (r + 1) / config_.ranks;
    }
  }
  channel_count_.assign(config_.channels, 0);

  burst_shift_ = log2_exact(config_.burst_bytes());
  field_bits_[static_cast<int>(AddressField::kChannel)] = log2_exact(config_.channels);
  field_bits_[static_cast<int>(AddressField::kRank)] = log2_exact(config_.ranks);
  field_bits_[static_cast<int>(AddressField::kBank)] = log2_exact(config_.banks);
  field_bits_[static_cast<int>(AddressField::kRow)] = log2_exact(config_.rows);
  field_bits_[static_cast<int>(AddressField::kColumn)] = log2_exact(config_.bursts_per_row());
  uint32_t shift = 0;
  for (auto it = config_.address_mapping.rbegin(); it != config_.address_mapping.rend(); ++it) {
    field_shift_[static_cast<int>(*it)] = shift;
    shift += field_bits_[static_cast<int>(*it)];
  }
  peak_bandwidth_.set(config_.peak_bandwidth_GBps());
}

DramLocation DramSystem::locate(uint64_t address) const {
  uint64_t burst = address >> burst_shift_;
  auto field = [&](AddressField f) {
    int i = static_cast<int>(f);
    return static_cast<uint32_t>((burst >> field_shift_[i]) & ((uint64_t{1} << field_bits_[i]) - 1));
  };
  return {field(AddressField::kChannel), field(AddressField::kRank), field(AddressField::kBank),
          field(AddressField::kRow), field(AddressField::kColumn)};
}

bool DramSystem::can_accept(uint64_t address, uint32_t bytes) const {
  if (bytes == 0 || address >= config_.capacity_bytes() || bytes > config_.capacity_bytes() - address) return false;
  uint64_t first = address >> burst_shift_;
  uint64_t last = (address + bytes - 1) >> burst_shift_;
  std::fill(channel_count_.begin(), channel_count_.end(), 0);
  for (uint64_t b = first; b <= last; ++b) {
    uint32_t ch = locate(b << burst_shift_).channel;
    if (channels_[ch].queued_bursts + ++channel_count_[ch] > config_.queue_depth_bursts) return false;
  }
  return true;
}

bool DramSystem::enqueue(DramOp op, uint64_t address, uint32_t bytes, uint64_t id) {
  if (bytes == 0) fail("DRAM request {} at 0x{:x} has zero bytes", id, address);
  if (address >= config_.capacity_bytes() || bytes > config_.capacity_bytes() - address) {
    fail("DRAM request {} at 0x{:x} + {} bytes runs past the capacity of {} bytes", id, address, bytes,
         config_.capacity_bytes());
  }
  uint64_t first = address >> burst_shift_;
  uint64_t last = (address + bytes - 1) >> burst_shift_;
  // Whether `needed` more bursts fit channel ch's queue now (a request that
  // could never fit is an error). A caller retries a refused request every
  // cycle, so the one-channel case counts nothing.
  auto room = [&](uint32_t ch, uint64_t needed) {
    if (needed > config_.queue_depth_bursts) {
      fail("DRAM request {} at 0x{:x} of {} bytes needs {} bursts in channel {}, more than queue_depth_bursts = {}", id,
           address, bytes, needed, ch, config_.queue_depth_bursts);
    }
    return channels_[ch].queued_bursts + needed <= config_.queue_depth_bursts;
  };
  bool fits = true;
  if (config_.channels == 1) {
    fits = room(0, last - first + 1);
  } else {
    std::fill(channel_count_.begin(), channel_count_.end(), 0);
    const int i = static_cast<int>(AddressField::kChannel);
    const uint64_t mask = (uint64_t{1} << field_bits_[i]) - 1;
    for (uint64_t b = first; b <= last; ++b) ++channel_count_[(b >> field_shift_[i]) & mask];
    for (uint32_t ch = 0; ch < config_.channels; ++ch)
      if (!room(ch, channel_count_[ch])) fits = false;
  }
  if (!fits) {
    ++rejected_;
    return false;
  }
  uint64_t slot = allocate_request();
  Request& req = requests_[slot];
  req.info = DramCompletion{id, op, address, bytes, cycle_, 0};
  req.bursts_left = static_cast<uint32_t>(last - first + 1);
  req.last_done = 0;
  ++requests_in_flight_;
  Burst run;  // the run being gathered (count 0: none yet)
  run.count = 0;
  auto flush = [&] {
    Channel& ch = channels_[run.loc.channel];
    Bank& bank = ch.ranks[run.loc.rank].banks[run.loc.bank];
    bank.queued += run.count;
    if (bank.open_row == run.loc.row) (op == DramOp::kRead ? bank.hit_reads : bank.hit_writes) += run.count;
    ch.queued_bursts += run.count;
    ch.queue.push_back(run);
    ch.wake = 0;
  };
  for (uint64_t b = first; b <= last; ++b) {
    const DramLocation loc = locate(b << burst_shift_);
    if (run.count > 0 && loc.channel == run.loc.channel && loc.rank == run.loc.rank && loc.bank == run.loc.bank &&
        loc.row == run.loc.row && loc.column == run.loc.column + run.count) {
      ++run.count;
      continue;
    }
    if (run.count > 0) flush();
    run.request = slot;
    run.op = op;
    run.loc = loc;
    run.count = 1;
  }
  flush();
  return true;
}

uint64_t DramSystem::allocate_request() {
  if (!free_requests_.empty()) {
    uint64_t slot = free_requests_.back();
    free_requests_.pop_back();
    return slot;
  }
  requests_.emplace_back();
  return requests_.size() - 1;
}

void DramSystem::tick() {
  for (uint32_t ch = 0; ch < config_.channels; ++ch)
    if (cycle_ >= channels_[ch].wake) schedule(ch);
  // Background current for this cycle, from the state after this cycle's commands.
  for (const Channel& ch : channels_) {
    for (const Rank& rank : ch.ranks) {
      if (rank.open_banks > 0 || cycle_ < rank.refresh_end) {
        ++active_rank_cycles_;
      } else {
        ++precharged_rank_cycles_;
      }
    }
  }
  ++cycle_;
  ++cycles_;
  while (!pending_.empty() && pending_.top().done_cycle <= cycle_) {
    Pending p = pending_.top();
    pending_.pop();
    Request& req = requests_[p.request];
    req.last_done = std::max(req.last_done, p.done_cycle);
    if (--req.bursts_left > 0) continue;
    req.info.done_cycle = req.last_done;
    if (req.info.op == DramOp::kRead) {
      ++reads_;
      read_latency_.add(req.info.latency_cycles());
    } else {
      ++writes_;
      write_latency_.add(req.info.latency_cycles());
    }
    completions_.push_back(req.info);
    free_requests_.push_back(p.request);
    --requests_in_flight_;
  }
}

void DramSystem::advance_idle(uint64_t target) {
  while (cycle_ < target) {
    if (requests_in_flight_ != 0) return;
    // The first cycle at which schedule() could issue a command: with empty
    // queues only a refresh can, once a rank's refresh falls due.
    uint64_t next = target;
    if (config_.refresh)
      for (const Channel& ch : channels_)
        for (const Rank& rank : ch.ranks) next = rank.refresh_pending ? cycle_ : std::min(next, rank.refresh_due);
    if (next <= cycle_) {
      tick();
      continue;
    }
    skip_quiet(next - cycle_);
  }
}

void DramSystem::skip_quiet(uint64_t k) {
  // No command issues and nothing completes, so the banks stay as they are:
  // each tick would count one background cycle per rank and advance the clock.
  for (const Channel& ch : channels_)
    for (const Rank& rank : ch.ranks) {
      const uint64_t active =
          rank.open_banks > 0 ? k : (rank.refresh_end > cycle_ ? std::min(k, rank.refresh_end - cycle_) : 0);
      active_rank_cycles_ += active;
      precharged_rank_cycles_ += k - active;
    }
  cycle_ += k;
  cycles_ += k;
}

uint64_t DramSystem::next_event_cycle() const {
  uint64_t next = UINT64_MAX;
  for (const Channel& ch : channels_) next = std::min(next, ch.wake);
  // A tick at cycle t completes the bursts done by t + 1.
  if (!pending_.empty()) next = std::min(next, pending_.top().done_cycle - 1);
  return std::max(next, cycle_);
}

void DramSystem::advance_quiet(uint64_t target) {
  while (cycle_ < target) {
    const uint64_t next = std::min(target, next_event_cycle());
    if (next <= cycle_) {
      tick();
      continue;
    }
    skip_quiet(next - cycle_);  // cycles [cycle_, next)
  }
}

std::optional<DramCompletion> DramSystem::pop_completion() {
  if (completions_.empty()) return std::nullopt;
  DramCompletion c = completions_.front();
  completions_.pop_front();
  return c;
}

bool DramSystem::act_ready(const Rank& rank, const Bank& bank) const {
  if (bank.open_row != kClosed || cycle_ < bank.act_ready || cycle_ < rank.act_ready) return false;
  // tFAW: the fifth activate waits until tFAW after the fourth-last one.
  if (rank.act_count >= 4 && cycle_ < rank.act_history[rank.act_count % 4] + config_.tFAW) return false;
  return true;
}

bool DramSystem::cas_ready(const Channel& ch, const Burst& b) const {
  const Rank& rank = ch.ranks[b.loc.rank];
  if (cycle_ < rank.banks[b.loc.bank].cas_ready) return false;
  return b.op == DramOp::kRead ? cycle_ >= rank.rd_ready : cycle_ >= rank.wr_ready;
}

bool DramSystem::try_refresh(uint32_t ch_index) {
  Channel& ch = channels_[ch_index];
  for (uint32_t r = 0; r < config_.ranks; ++r) {
    Rank& rank = ch.ranks[r];
    if (!rank.refresh_pending && cycle_ >= rank.refresh_due) rank.refresh_pending = true;
    if (!rank.refresh_pending) continue;
    if (rank.open_banks == 0) {
      if (cycle_ >= rank.ref_ready && cycle_ >= rank.refresh_end) {
        issue_refresh(ch_index, r);
        return true;
      }
      continue;
    }
    for (uint32_t b = 0; b < config_.banks; ++b) {
      const Bank& bank = rank.banks[b];
      if (bank.open_row != kClosed && cycle_ >= bank.pre_ready) {
        issue_precharge(ch_index, r, b);
        return true;
      }
    }
  }
  return false;
}

void DramSystem::schedule(uint32_t ch_index) {
  Channel& ch = channels_[ch_index];
  if (cycle_ < ch.wake) return;  // nothing can have become ready
  issue_one(ch_index);
  ch.wake = channel_wake(ch_index);
}

bool DramSystem::issue_one(uint32_t ch_index) {
  if (config_.refresh && try_refresh(ch_index)) return true;
  Channel& ch = channels_[ch_index];
  if (ch.queue.empty()) return false;

  // First ready: the oldest burst whose row is open and whose RD/WR may issue now.
  for (auto it = ch.queue.begin(); it != ch.queue.end(); ++it) {
    const Rank& rank = ch.ranks[it->loc.rank];
    if (rank.refresh_pending) continue;
    Bank& bank = ch.ranks[it->loc.rank].banks[it->loc.bank];
    if (bank.open_row == it->loc.row && cas_ready(ch, *it)) {
      issue_cas(ch_index, *it);
      --bank.queued;
      --(it->op == DramOp::kRead ? bank.hit_reads : bank.hit_writes);
      --ch.queued_bursts;
      if (--it->count == 0) {
        ch.queue.erase(it);
      } else {  // the run's next burst
        ++it->loc.column;
        it->caused_activate = it->caused_precharge = false;
      }
      return true;
    }
  }

  // First come, first served: the oldest burst whose ACT or PRE may issue now.
  // An open row that a queued burst still hits is not closed.
  for (Burst& b : ch.queue) {
    Rank& rank = ch.ranks[b.loc.rank];
    if (rank.refresh_pending) continue;
    Bank& bank = rank.banks[b.loc.bank];
    if (bank.open_row == kClosed) {
      if (act_ready(rank, bank)) {
        issue_activate(ch_index, b);
        return true;
      }
    } else if (bank.open_row != b.loc.row) {
      if (!bank.has_hit() && cycle_ >= bank.pre_ready) {
        b.caused_precharge = true;
        issue_precharge(ch_index, b.loc.rank, b.loc.bank);
        return true;
      }
    }
  }
  return false;
}

uint64_t DramSystem::channel_wake(uint32_t ch_index) const {
  // Every condition issue_one() tests compares cycle_ with a time that only a
  // command or an arrival in the channel can change, and at most one command
  // issues per cycle. The queued bursts of one bank share their conditions
  // but for the operation of a row hit.
  const Channel& ch = channels_[ch_index];
  uint64_t wake = UINT64_MAX;
  for (const Rank& rank : ch.ranks) {
    if (config_.refresh) {
      if (!rank.refresh_pending) {
        wake = std::min(wake, rank.refresh_due);
      } else if (rank.open_banks == 0) {
        wake = std::min(wake, std::max(rank.ref_ready, rank.refresh_end));
      } else {
        for (const Bank& bank : rank.banks)
          if (bank.open_row != kClosed) wake = std::min(wake, bank.pre_ready);
      }
    }
    if (rank.refresh_pending) continue;  // its bursts wait for the refresh, counted above
    for (const Bank& bank : rank.banks) {
      if (bank.queued == 0) continue;
      if (bank.open_row == kClosed) {
        uint64_t t = std::max(bank.act_ready, rank.act_ready);
        if (rank.act_count >= 4) t = std::max(t, rank.act_history[rank.act_count % 4] + config_.tFAW);
        wake = std::min(wake, t);
        continue;
      }
      if (bank.hit_reads > 0) wake = std::min(wake, std::max(bank.cas_ready, rank.rd_ready));
      if (bank.hit_writes > 0) wake = std::min(wake, std::max(bank.cas_ready, rank.wr_ready));
      if (!bank.has_hit()) wake = std::min(wake, bank.pre_ready);  // bursts to another row
    }
  }
  return std::max(wake, cycle_ + 1);
}

void DramSystem::issue_activate(uint32_t ch_index, Burst& b) {
  const uint64_t t = cycle_;
  Rank& rank = channels_[ch_index].ranks[b.loc.rank];
  Bank& bank = rank.banks[b.loc.bank];
  bank.open_row = b.loc.row;
  ++rank.open_banks;
  for (const Burst& q : channels_[ch_index].queue)
    if (q.loc.rank == b.loc.rank && q.loc.bank == b.loc.bank && q.loc.row == b.loc.row)
      (q.op == DramOp::kRead ? bank.hit_reads : bank.hit_writes) += q.count;
  bank.cas_ready = t + config_.tRCD;
  bank.pre_ready = std::max(bank.pre_ready, t + config_.tRAS);
  bank.act_ready = t + config_.tRC;
  rank.act_ready = t + config_.tRRD;
  rank.act_history[rank.act_count % 4] = t;
  ++rank.act_count;
  b.caused_activate = true;
  ++cmd_act_;
  log(DramCommand::kActivate, b.loc);
}

void DramSystem::issue_precharge(uint32_t ch_index, uint32_t rank_index, uint32_t bank_index) {
  const uint64_t t = cycle_;
  Rank& rank = channels_[ch_index].ranks[rank_index];
  Bank& bank = rank.banks[bank_index];
  DramLocation loc{ch_index, rank_index, bank_index, bank.open_row, 0};
  bank.open_row = kClosed;
  bank.hit_reads = bank.hit_writes = 0;
  --rank.open_banks;
  bank.act_ready = std::max(bank.act_ready, t + config_.tRP);
  rank.ref_ready = std::max(rank.ref_ready, t + config_.tRP);
  ++cmd_pre_;
  log(DramCommand::kPrecharge, loc);
}

void DramSystem::issue_cas(uint32_t ch_index, const Burst& b) {
  const uint64_t t = cycle_;
  const DramConfig& c = config_;
  const int64_t CL = c.CL, CWL = c.CWL, BURST = c.burst_cycles(), RTRS = c.tRTRS;
  const int64_t same_type_gap = std::max<int64_t>(c.tCCD, BURST);  // the data bus holds one burst at a time
  Channel& ch = channels_[ch_index];
  Bank& bank = ch.ranks[b.loc.rank].banks[b.loc.bank];
  uint64_t done = 0;
  if (b.op == DramOp::kRead) {
    done = t + c.CL + c.burst_cycles();
    bank.pre_ready = std::max(bank.pre_ready, t + c.tRTP);
    for (uint32_t r = 0; r < c.ranks; ++r) {
      Rank& rank = ch.ranks[r];
      if (r == b.loc.rank) {
        rank.rd_ready = std::max(rank.rd_ready, after(t, same_type_gap));
        rank.wr_ready = std::max(rank.wr_ready, after(t, CL + c.tCCD + 2 - CWL));  // JEDEC RL + tCCD + 2 - WL
      } else {
        rank.rd_ready = std::max(rank.rd_ready, after(t, BURST + RTRS));
        rank.wr_ready = std::max(rank.wr_ready, after(t, CL + BURST + RTRS - CWL));
      }
    }
    ++cmd_rd_;
    ++read_bursts_;
    read_bytes_ += c.burst_bytes();
  } else {
    done = t + c.CWL + c.burst_cycles();
    bank.pre_ready = std::max(bank.pre_ready, t + c.CWL + c.burst_cycles() + c.tWR);
    for (uint32_t r = 0; r < c.ranks; ++r) {
      Rank& rank = ch.ranks[r];
      if (r == b.loc.rank) {
        rank.wr_ready = std::max(rank.wr_ready, after(t, same_type_gap));
        rank.rd_ready = std::max(rank.rd_ready, after(t, CWL + BURST + c.tWTR));
      } else {
        rank.wr_ready = std::max(rank.wr_ready, after(t, BURST + RTRS));
        rank.rd_ready = std::max(rank.rd_ready, after(t, CWL + BURST + RTRS - CL));
      }
    }
    ++cmd_wr_;
    ++write_bursts_;
    write_bytes_ += c.burst_bytes();
  }
  if (b.caused_precharge) {
    ++row_conflicts_;
  } else if (b.caused_activate) {
    ++row_misses_;
  } else {
    ++row_hits_;
  }
  pending_.push({done, pending_sequence_++, b.request});
  log(b.op == DramOp::kRead ? DramCommand::kRead : DramCommand::kWrite, b.loc);
}

void DramSystem::issue_refresh(uint32_t ch_index, uint32_t rank_index) {
  const uint64_t t = cycle_;
  Rank& rank = channels_[ch_index].ranks[rank_index];
  rank.refresh_pending = false;
  rank.refresh_due += config_.tREFI;
  rank.refresh_end = t + config_.tRFC;
  for (Bank& bank : rank.banks) bank.act_ready = std::max(bank.act_ready, t + config_.tRFC);
  ++cmd_ref_;
  log(DramCommand::kRefresh, DramLocation{ch_index, rank_index, 0, 0, 0});
}

void DramSystem::log(DramCommand c, const DramLocation& loc) {
  if (log_commands_) command_log_.push_back({cycle_, c, loc});
}

DramEnergy DramSystem::energy() const {
  const DramConfig& c = config_;
  // mA * V * cycles * ns/cycle = pJ, for the devices_per_rank devices of a rank.
  const double scale = c.VDD_V * c.tCK_ns * c.devices_per_rank();
  const double act_mA_cycles =
      c.IDD0_mA * c.tRC - (c.IDD3N_mA * c.tRAS + c.IDD2N_mA * static_cast<double>(c.tRC - c.tRAS));
  DramEnergy e;
  e.activate_pJ = scale * act_mA_cycles * static_cast<double>(cmd_act_.value);
  e.read_pJ = scale * (c.IDD4R_mA - c.IDD3N_mA) * c.burst_cycles() * static_cast<double>(cmd_rd_.value);
  e.write_pJ = scale * (c.IDD4W_mA - c.IDD3N_mA) * c.burst_cycles() * static_cast<double>(cmd_wr_.value);
  e.refresh_pJ = scale * (c.IDD5_mA - c.IDD3N_mA) * c.tRFC * static_cast<double>(cmd_ref_.value);
  e.background_pJ = scale * (c.IDD3N_mA * static_cast<double>(active_rank_cycles_.value) +
                             c.IDD2N_mA * static_cast<double>(precharged_rank_cycles_.value));
  e.io_pJ = c.io_pJ_per_bit * 8.0 * c.burst_bytes() * static_cast<double>(cmd_rd_.value + cmd_wr_.value);
  return e;
}

void DramSystem::update_stats() {
  const DramConfig& c = config_;
  const double bursts = static_cast<double>(cmd_rd_.value + cmd_wr_.value);
  const double bytes = bursts * c.burst_bytes();
  const double time_ns = static_cast<double>(cycle_) * c.tCK_ns;
  bandwidth_.set(time_ns > 0 ? bytes / time_ns : 0.0);
  bus_utilisation_.set(cycle_ > 0 ? bursts * c.burst_cycles() / (static_cast<double>(cycle_) * c.channels) : 0.0);
  hit_rate_.set(bursts > 0 ? static_cast<double>(row_hits_.value) / bursts : 0.0);
  read_latency_mean_ns_.set(read_latency_.mean() * c.tCK_ns);
  read_latency_p50_ns_.set(static_cast<double>(read_latency_.percentile(50)) * c.tCK_ns);
  read_latency_p99_ns_.set(static_cast<double>(read_latency_.percentile(99)) * c.tCK_ns);
  read_latency_max_ns_.set(static_cast<double>(read_latency_.max()) * c.tCK_ns);
  DramEnergy e = energy();
  energy_act_.set(e.activate_pJ);
  energy_rd_.set(e.read_pJ);
  energy_wr_.set(e.write_pJ);
  energy_ref_.set(e.refresh_pJ);
  energy_bg_.set(e.background_pJ);
  energy_io_.set(e.io_pJ);
  energy_total_.set(e.total_pJ());
  energy_per_bit_.set(bytes > 0 ? e.total_pJ() / (bytes * 8.0) : 0.0);
  power_mW_.set(time_ns > 0 ? e.total_pJ() / time_ns : 0.0);  // pJ/ns = mW
}

}  // namespace edrnr::sim
