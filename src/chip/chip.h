#pragma once
// The EDR-NR chip, functional and bit-accurate (paper Section IV, Fig. 10):
// its configuration, its counters, and render_chip, which renders an image
// through the units
//   ZORG -> ABT -> TSPS -> CTU (+LFAU) -> RP-ROB -> FTU (+LFAU) -> OoO-SI ->
//   CFIU -> TME -> VRU
// with the retire and reschedule feedback of Section IV-A: after the VRU, an
// RP with a live ray still in its coarse voxel is rescheduled (fine-voxel
// transition, back to the FTU through the RP-ROB); otherwise it retires from
// the RP-ROB and, if a ray is still inside the traversal box, goes back to
// the CTU keeping its RP pointer (CV transition), else it is finished and its
// four pixels are written (the pointer is released).
//
// The image depends only on the model, the camera, the render settings and
// the numerics. The scheduling switches (row order instead of Z order, no
// AABB, no lag-first, no RP reordering, no out-of-order issue, other bank
// mappings) and the buffer sizes change the order in which work is done, and
// so the counters, never a pixel: each ray's samples are a function of the
// ray alone (chip_ray.h) and are composited in order of k.
//
// Time is not modelled here. The functional run moves work between the units
// in a fixed order (admit RPs while the RP buffer has room; coarse-traverse;
// insert into the RP-ROB; schedule CCRPs to the FTU until the OoO-SI queue is
// full; issue one CCRP_SP), and a feature block requested at issue number n
// arrives at issue number n + functional_fill_latency_issues: enough to make
// the out-of-order issue and the feature cache meaningful. The cycle
// simulator wraps the same units with real latencies.
#include <yaml-cpp/yaml.h>

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "chip/cfiu.h"
#include "chip/ctu.h"
#include "chip/feature_cache.h"
#include "chip/front_end.h"
#include "chip/ftu.h"
#include "chip/numerics.h"
#include "chip/oo_si.h"
#include "chip/rp_buffer.h"
#include "chip/rp_rob.h"
#include "chip/tme.h"
#include "chip/vru.h"
#include "chip/zorg.h"
#include "core/image.h"
#include "core/stats.h"
#include "data/camera.h"
#include "model/scene_model.h"
#include "render/reference.h"

namespace edrnr {

// Each data-reuse technique can be switched off for comparison; none changes
// the image.
struct ChipSwitches {
  bool z_order = true;     // ZORG Z-order scan (false: row order, 4 pixels of a row per RP)
  bool aabb = true;        // ABT + TSPS on the object AABB (false: on the whole scene box)
  bool lag_first = true;   // LFAU lag-first selection (false: the first live ray's voxel leads)
  bool rp_reorder = true;  // RP-ROB clustering by CV tag (false: first in, first out)
  bool ooo_issue = true;   // OoO-SI out-of-order issue (false: in order)
  bool operator==(const ChipSwitches& o) const = default;
};

struct ChipConfig {
  int rp_buffer_capacity = 64;           // RPs in flight (global RP buffer)
  chip::RpRobConfig rp_rob;              // entries, entry depth, recent-tags recorder size
  int ooo_queue_depth = 16;              // OoO-SI location shifter entries
  int64_t feature_cache_bytes = 262144;  // 256 KB, 8 banks
  int mshr_entries = 16;
  chip::BankMapping bank_mapping = chip::BankMapping::Balanced;
  int64_t mlp_cache_bytes = 8448;          // 8.25 KB: one MLP
  int64_t micro_grid_cache_bytes = 8192;   // 8 KB of 64-bit fine-voxel words
  int functional_fill_latency_issues = 8;  // functional stand-in for the DRAM latency
  float step_micro = kDefaultStepMicro;    // candidate spacing in micro-voxel edges
  float transmittance_min = 1e-4f;         // early termination threshold
  float background[3] = {1.f, 1.f, 1.f};
  ChipSwitches switches;
  ChipNumerics numerics;
};

// Throws Error naming the field when a value is out of range.
void validate(const ChipConfig& config);

// Reads a chip config (configs/chip/*.yaml). Missing keys keep their
// defaults; an unknown key or a bad value throws Error naming `where` and the
// key.
ChipConfig chip_config_from_yaml(const YAML::Node& node, std::string_view where = "chip config");
ChipConfig load_chip_config(const std::filesystem::path& path);
// The fully resolved config (chip_config_from_yaml reads it back).
YAML::Node chip_config_to_yaml(const ChipConfig& config);

// Feature cache lines for a model with F channels: the cache bytes over the
// block bytes (125 F / 2), rounded down to a multiple of 8 (a rotation group
// of the balanced bank layout). Throws Error if not even 8 lines fit.
int feature_cache_lines(const ChipConfig& config, int feature_channels);

struct ChipCounters {
  // ZORG, ABT, TSPS.
  uint64_t packets = 0;            // RPs issued by ZORG
  uint64_t rays = 0;               // valid rays
  uint64_t rays_dropped_abt = 0;   // rays the ABT dropped
  uint64_t rays_dropped_tsps = 0;  // rays with no candidate in the box (TSPS)
  uint64_t packets_dropped = 0;    // RPs with no ray left after ABT/TSPS (background only)
  uint64_t tsps_position_evals = 0;
  uint64_t zorg_skipped_quads = 0;  // out-of-bounds quads jumped over
  // Traversal and scheduling units.
  chip::CtuCounters ctu;
  chip::FtuCounters ftu;
  chip::RpRobCounters rp_rob;
  chip::OooCounters ooo;
  chip::FeatureCacheCounters feature_cache;
  chip::CfiuCounters cfiu;
  chip::TmeCounters tme;
  chip::VruCounters vru;
  // Pipeline.
  uint64_t cv_transitions = 0;    // RPs sent back to the CTU (pointer kept)
  uint64_t fine_reschedules = 0;  // RPs sent back to the FTU
  uint64_t rps_finished = 0;      // RPs that went through the pipeline and retired
  uint64_t fill_waits = 0;        // issue slots spent waiting for a feature block
  uint64_t peak_rp_buffer = 0;
  int feature_cache_lines = 0;
  std::array<int, chip::kFeatureBanks> bank_depth_rows{};  // rows each bank needs for all lines
  uint64_t mlp_bytes = 0;                                  // one MLP as the MLP cache holds it

  // The paper's figures.
  double coarse_rays_per_iteration() const;  // rays advancing together per RP, coarse (paper: 3.89)
  double fine_rays_per_iteration() const;    // ... fine (paper: 3.48)
  double rps_per_tag_switch() const;         // CCRPs scheduled per CV tag switch
  double feature_hit_rate() const;           // feature cache requests that hit
  double micro_grid_hit_rate() const;
};

// The units whose counters make up a ChipCounters; the functional chip and
// the cycle simulator each keep one of every unit.
struct ChipUnits {
  const chip::Zorg& zorg;
  const chip::FrontEnd& front;
  const chip::Ctu& ctu;
  const chip::Ftu& ftu;
  const chip::RpRob& rob;
  const chip::OooSi& ooo;
  const chip::Cfiu& cfiu;
  const chip::Tme& tme;
  const chip::Vru& vru;
  const chip::RpBuffer& buffer;
};
// The units' counters, the feature cache's geometry and the MLP size; what
// the caller tallies itself (packets dropped, CV transitions, reschedules,
// RPs finished, fill waits) is left zero.
ChipCounters unit_counters(const ChipUnits& u);

// Registers every counter under `prefix` ("chip.ctu.coarse_checks", ...) with
// its unit and description, set to the values in `c`.
void export_chip_stats(const ChipCounters& c, StatsRegistry& stats, const std::string& prefix = "chip");

// Throws Error naming what is wrong unless the model is one the chip can
// render: micro resolution, bitmaps, lookups (finalize()), feature channels,
// an MLP for every occupied coarse voxel.
void check_chip_model(const SceneModel& model);

// Renders the camera's image through the chip model. The model must have its
// INT4 features and INT8 MLPs and be finalize()d. Throws Error on a bad
// config, camera or model.
Image render_chip(const SceneModel& model, const Camera& camera, const ChipConfig& config,
                  ChipCounters* counters = nullptr);

// The chip as a render engine with the reference renderer's signature: the
// default ChipConfig with the settings' step, threshold and background (the
// chip always reads the quantized model: a form of Float is an Error; threads
// and use_occupancy_tiers do not apply). stats: rays, rays that reach the
// traversal (hit the AABB), samples composited, bitmap checks of all tiers.
Image render_chip_engine(const SceneModel& model, const Camera& camera, const RenderSettings& settings,
                         RenderStats* stats = nullptr);

}  // namespace edrnr
