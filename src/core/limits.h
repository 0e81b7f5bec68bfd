#pragma once
// The limits edrnr enforces on its inputs, in one place (docs/reliability.md
// lists them with their reasons). Each is checked before the work or the
// allocation it bounds, and a refusal names the input, the limit and the value.
#include <fmt/format.h>

#include <cmath>
#include <cstdint>
#include <string_view>
#include <type_traits>

#include "core/error.h"

namespace edrnr::limits {

// Images: any rendered, simulated, decoded or dataset image.
inline constexpr int kMaxImageSide = 16384;                   // pixels, width or height
inline constexpr int64_t kMaxImagePixels = int64_t{1} << 24;  // 16.8 M pixels (4096 x 4096): 256 MiB as float RGBA
// All the images of one dataset split, decoded together (train, simulate, eval).
inline constexpr int64_t kMaxDatasetPixels = int64_t{1} << 28;  // 268 M pixels: 4 GiB as float RGBA

// Threads a command may ask for (0 still means all cores).
inline constexpr int kMaxThreads = 256;

// Rendering: candidate samples along the longest ray through the scene box
// (its diagonal, sqrt(3) * micro_res micro voxels, divided by the step). The
// sample index stays exact and a frame finishes.
inline constexpr int64_t kMaxSamplesPerRay = int64_t{1} << 16;
inline constexpr double kMaxStepMicro = 1024.0;  // micro voxels; beyond, a ray has at most one sample

// Clocks. The core clock is in MHz (Table I: 50..380); the DRAM clock period
// in ns (DDR3: 0.94..3.3). Their ratio bounds the core cycles per DRAM cycle
// and the other way round, so a frame's simulation ends.
inline constexpr double kMinClockMHz = 1.0, kMaxClockMHz = 10000.0;
inline constexpr double kMinDramTckNs = 0.25, kMaxDramTckNs = 20.0;
inline constexpr uint32_t kMaxDramTimingCycles = 1 << 20;  // any other DRAM timing value (tREFI of DDR3-1600: 6240)
inline constexpr uint32_t kMaxDramQueueBursts = 4096;      // a channel's transaction queue
inline constexpr uint64_t kMaxDramBanks = 65536;           // channels x ranks x banks (state per bank)

// Chip and simulator configs: sizes that are allocated.
inline constexpr int64_t kMaxRpBufferCapacity = 65536;       // RPs in the global RP buffer
inline constexpr int64_t kMaxQueueEntries = 65536;           // RP-ROB entries, entry depth, queues, FIFOs, MSHRs
inline constexpr int64_t kMaxCacheBytes = int64_t{1} << 28;  // 256 MiB: any on-chip cache (Table I: 256 KB at most)
inline constexpr int64_t kMaxCacheWays = 1024;
inline constexpr int64_t kMaxLatencyCycles = 1 << 20;  // any unit latency or per-item cycle count

// DRAM workloads (edrnr dram).
inline constexpr uint64_t kMaxDramRequests = 1000000000;        // --random N, --stream N
inline constexpr uint64_t kMaxDramTraceCycle = 10000000000ULL;  // a trace request's arrival, DRAM clocks

// Files read whole (checked against the file's size before reading it; a pipe
// or device is read up to the limit).
inline constexpr uint64_t kMaxTextFileBytes = uint64_t{256} << 20;   // YAML, JSON, CSV, camera files
inline constexpr uint64_t kMaxPngFileBytes = uint64_t{256} << 20;    // one PNG
inline constexpr uint64_t kMaxTraceFileBytes = uint64_t{1} << 30;    // a DRAM trace
inline constexpr uint64_t kMaxModelFileBytes = uint64_t{4} << 30;    // a .edrnr model (its header's total size)
inline constexpr uint64_t kMaxCheckpointBytes = uint64_t{64} << 30;  // a training checkpoint
inline constexpr int kMaxMetadataDepth = 64;                         // nesting of a model's metadata JSON

// Training: the trainer's state (the feature pyramid and occupancy grid in the
// main phase; from the freeze on, per feature block, the values, two Adam
// moments and the float snapshot: 16 bytes per value). An occupancy grid that
// has not emptied (too few steps) would otherwise fill all memory.
// The default of the train config's max_state_gib.
inline constexpr double kDefaultTrainStateGiB = 4.0;
inline constexpr int64_t kMaxBatchSamples = int64_t{1} << 24;  // train config batch_samples
inline constexpr int kMaxRaysPerStep = 1 << 20;                // train config max_rays

// Throws Error "<what> <value>: <unit>must be between lo and hi" unless lo <= value <= hi.
template <class T>
void check_range(T value, T lo, T hi, std::string_view what, std::string_view unit = "") {
  bool ok = value >= lo && value <= hi;
  if constexpr (std::is_floating_point_v<T>) ok = ok && std::isfinite(value);
  if (!ok) fail("{} {}: must be between {} and {}{}{} (limit)", what, value, lo, hi, unit.empty() ? "" : " ", unit);
}

// --threads: 0 (all cores) up to kMaxThreads.
inline void check_threads(int64_t threads, std::string_view flag = "--threads") {
  if (threads < 0 || threads > kMaxThreads)
    fail("{} {}: must be 0 (all cores) up to the limit of {}", flag, threads, kMaxThreads);
}

// An image size, before anything of that size is allocated.
inline void check_image_size(int64_t width, int64_t height, std::string_view what) {
  if (width < 1 || height < 1 || width > kMaxImageSide || height > kMaxImageSide)
    fail("{} {}x{}: each side must be 1..{} pixels (limit)", what, width, height, kMaxImageSide);
  if (width * height > kMaxImagePixels)
    fail("{} {}x{}: {} pixels, over the limit of {} pixels per image ({}x{})", what, width, height, width * height,
         kMaxImagePixels, 4096, 4096);
}

}  // namespace edrnr::limits
