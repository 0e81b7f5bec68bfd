// edrnr chip-render: renders one image through the bit-accurate functional
// model of the EDR-NR chip and reports what its units counted.
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>

#include "chip/chip.h"
#include "commands.h"
#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"
#include "core/metrics.h"
#include "core/stats.h"
#include "model/model_io.h"
#include "render/cameras.h"
#include "render/options.h"
#include "render/reference.h"
#include "sim/sim_config.h"

namespace edrnr::cli {
namespace {

struct ChipRenderOptions {
  std::string model, output, config_file, camera_file, stats_file, banks, background;
  double orbit = 0, elevation = 30, radius = 4, fov = 40;
  int width = 800, height = 0;
  bool no_z_order = false, no_aabb = false, no_lag_first = false, no_rp_reorder = false, no_ooo = false;
  bool reference = false;
  CLI::Option *orbit_opt = nullptr, *camera_opt = nullptr, *width_opt = nullptr, *height_opt = nullptr;
};

Camera pick_camera(const ChipRenderOptions& o) {
  if ((o.orbit_opt->count() > 0) == (o.camera_opt->count() > 0)) fail("give exactly one of --orbit and --camera");
  if (o.camera_opt->count()) {
    Camera cam = load_camera_json(o.camera_file);
    if (!o.width_opt->count() && !o.height_opt->count()) {
      limits::check_image_size(cam.width, cam.height, fmt::format("--camera '{}': image size", o.camera_file));
      return cam;
    }
    const int w = o.width_opt->count() ? o.width : cam.width;
    const int h = o.height_opt->count()
                      ? o.height
                      : int(std::clamp<double>(std::round(double(w) * cam.height / cam.width), 1, 1e9));
    limits::check_image_size(w, h, "--width/--height");
    return resize_camera(cam, w, h);
  }
  const int h = o.height_opt->count() ? o.height : o.width;
  limits::check_image_size(o.width, h, "--width/--height");
  return orbit_camera(o.width, h, o.orbit, o.elevation, o.radius, o.fov);
}

void run_chip_render(const ChipRenderOptions& o) {
  ChipConfig cfg = o.config_file.empty() ? ChipConfig{} : load_chip_config(o.config_file);
  if (o.no_z_order) cfg.switches.z_order = false;
  if (o.no_aabb) cfg.switches.aabb = false;
  if (o.no_lag_first) cfg.switches.lag_first = false;
  if (o.no_rp_reorder) cfg.switches.rp_reorder = false;
  if (o.no_ooo) cfg.switches.ooo_issue = false;
  if (!o.banks.empty()) cfg.bank_mapping = chip::parse_bank_mapping(o.banks, "--banks");
  if (!o.background.empty()) parse_background(o.background, "--background", cfg.background);
  validate(cfg);
  sim::check_chip_limits(cfg);
  check_step_micro(cfg.step_micro, 0, "chip config render.step_micro");
  check_output_path(o.output, "-o");
  if (!o.stats_file.empty()) check_output_path(o.stats_file, "--stats");
  const Camera cam = pick_camera(o);
  const SceneModel model = load_model(o.model);
  check_step_micro(cfg.step_micro, model.micro_res, "chip config render.step_micro");

  ChipCounters counters;
  const auto t0 = std::chrono::steady_clock::now();
  const Image img = render_chip(model, cam, cfg, &counters);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  write_png(o.output, img);
  // The fully resolved config beside the result (not beside a device or FIFO:
  // /dev/stdout.chip.yaml is no place for it).
  const bool config_beside = output_is_regular_file(o.output);
  if (config_beside) {
    std::stringstream yaml;
    yaml << chip_config_to_yaml(cfg) << "\n";
    write_file_atomic(o.output + ".chip.yaml", yaml.str());
  }

  StatsRegistry stats;
  export_chip_stats(counters, stats);
  if (o.reference) {
    RenderSettings rs;
    rs.step_micro = cfg.step_micro;
    rs.transmittance_min = cfg.transmittance_min;
    for (int c = 0; c < 3; ++c) rs.background[c] = cfg.background[c];
    rs.form = ModelForm::Quantized;
    const Image ref = render_reference(model, cam, rs);
    stats.value("chip.psnr_vs_reference", "dB", "PSNR against the float reference on the quantized model")
        .set(psnr(img, ref));
  }
  stats.value("chip.functional_seconds", "s", "wall time of the functional model").set(seconds);
  if (!o.stats_file.empty()) write_file_atomic(o.stats_file, stats.to_json().dump(2) + "\n");

  fmt::print("{}: {}x{} through the chip model in {:.2f} s ({})\n", o.output, img.width, img.height, seconds,
             config_beside ? fmt::format("config beside it: {}.chip.yaml", o.output)
                           : std::string("not a regular file: no config written beside it"));
  fmt::print("  rays advancing together per RP: coarse {:.2f} (paper 3.89), fine {:.2f} (paper 3.48)\n",
             counters.coarse_rays_per_iteration(), counters.fine_rays_per_iteration());
  fmt::print("  CCRPs per CV tag switch {:.2f}; feature cache hit rate {:.4f}; micro-grid hit rate {:.4f}\n",
             counters.rps_per_tag_switch(), counters.feature_hit_rate(), counters.micro_grid_hit_rate());
  if (o.reference)
    fmt::print("  PSNR against the reference renderer: {:.2f} dB\n", stats.get("chip.psnr_vs_reference"));
  stats.print_table(std::cout);
}

void register_chip_cmd(CLI::App& app) {
  auto o = std::make_shared<ChipRenderOptions>();
  CLI::App* cmd = app.add_subcommand("chip-render", "Render one image through the functional EDR-NR chip model");
  cmd->add_option("model", o->model, "the .edrnr model (its INT4 features and INT8 MLPs are used)")->required();
  cmd->add_option("-o,--output", o->output, "the PNG to write")->required();
  cmd->add_option("--config", o->config_file, "chip config YAML (default: built-in, configs/chip/default.yaml)");
  o->orbit_opt = cmd->add_option("--orbit", o->orbit, "camera on a circle around the origin, at this azimuth (deg)");
  cmd->add_option("--elevation", o->elevation, "orbit elevation (deg)")->capture_default_str();
  cmd->add_option("--radius", o->radius, "orbit radius (scene units)")->capture_default_str();
  cmd->add_option("--fov", o->fov, "orbit horizontal field of view (deg)")->capture_default_str();
  o->camera_opt = cmd->add_option("--camera", o->camera_file, "camera from a JSON file (docs/rendering.md)");
  o->width_opt = cmd->add_option("--width", o->width, "image width")->capture_default_str();
  o->height_opt = cmd->add_option("--height", o->height, "image height (default: square, or the camera's aspect)");
  cmd->add_option("--background", o->background, "white, black or R,G,B (default: the config's)");
  cmd->add_flag("--no-z-order", o->no_z_order, "row-order ray packets");
  cmd->add_flag("--no-aabb", o->no_aabb, "traverse the whole scene box");
  cmd->add_flag("--no-lag-first", o->no_lag_first, "the first live ray leads instead of the lagging ones");
  cmd->add_flag("--no-rp-reorder", o->no_rp_reorder, "RP-ROB as a plain FIFO");
  cmd->add_flag("--no-ooo", o->no_ooo, "issue samples in order");
  cmd->add_option("--banks", o->banks, "feature bank mapping: balanced, direct or linear");
  cmd->add_option("--stats", o->stats_file, "write every counter as JSON to this file");
  cmd->add_flag("--reference", o->reference, "also render with the reference renderer and report the PSNR");
  cmd->callback([o] { run_chip_render(*o); });
}

Registrar reg{50, register_chip_cmd};

}  // namespace
}  // namespace edrnr::cli
