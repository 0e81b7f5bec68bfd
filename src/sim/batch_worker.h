#pragma once
// The simulator's work that does not depend on the clock, and the second
// thread it may run on (--threads 2):
//   BatchArithmetic  a batch's interpolation sums, MLP and compositing;
//   FrontEndAhead    the front end's ray packets, built in ZORG order ahead
//                    of the cycle at which the front end takes them;
//   FtuAhead         FTU runs made as soon as their input is final;
//   Worker           a thread that runs them, batch jobs in submission order.
// The engine keeps every timing decision: it only reads results computed
// here, which are the same whichever thread computed them.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <exception>
#include <memory>
#include <thread>
#include <vector>

#include "chip/cfiu.h"
#include "chip/chip.h"
#include "chip/chip_ray.h"
#include "chip/front_end.h"
#include "chip/ftu.h"
#include "chip/oo_si.h"
#include "chip/rp_buffer.h"
#include "chip/tme.h"
#include "chip/vru.h"
#include "chip/zorg.h"
#include "model/scene_model.h"

namespace edrnr::sim {

// What one thread writes and the other reads is kept off the cache lines the
// other thread writes: a line written by both moves between the cores at
// every write (tens to hundreds of nanoseconds each on a shared host).
inline constexpr size_t kCacheLineBytes = 64;

// An RP's batch from the FTU until its last sample leaves the VRU. The
// arithmetic job (sample coordinates unless made, weighted sums, MLP,
// compositing) reads block, cv_tag, samples and coords and writes coords and
// stay; it may run on the worker thread in between.
struct Flight {
  uint32_t slot = 0;   // computation-SRAM slot of the batch (freed when the CFIU has read it)
  uint32_t block = 0;  // feature block (its line stays reserved until then)
  uint32_t cv_tag = 0;
  std::vector<uint8_t> sample_cycles;     // CFIU cycles per sample (1 + bank conflicts)
  std::vector<chip::SampleRef> samples;   // the batch's samples, taken from its computation-SRAM slot
  std::vector<chip::SampleCoord> coords;  // SCC output per sample, once coords_made
  bool coords_made = false;               // by the engine when the CFIU's bank reads need them, else by the job
  bool stay = false;                      // a live ray is still in the CV: reschedule; else leave it
  uint64_t job = 0;                       // job sequence number
  bool deferred = false;                  // BatchArithmetic::defer() holds it until flush()
  bool made = false;                      // made with its FTU run (FtuAhead): no job
};

// Makes f.coords (the SCC output of each of f.samples, rays of p) and sets
// f.coords_made.
void make_coords(const chip::RayMath& math, const ChipNumerics& n, const chip::RayPacket& p, Flight& f);

// The arithmetic of batches: interpolation sums, the TME and the VRU, with
// their own unit instances, so that it can run on a thread of its own.
class BatchArithmetic {
 public:
  BatchArithmetic(const SceneModel& model, const ChipConfig& config, const ChipNumerics& n, const chip::RayMath& math,
                  const chip::Cfiu& cfiu, double delta);

  // The sample coordinates unless made, the interpolation sums of every
  // sample, the TME on the whole batch (the direction inputs once per ray),
  // then compositing in sample order; sets f.stay. CV f.cv_tag's MLP is
  // selected without counting a load: the caller counts the loads in the
  // hardware's order (defer() counts them).
  void run(chip::RayPacket& p, Flight& f);
  // run(p, f) deferred (one thread): the MLP load is counted now, in the
  // order run() would count it, and the arithmetic waits for flush(), which
  // evaluates the deferred batches of each MLP as one TME batch. Every
  // output and counter is the same as run()'s: batches of different RPs
  // touch different rays, and an RP has one batch in flight. p and f must
  // stay in place until flush().
  void defer(chip::RayPacket& p, Flight& f);
  // The arithmetic of every deferred batch; clears their `deferred`.
  void flush();

  const chip::Tme& tme() const { return tme_; }
  const chip::Vru& vru() const { return vru_; }

 private:
  const SceneModel& model_;
  const ChipNumerics n_;
  const chip::RayMath& math_;
  const chip::Cfiu& cfiu_;
  chip::Tme tme_;
  chip::Vru vru_;
  std::vector<int32_t> features_;                   // F per sample of the batch
  std::vector<chip::TmeOutput> outputs_;            // per sample
  std::vector<chip::TmeDirection*> dir_of_sample_;  // per sample: its ray's direction inputs
  std::vector<int32_t> dir_code_;                   // a ray's direction codes, before its inputs
  struct Deferred {
    chip::RayPacket* packet;
    Flight* flight;
    int32_t mlp;
  };
  std::vector<Deferred> deferred_;  // in submission order
  std::vector<uint32_t> order_;     // flush(): deferred_ grouped by MLP

  // The direction inputs of `ray` (made once per ray, then kept with the
  // ray, where the TME keeps their terms too).
  chip::TmeDirection* direction_of(chip::RayState& ray);
  // Composites n samples of f (outputs_ from `first`) and sets f.stay.
  void finish(chip::RayPacket& p, Flight& f, size_t first);
};

// One front-end packet: the quad ZORG issued, its packet and the TSPS
// position evaluations spent on it (its front-end cycles follow from them).
// The packet lives in its own allocation, handed between the threads
// without copying it.
struct FrontEndPacket {
  chip::PixelQuad quad;
  std::unique_ptr<chip::RayPacket> packet = std::make_unique<chip::RayPacket>();
  uint64_t tsps_position_evals = 0;
};

// Builds the frame's packets in ZORG order with its own ZORG and the given
// front end. Single producer (the worker), single consumer (the engine).
class FrontEndAhead {
 public:
  // front_end and vru are used by the producer only until the worker stops.
  FrontEndAhead(const chip::Zorg& zorg, chip::FrontEnd& front_end, const chip::Vru& vru, size_t depth);

  // Producer: builds the next packet if the ring has room. False when it has
  // none or the frame is done.
  bool produce_one();
  // Producer: whether produce_one() would build a packet, and whether fewer
  // than a quarter of the ring's packets are ready.
  bool can_produce() const;
  bool running_low() const;
  // Consumer: whether the next packet is ready; take() swaps it into e (whose
  // packet, not null, the ring builds a later packet in).
  // Precondition of take(): ready().
  bool ready() const { return produced_.load(std::memory_order_acquire) != consumed_; }
  void take(FrontEndPacket& e);

  std::atomic<uint64_t>& produced() { return produced_; }
  uint64_t consumed() const { return consumed_; }

 private:
  chip::Zorg zorg_;
  chip::FrontEnd& front_;
  const chip::Vru& vru_;
  std::vector<FrontEndPacket> ring_;
  alignas(kCacheLineBytes) std::atomic<uint64_t> produced_{0};         // the producer's
  alignas(kCacheLineBytes) std::atomic<uint64_t> consumed_shared_{0};  // consumed_, as the producer sees it
  uint64_t consumed_ = 0;                                              // consumer's own count
};

// One FTU run (Ftu::run of an RP in one CV) with what the timing shell needs
// from it: the batch, the run's own counters and the fine voxels whose
// micro-grid words it read, in order.
struct FtuRun {
  bool has_batch = false;
  chip::SampleBatch batch;
  chip::FtuCounters counts;  // micro_word_hits stays 0: the engine replays micro_log through its LRU tags
  std::vector<uint32_t> micro_log;
};

// Runs `ftu` (whose micro-grid LRU must have no capacity) once into `out`.
void run_ftu(chip::Ftu& ftu, chip::RayPacket& p, uint32_t rp, uint32_t cv_tag, FtuRun& out);

// With two threads, an RP's next FTU run is made as soon as its rays are
// final for it (the CTU found its next CV, or a batch ended with a live ray
// still in the CV), by whichever thread gets to it first: the worker, or the
// engine when it schedules the RP. The run reads and writes that RP's rays
// alone, so its result is the same whoever makes it and whenever. The
// worker makes the arithmetic of the run's batch right after it (the next
// thing to happen to those rays), so that the engine need not wait for it.
class FtuAhead {
 public:
  // arithmetic: the worker's.
  FtuAhead(const SceneModel& model, const chip::RayMath& math, bool lag_first, chip::RpBuffer& buffer,
           BatchArithmetic& arithmetic);

  // Either thread: rp's run in CV cv_tag may be made (none of rp's is pending).
  void pend(uint32_t rp, uint32_t cv_tag);
  // Engine, after pend(rp): whether the worker needs a job for rp's run
  // (false while a job of rp's that it has not started is queued: that job
  // makes whatever run is pending when it starts). This bounds the jobs
  // queued per RP to one, however often the RP changes CV meanwhile.
  bool needs_job(uint32_t rp);
  // Worker: the job of rp started (needs_job(rp) is true again).
  void job_started(uint32_t rp);
  // Worker: makes rp's run with the worker's FTU, and its batch's arithmetic,
  // unless someone started it.
  void try_run(uint32_t rp);
  // Engine: rp's run in cv_tag, made now with `ftu` if nobody started it,
  // else waited for. Rethrows what the run or its arithmetic threw. Valid
  // until pend(rp).
  FtuRun& take(uint32_t rp, uint32_t cv_tag, chip::Ftu& ftu);
  // Engine, after take(rp): the flight of the run's batch (block, cv_tag,
  // samples, coords, stay; the batch's samples moved into it) when the
  // worker made its arithmetic with the run, else null. Valid until pend(rp).
  Flight* made_flight(uint32_t rp);
  // Engine, while it waits: makes one pending run nobody started with `ftu`
  // (take() then finds it made); false when there is none.
  bool run_any_pending(chip::Ftu& ftu);

 private:
  enum : uint8_t { kNone, kPending, kRunning, kDone };
  struct alignas(kCacheLineBytes) Slot {
    std::atomic<uint8_t> state{kNone};
    std::atomic<bool> queued{false};  // a job for this RP's run is queued and not started
    uint32_t cv_tag = 0;
    FtuRun run;
    Flight flight;  // the batch's arithmetic, when made with the run
    bool flight_made = false;
    std::exception_ptr error;
  };
  // Makes slot's run with `ftu` and, given `arithmetic`, its batch's arithmetic.
  void run_slot(Slot& slot, uint32_t rp, chip::Ftu& ftu, BatchArithmetic* arithmetic);

  chip::RpBuffer& buffer_;
  BatchArithmetic& arithmetic_;
  chip::Ftu ftu_;                  // the worker's
  uint32_t steal_from_ = 0;        // run_any_pending's next RP to look at
  std::unique_ptr<Slot[]> slots_;  // by RP pointer
};

// Runs BatchArithmetic jobs in order on a second thread and, between them,
// builds front-end packets ahead (when given a FrontEndAhead) and makes FTU
// runs ahead (when given an FtuAhead). Each side
// spins before it sleeps, and wakes the other only when that one sleeps, so
// that a job costs no system call while both are busy.
class Worker {
 public:
  // capacity: RPs in flight.
  Worker(BatchArithmetic& arithmetic, chip::RpBuffer& buffer, std::vector<Flight>& flights, size_t capacity,
         FrontEndAhead* ahead, FtuAhead* ftu_ahead);
  ~Worker();

  // Queues the arithmetic job of RP `rp`; returns its sequence number. With
  // an FtuAhead, a job whose RP stays in its CV pends and makes its next FTU
  // run after it completes.
  uint64_t submit(uint32_t rp);
  // Queues a job for rp's pending FTU run (FtuAhead::pend, needs_job first).
  void submit_ftu(uint32_t rp);
  // Waits until job `seq` (of RP rp) is done (its results are then
  // visible). Rethrows an exception a job threw. With `own` (the engine's
  // arithmetic), a job the worker has not started is made here with it
  // instead (the worker then skips it), with what the worker does after it.
  // With `ftu` (the engine's), pending FTU runs are made with it meanwhile,
  // as long as the job is not done.
  void wait(uint64_t seq, uint32_t rp, BatchArithmetic* own = nullptr, chip::Ftu* ftu = nullptr);
  // The next front-end packet, swapped into e (FrontEndAhead::take), waiting
  // for it if need be.
  void take_packet(FrontEndPacket& e);

 private:
  void loop();
  void signal();
  // Appends rp to a job ring (`taken`: the jobs the worker has started or
  // done) and wakes the worker; returns the job's sequence number. A full
  // ring: a wait for room with wait_when_full, else a logic error.
  uint64_t push(std::vector<uint32_t>& queue, std::atomic<uint64_t>& submitted, const std::atomic<uint64_t>& taken,
                uint32_t rp, const char* what, bool wait_when_full);
  void main_wait(const std::atomic<uint64_t>& counter, uint64_t above);
  // After rp's batch job (either thread): a batch whose RP stays in its CV
  // pends the RP's next FTU run; true when it does.
  bool pend_next_run(uint32_t rp);
  void fail_with(std::exception_ptr e);  // worker: records a job's exception
  void rethrow_failure() const;          // main: rethrows it, if any

  BatchArithmetic& arithmetic_;
  chip::RpBuffer& buffer_;
  std::vector<Flight>& flights_;
  FrontEndAhead* ahead_;
  FtuAhead* ftu_ahead_;
  std::vector<uint32_t> queue_;      // batch jobs: RP pointers
  std::vector<uint32_t> ftu_queue_;  // FTU jobs: RP pointers
  // By RP: its queued batch job was claimed (by the worker or the engine).
  // One line each: both threads write them.
  struct alignas(kCacheLineBytes) Claim {
    std::atomic<bool> taken{true};
  };
  std::unique_ptr<Claim[]> claimed_;
  // Written by the main thread.
  alignas(kCacheLineBytes) std::atomic<uint64_t> submitted_{0};
  std::atomic<uint64_t> ftu_submitted_{0};
  std::atomic<uint64_t> signals_{0};  // bumped by the main thread to wake the sleeping worker
  std::atomic<bool> stop_{false}, main_sleeping_{false};
  // Written by the worker.
  alignas(kCacheLineBytes) std::atomic<uint64_t> completed_{0};
  std::atomic<uint64_t> ftu_started_{0};
  std::atomic<bool> worker_sleeping_{false};
  std::atomic<bool> failed_{false};
  std::exception_ptr error_;  // written once by the worker, then failed_ set
  alignas(kCacheLineBytes) std::thread thread_;
};

}  // namespace edrnr::sim
