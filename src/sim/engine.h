#pragma once
// The cycle simulator's engine behind simulate_chip (sim/simulator.h): the
// chip's units as timing shells around their functional models, stepped
// cycle by cycle with the memory system, the statistics and, with two
// threads, the worker (sim/batch_worker.h). Private to the simulator; its
// code is split by responsibility:
//   engine.cpp          construction, the cycle loop, the units
//   engine_skip.cpp     skipping quiet cycles
//   engine_memory.cpp   fills and their retries, MLP loads and prefetches
//   engine_results.cpp  counters, statistics, energy and the result
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "chip/chip_ray.h"
#include "chip/front_end.h"
#include "chip/lru_tags.h"
#include "chip/rp_buffer.h"
#include "chip/zorg.h"
#include "sim/batch_worker.h"
#include "sim/cache.h"
#include "sim/chrome_trace.h"
#include "sim/fifo.h"
#include "sim/memory_system.h"
#include "sim/simulator.h"

namespace edrnr::sim::engine {

using namespace chip;

enum Unit : uint32_t { kFrontEnd, kCtu, kFtu, kOooSi, kCfiu, kTme, kVru, kUnits };
inline constexpr const char* kUnitNames[kUnits] = {"front_end", "ctu", "ftu", "ooo_si", "cfiu", "tme", "vru"};

inline uint64_t ceil_div(uint64_t a, uint64_t b) { return (a + b - 1) / b; }
inline double ratio(double a, double b) { return b > 0 ? a / b : 0.0; }

// One sample on its way from the CFIU through the TME to the VRU.
struct SampleToken {
  uint32_t rp = 0;
  bool first = false;  // first sample of its batch
  bool last = false;   // last sample of its batch
};

class HitSeries {
 public:
  explicit HitSeries(uint64_t window) : window_(window) {}
  void record(uint64_t cycle, bool hit) {
    const size_t w = size_t(cycle / window_);
    while (series_.size() <= w) series_.push_back({uint64_t(series_.size()) * window_, 0, 0});
    ++series_[w].accesses;
    series_[w].hits += hit;
  }
  const std::vector<HitRateWindow>& series() const { return series_; }

 private:
  uint64_t window_;
  std::vector<HitRateWindow> series_;
};

// One frame's simulation. Contract: construct, call run() once; the result
// given to the constructor then holds the image, statistics and energy.
class Engine {
 public:
  Engine(const SceneModel& model, const Camera& camera, const SimConfig& config, const SimOptions& options,
         SimResult& result);
  void run();

 private:
  // ------------------------------------------------------------ skipping

  // After cycle c has run: the first later cycle in which any unit or FIFO
  // may act differently from c (a countdown ending, an item becoming
  // visible), unless the memory delivers first (the caller runs the memory
  // through the cycles between and ends them at a completion). In those
  // cycles every unit reports c's state, and the only side effects are the
  // per-cycle counts that skip() adds in bulk. c + 1 when that cannot be
  // shown.
  uint64_t quiet_until(uint64_t c);
  // Counts cycles [first, first + n) as quiet_until() found them: each unit
  // in its state, the back end's countdowns run down, refused RP-ROB inserts
  // and OoO-SI waits repeated.
  void skip(uint64_t first, uint64_t n);

  // ------------------------------------------------------------ units

  void set_state(Unit u, UnitState s);
  // ZORG, ABT and TSPS: one RP at a time; its pointer is allocated when it leaves.
  void step_front_end();
  // CTU: coarse traversal of one RP at a time; CV transitions first, then new RPs.
  void step_ctu();
  // FTU: one CCRP at a time from the RP-ROB; its micro-grid words come
  // through the micro-grid cache; its batch goes to the OoO-SI, which asks the
  // CFIU to prefetch the feature block.
  void step_ftu();
  // OoO-SI: issues the oldest batch whose block is on chip to the CFIU. The
  // batch's work is done now; its timing follows.
  void step_issue();
  // The batch's arithmetic starts as soon as it exists (unless the worker
  // made it with the FTU run): it depends only on the samples, the model and
  // its RP's rays, and the RP has no other batch in flight. The sample
  // coordinates are computed here when the CFIU's bank reads at issue need
  // them; with two threads the TME's MLP loads are counted here.
  void start_batch(uint32_t rp, uint32_t slot);
  // The CFIU reads the corners of each sample from the banks now; bank
  // conflicts lengthen its samples.
  void issue(const LsEntry& e);
  // CFIU: streams the issued batch's samples into the TME's queue.
  void step_cfiu();
  // TME: the MLP of the batch's CV must be in the MAC array. A load copies it
  // from the MLP cache (missing lines from DRAM) into a weight buffer. With one
  // buffer the load starts when the batch reaches the head of the TME's queue
  // and stops the TME; with two, it starts into the shadow buffer as soon as
  // the OoO-SI issues the batch, and the buffers swap when the batch arrives.
  void step_tme();
  // A batch reaching the TME: the per-batch and per-access MLP hit rates.
  void count_mlp_batch(const SampleToken& first, bool on_chip);
  // With two threads: the TME's MLP loads, counted as batches start (in the
  // order the TME takes them), since the worker's arithmetic counts none.
  void count_mlp_load(uint32_t cv_tag);
  // VRU: composites one sample per vru_cycles_per_sample; after a batch's last
  // sample the RP is rescheduled or leaves its CV.
  void step_vru();
  void complete_batch(uint32_t rp);
  // Retire from the RP-ROB: back to the CTU (pointer kept) or finished.
  void leave_cv(uint32_t rp);
  void finish(uint32_t rp);
  void write_pixels(const RayPacket& p);
  void write_output_record(uint64_t sequence);

  // ------------------------------------------------------------ memory

  // Starts copying the MLP of CV `tag` into the free weight buffer.
  void start_mlp_load(uint32_t tag, uint64_t c);
  // With a shadow buffer: the OoO-SI issued a batch of CV `tag`; load its MLP
  // now unless it is active, loaded, or the shadow buffer is taken.
  void early_mlp_load(uint32_t tag);
  // The RP-ROB switched to `tag`: its MLP's lines are fetched ahead of the TME.
  void start_mlp_prefetch(uint32_t tag);
  // One prefetch request per cycle, while MSHR entries are free.
  void issue_mlp_prefetch(uint64_t c) {
    if (prefetch_next_ < prefetch_lines_.size()) issue_next_mlp_prefetch(c);
  }
  void issue_next_mlp_prefetch(uint64_t c);
  // Lines a unit waits for are reserved when they miss, so that no other fill
  // evicts them before the unit has read them; once resident they are read
  // (copied into the unit), released and dropped from `waiting`. True when
  // none is left.
  static bool take_arrived(Cache& cache, std::vector<uint64_t>& waiting);
  static uint64_t line_start(const Cache& cache, uint64_t addr);
  // A transfer the memory system completed: its line filled, or its data marked ready.
  void deliver(const MemoryCompletion& m);
  // Fills refused because every way of the set was reserved, tried again each cycle.
  void retry_fills() {
    if (!retry_micro_.empty() || !retry_mlp_.empty()) retry_refused_fills();
  }
  void retry_refused_fills();

  // ------------------------------------------------------------ results

  struct AccessCount {
    uint64_t hits = 0, misses = 0;
  };
  static void count_per_access(AccessCount& a, bool hit, size_t samples);
  ChipCounters chip_counters() const;
  EnergyRun energy_run(const ChipCounters& c) const;
  void finish_result();

  // ------------------------------------------------------------ state

  struct FrontEndShell {
    bool holding = false;
    bool live = false;  // the packet has a ray to traverse (else only background pixels)
    uint64_t end = 0;
    uint64_t sequence = 0;
    FrontEndPacket packet;  // its quad and evaluations are used with two threads only
  };
  struct CtuShell {
    bool holding = false;
    uint64_t end = 0;
    uint32_t rp = 0;
    CtuResult result;
  };
  struct FtuShell {
    bool holding = false;
    bool output = false;  // the run is done; handing its result on
    bool has_batch = false;
    uint32_t rp = 0, slot = 0;
    uint64_t end = 0, ready = 0;
    std::vector<uint64_t> reads;  // micro-word addresses of the run, in order
    size_t next_read = 0;
    std::vector<uint64_t> waiting;  // missed words (their lines reserved)
  };
  struct CfiuShell {
    bool active = false;
    uint32_t rp = 0;
    uint32_t next = 0;   // sample being read
    uint32_t left = 0;   // cycles left for it
    uint64_t start = 0;  // first cycle of the batch
  };
  struct TmeShell {
    bool holding = false;
    SampleToken token;
    uint64_t left = 0;
    bool active = false;  // the active weight buffer holds active_tag's MLP
    uint32_t active_tag = 0;
    bool shadow_ready = false;  // a finished load waits to become active
    uint32_t shadow_tag = 0;
    bool shadow_on_chip = false;
    bool loading = false;  // a load into the free buffer is under way
    uint32_t load_tag = 0;
    bool load_on_chip = false;  // its lines were all in the MLP cache when it started
    uint64_t load_end = 0;
    std::vector<uint64_t> lines;
    size_t next_line = 0;
    std::vector<uint64_t> waiting;
  };
  struct VruShell {
    bool holding = false;
    SampleToken token;
    uint64_t left = 0;
  };

  const SceneModel& model_;
  const SimConfig& cfg_;
  const SimTiming& t_;
  const SimOptions& opt_;
  SimResult& res_;
  StatsRegistry& stats_;
  ChipNumerics n_;
  double delta_;
  RayMath math_;
  Zorg zorg_;
  FrontEnd front_;
  RpBuffer buffer_;
  Ctu ctu_;
  RpRob rob_;
  Ftu ftu_;                 // the engine's FTU model (its micro-grid LRU has no capacity: micro_lru_ counts)
  LruTags micro_lru_;       // the micro-grid bitmap cache's tags, for FtuCounters::micro_word_hits
  FtuCounters ftu_counts_;  // every FTU run's counters, whichever thread made it
  FtuRun ftu_run_;          // with one thread: the run the FTU makes now
  OooSi ooo_;
  Cfiu cfiu_;
  BatchArithmetic arithmetic_;
  Vru vru_;  // ray start and pixels (the arithmetic composites with its own)
  Image image_;
  uint64_t mlp_bytes_;
  AddressMap map_;
  MemorySystem mem_;
  Cache micro_cache_;
  Cache mlp_cache_;
  HitSeries feature_series_;  // per batch request
  HitSeries mlp_series_;      // per batch at the TME: its MLP on chip (MAC array or MLP cache)
  ActivityRecorder activity_;
  size_t rp_capacity_;
  Fifo<uint32_t> fe_out_, retire_q_;
  Fifo<SampleToken> tme_in_, vru_in_;
  Fifo<uint32_t> done_q_;
  std::vector<SampleBatch> batches_;  // the computation SRAM: OoO-SI entries plus the batch the CFIU reads
  std::vector<uint32_t> free_slots_;
  std::vector<Flight> flights_;     // by RP pointer
  std::vector<uint64_t> sequence_;  // by RP pointer: ZORG issue index
  std::vector<MemoryCompletion> completions_;
  std::vector<uint64_t> retry_micro_, retry_mlp_;
  std::unique_ptr<FrontEndAhead> ahead_;  // with threads = 2: the front end runs on the worker
  std::unique_ptr<FtuAhead> ftu_ahead_;   // with threads = 2: FTU runs made as soon as their input is final
  std::unique_ptr<Worker> worker_;
  // With threads = 2: the arithmetic of batch jobs the engine makes itself
  // rather than wait for the worker to start them (arithmetic_ is the worker's).
  std::unique_ptr<BatchArithmetic> main_arithmetic_;

  FrontEndShell fe_;
  CtuShell ctu_s_;
  FtuShell ftu_s_;
  CfiuShell cfiu_s_;
  TmeShell tme_s_;
  VruShell vru_s_;

  uint64_t cycle_ = 0, cycles_ = 0, skipped_cycles_ = 0;
  UnitState quiet_state_[kUnits] = {};  // each unit's state in the cycles quiet_until() found
  bool bitmaps_ready_ = false;
  int32_t loaded_mlp_ = -1;  // count_mlp_load's: the TME's current MLP
  uint64_t mlp_loads_ = 0, mlp_load_bytes_ = 0;
  bool any_busy_ = false;
  uint64_t mlp_lines_ = 0, macs_per_sample_ = 0, neurons_per_sample_ = 0, tme_cycles_per_sample_ = 1;
  uint64_t rps_done_ = 0, packets_dropped_ = 0, rps_finished_ = 0, cv_transitions_ = 0, fine_reschedules_ = 0;
  uint64_t ctu_runs_ = 0, ftu_runs_ = 0, mlp_switches_ = 0, feature_fills_ = 0;
  uint64_t fill_words_micro_ = 0, fill_words_mlp_ = 0;
  bool prefetch_started_ = false;
  uint32_t prefetch_tag_ = 0;
  std::vector<uint64_t> prefetch_lines_;
  size_t prefetch_next_ = 0;
  AccessCount feature_access_, mlp_access_;
};

}  // namespace edrnr::sim::engine
