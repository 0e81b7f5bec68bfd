#include "chip/chip.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <optional>
#include <stdexcept>

#include "chip/chip_ray.h"
#include "chip/front_end.h"
#include "chip/rp_buffer.h"
#include "chip/zorg.h"
#include "core/error.h"
#include "core/file_io.h"
#include "core/yaml_read.h"

namespace edrnr {

using namespace chip;

// ---------------------------------------------------------------- config

void validate(const ChipConfig& c) {
  if (c.rp_buffer_capacity < 1) fail("chip config rp_buffer_capacity {} must be at least 1", c.rp_buffer_capacity);
  if (c.rp_rob.entries < 1) fail("chip config rp_rob.entries {} must be at least 1", c.rp_rob.entries);
  if (c.rp_rob.entry_depth < 1) fail("chip config rp_rob.entry_depth {} must be at least 1", c.rp_rob.entry_depth);
  if (c.rp_rob.recent_tags < 0) fail("chip config rp_rob.recent_tags {} must not be negative", c.rp_rob.recent_tags);
  if (c.ooo_queue_depth < 1) fail("chip config ooo_queue_depth {} must be at least 1", c.ooo_queue_depth);
  if (c.feature_cache_bytes < 1) fail("chip config feature_cache.bytes {} must be positive", c.feature_cache_bytes);
  if (c.mshr_entries < 1) fail("chip config feature_cache.mshr_entries {} must be at least 1", c.mshr_entries);
  if (c.mlp_cache_bytes < 1) fail("chip config mlp_cache_bytes {} must be positive", c.mlp_cache_bytes);
  if (c.micro_grid_cache_bytes < 0)
    fail("chip config micro_grid_cache_bytes {} must not be negative", c.micro_grid_cache_bytes);
  if (c.functional_fill_latency_issues < 0)
    fail("chip config functional_fill_latency_issues {} must not be negative", c.functional_fill_latency_issues);
  if (!(c.step_micro > 0.f) || !std::isfinite(c.step_micro))
    fail("chip config render.step_micro {} must be positive", c.step_micro);
  if (!(c.transmittance_min >= 0.f && c.transmittance_min <= 1.f))
    fail("chip config render.transmittance_min {} is outside [0, 1]", c.transmittance_min);
  for (int i = 0; i < 3; ++i)
    if (!(c.background[i] >= 0.f && c.background[i] <= 1.f))
      fail("chip config render.background[{}] = {} is outside [0, 1]", i, c.background[i]);
  edrnr::validate(c.numerics);
}

ChipConfig chip_config_from_yaml(const YAML::Node& node, std::string_view where_view) {
  const std::string where(where_view);
  ChipConfig c;
  if (!node || node.IsNull()) return c;
  yaml_for_each_key(
      node, where,
      {"rp_buffer_capacity", "rp_rob", "ooo_queue_depth", "feature_cache", "mlp_cache_bytes", "micro_grid_cache_bytes",
       "functional_fill_latency_issues", "render", "switches", "numerics", "simulator"},
      [&](const std::string& key, const YAML::Node& v, const std::string& at) {
        if (key == "rp_buffer_capacity") c.rp_buffer_capacity = yaml_scalar<int>(v, at, "an integer");
        if (key == "ooo_queue_depth") c.ooo_queue_depth = yaml_scalar<int>(v, at, "an integer");
        if (key == "mlp_cache_bytes") c.mlp_cache_bytes = yaml_scalar<int64_t>(v, at, "an integer");
        if (key == "micro_grid_cache_bytes") c.micro_grid_cache_bytes = yaml_scalar<int64_t>(v, at, "an integer");
        if (key == "functional_fill_latency_issues")
          c.functional_fill_latency_issues = yaml_scalar<int>(v, at, "an integer");
        if (key == "rp_rob")
          yaml_for_each_key(v, at, {"entries", "entry_depth", "recent_tags", "tag_switch", "switch_when"},
                            [&](const std::string& k, const YAML::Node& x, const std::string& a) {
                              if (k == "switch_when") {
                                const std::string w = yaml_scalar<std::string>(x, a, "retired or idle");
                                if (w != "retired" && w != "idle") fail("{}: '{}' is not retired or idle", a, w);
                                c.rp_rob.switch_when_idle = w == "idle";
                                return;
                              }
                              if (k == "tag_switch") {
                                c.rp_rob.tag_switch =
                                    parse_tag_switch_rule(yaml_scalar<std::string>(x, a, "a name"), a);
                                return;
                              }
                              int val = yaml_scalar<int>(x, a, "an integer");
                              if (k == "entries") c.rp_rob.entries = val;
                              if (k == "entry_depth") c.rp_rob.entry_depth = val;
                              if (k == "recent_tags") c.rp_rob.recent_tags = val;
                            });
        if (key == "feature_cache")
          yaml_for_each_key(v, at, {"bytes", "mshr_entries", "bank_mapping"},
                            [&](const std::string& k, const YAML::Node& x, const std::string& a) {
                              if (k == "bytes") c.feature_cache_bytes = yaml_scalar<int64_t>(x, a, "an integer");
                              if (k == "mshr_entries") c.mshr_entries = yaml_scalar<int>(x, a, "an integer");
                              if (k == "bank_mapping")
                                c.bank_mapping = parse_bank_mapping(yaml_scalar<std::string>(x, a, "a name"), a);
                            });
        if (key == "render")
          yaml_for_each_key(v, at, {"step_micro", "transmittance_min", "background"},
                            [&](const std::string& k, const YAML::Node& x, const std::string& a) {
                              if (k == "step_micro") c.step_micro = yaml_scalar<float>(x, a, "a number");
                              if (k == "transmittance_min") c.transmittance_min = yaml_scalar<float>(x, a, "a number");
                              if (k == "background") {
                                if (!x.IsSequence() || x.size() != 3) fail("{}: expected [r, g, b]", a);
                                for (int i = 0; i < 3; ++i)
                                  c.background[i] = yaml_scalar<float>(x[size_t(i)], a, "a number");
                              }
                            });
        if (key == "switches")
          yaml_for_each_key(v, at, {"z_order", "aabb", "lag_first", "rp_reorder", "ooo_issue"},
                            [&](const std::string& k, const YAML::Node& x, const std::string& a) {
                              const bool b = yaml_scalar<bool>(x, a, "true or false");
                              if (k == "z_order") c.switches.z_order = b;
                              if (k == "aabb") c.switches.aabb = b;
                              if (k == "lag_first") c.switches.lag_first = b;
                              if (k == "rp_reorder") c.switches.rp_reorder = b;
                              if (k == "ooo_issue") c.switches.ooo_issue = b;
                            });
        if (key == "numerics") c.numerics = numerics_from_yaml(v, at);
        // "simulator": timing, memory and energy of the cycle simulator
        // (sim/sim_config.h); the functional model does not use it.
      });
  try {
    validate(c);
  } catch (const Error& e) {
    fail("{}: {}", where, e.what());
  }
  return c;
}

ChipConfig load_chip_config(const std::filesystem::path& path) {
  const std::string text = read_file_text(path);
  YAML::Node node;
  try {
    node = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    fail("{}: not valid YAML: {}", path.string(), e.what());
  }
  return chip_config_from_yaml(node, path.string());
}

YAML::Node chip_config_to_yaml(const ChipConfig& c) {
  YAML::Node n;
  n["rp_buffer_capacity"] = c.rp_buffer_capacity;
  n["rp_rob"]["entries"] = c.rp_rob.entries;
  n["rp_rob"]["entry_depth"] = c.rp_rob.entry_depth;
  n["rp_rob"]["recent_tags"] = c.rp_rob.recent_tags;
  n["rp_rob"]["tag_switch"] = tag_switch_rule_name(c.rp_rob.tag_switch);
  n["rp_rob"]["switch_when"] = c.rp_rob.switch_when_idle ? "idle" : "retired";
  n["ooo_queue_depth"] = c.ooo_queue_depth;
  n["feature_cache"]["bytes"] = c.feature_cache_bytes;
  n["feature_cache"]["mshr_entries"] = c.mshr_entries;
  n["feature_cache"]["bank_mapping"] = bank_mapping_name(c.bank_mapping);
  n["mlp_cache_bytes"] = c.mlp_cache_bytes;
  n["micro_grid_cache_bytes"] = c.micro_grid_cache_bytes;
  n["functional_fill_latency_issues"] = c.functional_fill_latency_issues;
  n["render"]["step_micro"] = c.step_micro;
  n["render"]["transmittance_min"] = c.transmittance_min;
  for (int i = 0; i < 3; ++i) n["render"]["background"].push_back(c.background[i]);
  n["switches"]["z_order"] = c.switches.z_order;
  n["switches"]["aabb"] = c.switches.aabb;
  n["switches"]["lag_first"] = c.switches.lag_first;
  n["switches"]["rp_reorder"] = c.switches.rp_reorder;
  n["switches"]["ooo_issue"] = c.switches.ooo_issue;
  n["numerics"] = numerics_to_yaml(c.numerics);
  return n;
}

int feature_cache_lines(const ChipConfig& config, int feature_channels) {
  const int64_t block_bytes = (int64_t(kBlockVerts) * feature_channels * 4 + 7) / 8;
  const int64_t lines = config.feature_cache_bytes / block_bytes / kFeatureBanks * kFeatureBanks;
  if (lines < kFeatureBanks)
    fail("feature cache of {} bytes holds fewer than {} blocks of {} bytes", config.feature_cache_bytes, kFeatureBanks,
         block_bytes);
  return int(std::min<int64_t>(lines, 1 << 20));
}

// ---------------------------------------------------------------- counters

namespace {
double ratio(uint64_t a, uint64_t b) { return b ? double(a) / double(b) : 0.0; }
}  // namespace

ChipCounters unit_counters(const ChipUnits& u) {
  ChipCounters c;
  c.packets = u.zorg.packet_count();
  c.rays = u.front.counters().rays;
  c.rays_dropped_abt = u.front.counters().rays_dropped_abt;
  c.rays_dropped_tsps = u.front.counters().rays_dropped_tsps;
  c.tsps_position_evals = u.front.tsps_position_evals();
  c.zorg_skipped_quads = u.zorg.skipped_quads();
  c.ctu = u.ctu.counters();
  c.ftu = u.ftu.counters();
  c.rp_rob = u.rob.counters();
  c.ooo = u.ooo.counters();
  c.feature_cache = u.cfiu.cache().counters();
  c.cfiu = u.cfiu.counters();
  c.tme = u.tme.counters();
  c.vru = u.vru.counters();
  c.peak_rp_buffer = uint64_t(u.buffer.peak_in_use());
  c.feature_cache_lines = u.cfiu.cache().lines();
  for (int b = 0; b < chip::kFeatureBanks; ++b) c.bank_depth_rows[size_t(b)] = u.cfiu.cache().layout().bank_depth(b);
  c.mlp_bytes = u.tme.mlp_count() ? u.tme.mlp(0).stored_bytes : 0;
  return c;
}

double ChipCounters::coarse_rays_per_iteration() const { return ratio(ctu.rays_advanced, ctu.iterations); }
double ChipCounters::fine_rays_per_iteration() const { return ratio(ftu.rays_advanced, ftu.iterations); }
double ChipCounters::rps_per_tag_switch() const { return ratio(rp_rob.schedules, rp_rob.tag_runs); }
double ChipCounters::feature_hit_rate() const { return ratio(feature_cache.hits, feature_cache.requests); }
double ChipCounters::micro_grid_hit_rate() const { return ratio(ftu.micro_word_hits, ftu.micro_word_reads); }

void export_chip_stats(const ChipCounters& c, StatsRegistry& s, const std::string& p) {
  auto cnt = [&](const std::string& name, const char* unit, const char* what, uint64_t v) {
    s.counter(p + "." + name, unit, what).value = v;
  };
  auto val = [&](const std::string& name, const char* unit, const char* what, double v) {
    s.value(p + "." + name, unit, what).value = v;
  };
  cnt("zorg.packets", "RPs", "ray packets issued by ZORG", c.packets);
  cnt("zorg.rays", "rays", "valid rays generated", c.rays);
  cnt("zorg.skipped_quads", "quads", "out-of-bounds Z-order quads jumped over", c.zorg_skipped_quads);
  cnt("abt.rays_dropped", "rays", "rays dropped by the AABB tester", c.rays_dropped_abt);
  cnt("tsps.rays_dropped", "rays", "rays with no candidate in the traversal box", c.rays_dropped_tsps);
  cnt("tsps.position_evals", "positions", "positions computed by the entry-point search", c.tsps_position_evals);
  cnt("packets_dropped", "RPs", "RPs with no ray left after ABT/TSPS", c.packets_dropped);
  cnt("ctu.iterations", "iterations", "coarse traversal iterations (LFAU selections)", c.ctu.iterations);
  cnt("ctu.coarse_checks", "lookups", "coarse bitmap checks", c.ctu.coarse_checks);
  cnt("ctu.candidates", "CRPs", "candidate RPs sent to the RP-ROB", c.ctu.candidates);
  val("ctu.rays_per_iteration", "rays", "rays advancing together per RP in coarse traversal",
      c.coarse_rays_per_iteration());
  cnt("ftu.iterations", "iterations", "fine traversal iterations (LFAU selections)", c.ftu.iterations);
  cnt("ftu.fine_checks", "lookups", "fine bitmap checks", c.ftu.fine_checks);
  cnt("ftu.leaf_checks", "lookups", "leaf checks (from micro-grid words)", c.ftu.leaf_checks);
  cnt("ftu.micro_checks", "lookups", "micro checks (from micro-grid words)", c.ftu.micro_checks);
  cnt("ftu.micro_word_reads", "words", "64-bit micro-grid bitmap words read", c.ftu.micro_word_reads);
  val("ftu.micro_grid_hit_rate", "ratio", "micro-grid bitmap cache hit rate", c.micro_grid_hit_rate());
  cnt("ftu.candidate_tests", "candidates", "candidates of occupied leaves tested against their micro bit",
      c.ftu.candidate_tests);
  cnt("ftu.samples", "samples", "samples generated", c.ftu.samples);
  cnt("ftu.batches", "CCRP_SPs", "sample batches (one RP, one fine voxel)", c.ftu.batches);
  val("ftu.rays_per_iteration", "rays", "rays advancing together per RP in fine traversal",
      c.fine_rays_per_iteration());
  cnt("rp_rob.inserts", "CRPs", "CRPs inserted", c.rp_rob.inserts);
  cnt("rp_rob.insert_refusals", "attempts", "inserts refused for lack of room", c.rp_rob.insert_refusals);
  cnt("rp_rob.schedules", "CCRPs", "CCRPs scheduled to the FTU", c.rp_rob.schedules);
  cnt("rp_rob.tag_runs", "runs", "runs of schedules with one CV tag", c.rp_rob.tag_runs);
  cnt("rp_rob.recorder_hits", "switches", "tag switches decided by the recent-tags recorder", c.rp_rob.recorder_hits);
  val("rp_rob.rps_per_tag_switch", "CCRPs", "CCRPs scheduled per CV tag switch", c.rps_per_tag_switch());
  cnt("ooo.issued", "CCRP_SPs", "sample batches issued", c.ooo.issued);
  cnt("ooo.issued_out_of_order", "CCRP_SPs", "batches issued from behind the queue head", c.ooo.issued_out_of_order);
  cnt("ooo.fill_waits", "issues", "issue slots spent waiting for a feature block", c.fill_waits);
  cnt("feature_cache.requests", "requests", "feature block requests", c.feature_cache.requests);
  cnt("feature_cache.hits", "requests", "requests that hit", c.feature_cache.hits);
  cnt("feature_cache.misses", "blocks", "blocks fetched (MSHR entries opened)", c.feature_cache.misses);
  cnt("feature_cache.merged_misses", "requests", "misses merged by the MSHR", c.feature_cache.merged_misses);
  cnt("feature_cache.evictions", "lines", "lines evicted", c.feature_cache.evictions);
  val("feature_cache.hit_rate", "ratio", "feature cache hit rate", c.feature_hit_rate());
  cnt("feature_cache.lines", "lines", "feature cache lines (fine-voxel blocks)", uint64_t(c.feature_cache_lines));
  for (int b = 0; b < kFeatureBanks; ++b)
    cnt("feature_cache.bank" + std::to_string(b) + "_depth", "rows", "rows the bank needs for all lines",
        uint64_t(c.bank_depth_rows[size_t(b)]));
  cnt("cfiu.samples", "samples", "samples interpolated", c.cfiu.samples);
  cnt("cfiu.fetch_cycles", "cycles", "bank access cycles", c.cfiu.fetch_cycles);
  cnt("cfiu.conflict_cycles", "cycles", "extra cycles from bank conflicts", c.cfiu.conflict_cycles);
  cnt("tme.samples", "samples", "samples through the MLP", c.tme.samples);
  cnt("tme.macs", "MACs", "multiply-accumulates", c.tme.macs);
  cnt("tme.mlp_loads", "loads", "MLP cache loads (CV switches)", c.tme.mlp_loads);
  cnt("tme.mlp_load_bytes", "bytes", "bytes loaded into the MLP cache", c.tme.mlp_load_bytes);
  cnt("tme.saturations", "values", "accumulator or output values clipped", c.tme.saturations);
  cnt("tme.mlp_bytes", "bytes", "one MLP as the MLP cache holds it", c.mlp_bytes);
  cnt("vru.samples", "samples", "samples composited", c.vru.samples);
  cnt("vru.samples_skipped", "samples", "samples of rays already stopped", c.vru.samples_skipped);
  cnt("vru.rays_terminated", "rays", "rays stopped by the transmittance threshold", c.vru.rays_terminated);
  cnt("cv_transitions", "RPs", "RPs sent back to the CTU", c.cv_transitions);
  cnt("fine_reschedules", "RPs", "RPs sent back to the FTU", c.fine_reschedules);
  cnt("rps_finished", "RPs", "RPs retired after traversal", c.rps_finished);
  cnt("peak_rp_buffer", "RPs", "most RPs in flight at once", c.peak_rp_buffer);
}

// ---------------------------------------------------------------- render

void check_chip_model(const SceneModel& m) {
  m.check_structure();
  if (m.micro_res > 1024) fail("model micro resolution {} exceeds the chip's 1024", m.micro_res);
  if (m.feature_channels < 1 || m.feature_channels > kMaxLayerWidth)
    fail("model has {} feature channels (1..{} supported)", m.feature_channels, kMaxLayerWidth);
  const Bitmap3& coarse = m.occupancy[int(Tier::Coarse)];
  for (size_t i = 0; i < coarse.size(); ++i)
    if (coarse.get(i) && m.coarse_to_mlp[i] < 0) fail("model: occupied coarse voxel {} has no MLP", i);
}

namespace {

// A feature block requested from DRAM, due at an issue number.
struct PendingFill {
  uint32_t block;
  uint64_t due;
};

class FunctionalChip {
 public:
  FunctionalChip(const SceneModel& model, const Camera& camera, const ChipConfig& config)
      : model_(model),
        config_(config),
        n_(config.numerics),
        delta_(double(config.step_micro) * double(model.scene_box.size().x) / double(model.micro_res)),
        math_(n_.traversal_float, config.step_micro, model.micro_res),
        zorg_(camera.width, camera.height, config.switches.z_order ? ScanOrder::ZOrder : ScanOrder::RowOrder),
        front_(model, camera, n_, math_, config.switches.aabb),
        buffer_(config.rp_buffer_capacity),
        ctu_(model, math_, config.switches.lag_first),
        rob_(RpRobConfig{config.rp_rob.entries, config.rp_rob.entry_depth, config.rp_rob.recent_tags,
                         config.switches.rp_reorder, config.rp_rob.tag_switch, config.rp_rob.switch_when_idle}),
        ftu_(model, math_, config.switches.lag_first, size_t(config.micro_grid_cache_bytes / 8)),
        ooo_(config.ooo_queue_depth, config.switches.ooo_issue),
        cfiu_(model, n_,
              FeatureCacheConfig{feature_cache_lines(config, model.feature_channels), config.mshr_entries,
                                 config.bank_mapping}),
        tme_(model, n_, delta_, size_t(config.mlp_cache_bytes)),
        vru_(n_, config.transmittance_min, config.background),
        image_(camera.width, camera.height, 3),
        batches_(size_t(config.ooo_queue_depth)),
        feature_(size_t(model.feature_channels)) {
    for (uint32_t i = 0; i < uint32_t(config.ooo_queue_depth); ++i) free_batches_.push_back(i);
    if (cfiu_.cache().lines() <= config.ooo_queue_depth)
      fail("chip config: the feature cache's {} lines must outnumber the {} OoO-SI entries that reserve them",
           cfiu_.cache().lines(), config.ooo_queue_depth);
  }

  Image run(ChipCounters* counters) {
    for (;;) {
      bool progress = admit();
      progress |= coarse_traverse();
      progress |= insert();
      progress |= fill_ooo_queue();
      progress |= issue();
      if (!progress) break;
    }
    if (!zorg_.done() || buffer_.in_use() != 0 || !rob_.empty() || !ooo_.empty() || !pending_.empty())
      throw std::logic_error("chip pipeline stopped with work left");
    if (counters) collect(*counters);
    return std::move(image_);
  }

 private:
  // ZORG -> ABT -> TSPS, while the RP buffer has room.
  bool admit() {
    bool progress = false;
    while (!zorg_.done() && !buffer_.full()) {
      progress = true;
      RayPacket p = front_.build(zorg_.next(), vru_);
      if (!p.live_mask()) {  // background only: no pointer needed
        ++packets_dropped_;
        write_pixels(p);
        continue;
      }
      const uint32_t rp = *buffer_.allocate();
      buffer_[rp] = std::move(p);
      ctu_queue_.push_back(rp);
    }
    return progress;
  }

  bool coarse_traverse() {
    bool progress = false;
    while (!ctu_queue_.empty()) {
      progress = true;
      const uint32_t rp = ctu_queue_.front();
      ctu_queue_.pop_front();
      const CtuResult r = ctu_.run(buffer_[rp]);
      if (r.found)
        insert_queue_.push_back({rp, r.cv_tag});
      else
        finish(rp);
    }
    return progress;
  }

  bool insert() {
    bool progress = false;
    while (!insert_queue_.empty() && rob_.insert(insert_queue_.front().first, insert_queue_.front().second)) {
      insert_queue_.pop_front();
      progress = true;
    }
    return progress;
  }

  // RP-ROB -> FTU -> OoO-SI until the location shifter is full.
  bool fill_ooo_queue() {
    bool progress = false;
    while (!ooo_.full()) {
      const auto s = rob_.schedule();
      if (!s) break;
      progress = true;
      const uint32_t slot = free_batches_.front();
      SampleBatch& batch = batches_[slot];
      if (!ftu_.run(buffer_[s->rp], s->rp, s->tag, batch)) {
        leave_cv(s->rp);
        continue;
      }
      free_batches_.pop_front();
      // Prefetch: reserve the block's line, fetching it on a miss.
      const uint32_t block = uint32_t(batch.block);
      for (;;) {
        const CacheAccess a = cfiu_.cache().request(block);
        if (a == CacheAccess::MissAllocated)
          pending_.push_back({block, issue_clock_ + uint64_t(config_.functional_fill_latency_issues)});
        if (a != CacheAccess::Stall) break;
        complete_oldest_fill();  // no MSHR entry or line free: wait for a fill
      }
      ooo_.push({s->rp, block, slot});
    }
    return progress;
  }

  void complete_oldest_fill() {
    if (pending_.empty()) throw std::logic_error("feature cache stalled with no fill outstanding");
    const PendingFill f = pending_.front();
    pending_.pop_front();
    issue_clock_ = std::max(issue_clock_, f.due);
    cfiu_.cache().fill(f.block);
  }

  // OoO-SI -> CFIU -> TME -> VRU for one CCRP_SP, then reschedule or retire.
  bool issue() {
    if (ooo_.empty()) return false;
    while (!pending_.empty() && pending_.front().due <= issue_clock_) complete_oldest_fill();
    std::optional<int> pos = ooo_.select(cfiu_.cache());
    while (!pos) {
      ++fill_waits_;
      complete_oldest_fill();
      pos = ooo_.select(cfiu_.cache());
    }
    const LsEntry e = ooo_.take(*pos);
    SampleBatch& batch = batches_[e.data_base];
    RayPacket& p = buffer_[e.rp];
    tme_.load(batch.cv_tag);
    for (const SampleRef& sref : batch.samples) {
      RayState& ray = p.rays[sref.ray];
      const SampleCoord sc = sample_coordinate(math_, ray.ray, sref.k, n_.interp_fraction_bits, n_.rounding);
      cfiu_.interpolate(e.block, sc, feature_.data());
      const TmeOutput out = tme_.eval(feature_.data(), ray.dir_code);
      vru_.composite(ray, out.alpha, out.rgb);
    }
    cfiu_.cache().release(e.block);
    free_batches_.push_back(e.data_base);
    ++issue_clock_;
    // Fine-voxel transition: more to do in this CV? Else the RP leaves it.
    if (has_live_ray_in(p, batch.cv_tag)) {
      ++fine_reschedules_;
      rob_.reschedule(e.rp);
    } else {
      leave_cv(e.rp);
    }
    return true;
  }

  bool has_live_ray_in(const RayPacket& p, uint32_t cv_tag) const {
    for (const RayState& r : p.rays) {
      if (!r.live()) continue;
      const Vec3i c = math_.cell_at(r.ray, r.k, kCoarseCellMicro);
      if (linear_index(c.x, c.y, c.z, model_.coarse_res()) == cv_tag) return true;
    }
    return false;
  }

  // Retire from the RP-ROB: back to the CTU (pointer kept) or finished.
  void leave_cv(uint32_t rp) {
    rob_.retire(rp);
    if (buffer_[rp].live_mask()) {
      ++cv_transitions_;
      ctu_queue_.push_back(rp);
    } else {
      finish(rp);
    }
  }

  void finish(uint32_t rp) {
    write_pixels(buffer_[rp]);
    buffer_.release(rp);
    ++rps_finished_;
  }

  void write_pixels(const RayPacket& p) {
    for (int r = 0; r < kRaysPerPacket; ++r) {
      if (!(p.pixels.valid_mask >> r & 1)) continue;
      const auto px = vru_.pixel(p.rays[size_t(r)]);
      float* out = image_.at(p.pixels.x[size_t(r)], p.pixels.y[size_t(r)]);
      for (int c = 0; c < 3; ++c) out[c] = px[size_t(c)];
    }
  }

  void collect(ChipCounters& c) const {
    c = unit_counters({zorg_, front_, ctu_, ftu_, rob_, ooo_, cfiu_, tme_, vru_, buffer_});
    c.packets_dropped = packets_dropped_;
    c.cv_transitions = cv_transitions_;
    c.fine_reschedules = fine_reschedules_;
    c.rps_finished = rps_finished_;
    c.fill_waits = fill_waits_;
  }

  const SceneModel& model_;
  const ChipConfig& config_;
  ChipNumerics n_;
  double delta_;
  RayMath math_;
  Zorg zorg_;
  FrontEnd front_;
  RpBuffer buffer_;
  Ctu ctu_;
  RpRob rob_;
  Ftu ftu_;
  OooSi ooo_;
  Cfiu cfiu_;
  Tme tme_;
  Vru vru_;
  Image image_;
  std::vector<SampleBatch> batches_;  // the computation SRAM, one slot per OoO-SI entry
  std::deque<uint32_t> free_batches_;
  std::vector<int32_t> feature_;
  std::deque<uint32_t> ctu_queue_;
  std::deque<std::pair<uint32_t, uint32_t>> insert_queue_;  // (RP, CV tag) waiting for the RP-ROB
  std::deque<PendingFill> pending_;
  uint64_t issue_clock_ = 0;
  uint64_t packets_dropped_ = 0;
  uint64_t cv_transitions_ = 0, fine_reschedules_ = 0, rps_finished_ = 0, fill_waits_ = 0;
};

}  // namespace

Image render_chip(const SceneModel& model, const Camera& camera, const ChipConfig& config, ChipCounters* counters) {
  validate(config);
  check_chip_model(model);
  if (camera.width < 1 || camera.height < 1) fail("camera image size {}x{} is empty", camera.width, camera.height);
  FunctionalChip chip(model, camera, config);
  return chip.run(counters);
}

Image render_chip_engine(const SceneModel& model, const Camera& camera, const RenderSettings& settings,
                         RenderStats* stats) {
  if (settings.form == ModelForm::Float)
    fail("the chip renders the quantized model only (use --form quantized or auto)");
  ChipConfig config;
  config.step_micro = settings.step_micro;
  config.transmittance_min = settings.transmittance_min;
  for (int c = 0; c < 3; ++c) config.background[c] = settings.background[c];
  ChipCounters counters;
  Image image = render_chip(model, camera, config, &counters);
  if (stats) {
    stats->rays = counters.rays;
    stats->rays_hit_aabb = counters.rays - counters.rays_dropped_abt - counters.rays_dropped_tsps;
    stats->samples = counters.vru.samples;
    stats->occupancy_checks =
        counters.ctu.coarse_checks + counters.ftu.fine_checks + counters.ftu.leaf_checks + counters.ftu.micro_checks;
  }
  return image;
}

}  // namespace edrnr
