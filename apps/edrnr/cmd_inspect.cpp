// edrnr inspect: validates a .edrnr model and prints its tiers, features,
// MLPs, metadata, DRAM footprint by data type, and the model checks.
#include <fmt/format.h>

#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "commands.h"
#include "core/error.h"
#include "core/file_io.h"
#include "model/footprint.h"
#include "model/model_io.h"

namespace edrnr::cli {
namespace {

struct InspectOptions {
  std::string file;
  bool json = false;
  bool no_check = false;
};

std::string widths_text(const std::vector<int>& widths) {
  return widths.empty() ? std::string("-") : fmt::format("{}", fmt::join(widths, "-"));
}

std::string box_text(const Box3f& b) {
  return fmt::format("[{}, {}, {}] .. [{}, {}, {}]", b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z);
}

nlohmann::ordered_json box_json(const Box3f& b) {
  return {{"lo", {b.lo.x, b.lo.y, b.lo.z}}, {"hi", {b.hi.x, b.hi.y, b.hi.z}}};
}

// Bytes of one float MLP: 4 per weight and per bias.
size_t mlp_f32_bytes(const MlpArch& a) { return 4 * (a.weight_count() + a.bias_count()); }

nlohmann::ordered_json report_json(const InspectOptions& o, size_t file_bytes, const SceneModel& m,
                                   const std::vector<ModelCheck>& checks, bool ok) {
  nlohmann::ordered_json tiers = nlohmann::ordered_json::array();
  for (int t = 0; t < kTierCount; ++t) {
    const Bitmap3& bm = m.occupancy[t];
    tiers.push_back({{"tier", tier_name(Tier(t))},
                     {"resolution", bm.res()},
                     {"voxels", bm.size()},
                     {"occupied", bm.count()},
                     {"occupied_percent", 100.0 * double(bm.count()) / double(bm.size())}});
  }
  const size_t F = size_t(m.feature_channels);
  const DramFootprint fp = dram_footprint(m);
  nlohmann::ordered_json j;
  j["file"] = o.file;
  j["file_bytes"] = file_bytes;
  j["format_version"] = kModelFormatVersion;
  j["scene_box"] = box_json(m.scene_box);
  j["object_aabb"] = box_json(m.object_aabb);
  j["micro_res"] = m.micro_res;
  j["tiers"] = tiers;
  j["features"] = {{"channels", F},
                   {"blocks", m.block_count()},
                   {"int4", !m.features_q4.empty()},
                   {"int4_bytes_per_block", feature_block_q4_bytes(m.feature_channels)},
                   {"float", !m.features_f32.empty()},
                   {"float_bytes", m.features_f32.size() * 4}};
  j["mlps"] = {{"count", m.mlp_count()},
               {"density_widths", m.mlp_arch.density_widths},
               {"color_widths", m.mlp_arch.color_widths},
               {"dir_frequencies", m.mlp_arch.dir_frequencies},
               {"int8", !m.mlps_q8.empty()},
               {"float", !m.mlps_f32.empty()},
               {"q8_bytes_per_mlp", m.mlp_arch.q8_bytes()},
               {"f32_bytes_per_mlp", mlp_f32_bytes(m.mlp_arch)},
               {"mlp_cache_bytes", kMlpCacheBytes},
               {"fits_mlp_cache", m.mlp_arch.q8_bytes() <= kMlpCacheBytes}};
  j["metadata"] = nlohmann::ordered_json::parse(m.metadata_json);
  j["dram_footprint_bytes"] = {{"coarse_bitmap", fp.coarse_bitmap_bytes},  {"fine_bitmap", fp.fine_bitmap_bytes},
                               {"micro_grid_bitmap", fp.micro_grid_bytes}, {"features", fp.feature_bytes},
                               {"mlp_weights", fp.mlp_weight_bytes},       {"total", fp.total_bytes()}};
  j["checks_run"] = !o.no_check;
  nlohmann::ordered_json cj = nlohmann::ordered_json::array();
  for (const ModelCheck& c : checks) cj.push_back({{"name", c.name}, {"passed", c.passed}, {"detail", c.detail}});
  j["checks"] = cj;
  j["ok"] = ok;
  return j;
}

void print_text(const InspectOptions& o, size_t file_bytes, const SceneModel& m,
                const std::vector<ModelCheck>& checks) {
  std::string out;
  auto line = [&out](const std::string& s) { out += s + "\n"; };
  line(fmt::format("file          {} ({} bytes, format version {})", o.file, file_bytes, kModelFormatVersion));
  line(fmt::format("scene box     {}", box_text(m.scene_box)));
  line(fmt::format("object AABB   {}", box_text(m.object_aabb)));
  nlohmann::ordered_json meta = nlohmann::ordered_json::parse(m.metadata_json);
  if (meta.empty()) line("metadata      (none)");
  bool first = true;
  for (auto it = meta.begin(); it != meta.end(); ++it, first = false)
    line(fmt::format("{}{}: {}", first ? "metadata      " : "              ", it.key(), it.value().dump()));

  line("");
  line(fmt::format("{:<12}{:>12}{:>14}{:>12}{:>10}", "occupancy", "resolution", "voxels", "occupied", "%"));
  for (int t = 0; t < kTierCount; ++t) {
    const Bitmap3& bm = m.occupancy[t];
    line(fmt::format("  {:<10}{:>12}{:>14}{:>12}{:>10.3f}", tier_name(Tier(t)), fmt::format("{}^3", bm.res()),
                     bm.size(), bm.count(), 100.0 * double(bm.count()) / double(bm.size())));
  }

  line("");
  const size_t per_block = feature_block_q4_bytes(m.feature_channels);
  line(fmt::format("features      {} blocks of 125 vertices x {} channels", m.block_count(), m.feature_channels));
  line(m.features_q4.empty()
           ? "  INT4        absent"
           : fmt::format("  INT4        {} bytes ({} per block)", m.block_count() * per_block, per_block));
  line(m.features_f32.empty() ? "  float       absent"
                              : fmt::format("  float       {} bytes", m.features_f32.size() * 4));

  const MlpArch& a = m.mlp_arch;
  line(fmt::format("MLPs          {}, one per occupied coarse voxel", m.mlp_count()));
  line(fmt::format("  shape       density {}, colour {}, {} direction frequencies", widths_text(a.density_widths),
                   widths_text(a.color_widths), a.dir_frequencies));
  line(fmt::format("  INT8        {}: {} bytes per MLP; {} the {}-byte MLP cache",
                   m.mlps_q8.empty() ? "absent" : "present", a.q8_bytes(),
                   a.q8_bytes() <= kMlpCacheBytes ? "fits" : "DOES NOT fit", kMlpCacheBytes));
  line(m.mlps_f32.empty() ? "  float       absent"
                          : fmt::format("  float       present: {} bytes per MLP", mlp_f32_bytes(a)));

  line("");
  const DramFootprint fp = dram_footprint(m);
  line("DRAM footprint, as the chip stores it");
  line(fmt::format("  {:<20}{:>14} B", "coarse bitmap", fp.coarse_bitmap_bytes));
  line(fmt::format("  {:<20}{:>14} B", "fine bitmap", fp.fine_bitmap_bytes));
  line(fmt::format("  {:<20}{:>14} B   (8 B per occupied fine voxel)", "micro-grid bitmap", fp.micro_grid_bytes));
  line(fmt::format("  {:<20}{:>14} B   (INT4 blocks)", "features", fp.feature_bytes));
  line(fmt::format("  {:<20}{:>14} B   (INT8, per MLP {} B)", "MLP weights", fp.mlp_weight_bytes, a.q8_bytes()));
  line(fmt::format("  {:<20}{:>14} B   ({:.3f} MiB)", "total", fp.total_bytes(),
                   double(fp.total_bytes()) / (1024.0 * 1024.0)));

  line("");
  if (o.no_check) {
    line("checks        skipped (--no-check)");
  } else {
    line("checks");
    for (const ModelCheck& c : checks)
      line(c.passed ? fmt::format("  PASS  {}", c.name) : fmt::format("  FAIL  {}: {}", c.name, c.detail));
  }
  std::cout << out;
}

void run_inspect(const InspectOptions& o) {
  std::vector<uint8_t> bytes = read_model_file(o.file);
  // The format itself is always validated; the model checks are reported below instead of thrown.
  SceneModel m = parse_model(bytes.data(), bytes.size(), o.file, ModelLoadOptions{.check_invariants = false});
  std::vector<ModelCheck> checks;
  if (!o.no_check) checks = model_checks(m);
  size_t failed = 0;
  for (const ModelCheck& c : checks) failed += !c.passed;

  if (o.json)
    std::cout << report_json(o, bytes.size(), m, checks, failed == 0).dump(2) << "\n";
  else
    print_text(o, bytes.size(), m, checks);
  std::cout.flush();
  if (failed) fail("{}: {} of {} model checks failed", o.file, failed, checks.size());
}

void register_inspect_cmd(CLI::App& app) {
  auto opts = std::make_shared<InspectOptions>();
  CLI::App* cmd = app.add_subcommand("inspect", "Validate a .edrnr model and print its contents and DRAM footprint");
  cmd->add_option("file", opts->file, "the .edrnr model file")->required();
  cmd->add_flag("--json", opts->json, "print the report as one JSON object");
  cmd->add_flag("--no-check", opts->no_check, "skip the model checks (tiers, blocks, MLPs, AABB)");
  cmd->callback([opts] { run_inspect(*opts); });
}

Registrar reg{10, register_inspect_cmd};

}  // namespace
}  // namespace edrnr::cli
