// edrnr make-scene: writes a procedural scene model (sphere, box, torus or
// several objects) built from analytic density and colour fields.
#include <fmt/format.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>

#include "commands.h"
#include "core/error.h"
#include "core/file_io.h"
#include "model/model_io.h"
#include "model/procedural.h"
#include "render/options.h"

namespace edrnr::cli {
namespace {

struct MakeSceneOptions {
  std::string scene;
  std::string output;
  int res = 256;
  int channels = 16;
  uint64_t seed = 0;
  bool quantized_only = false;
  std::string center, half_size, color;
  float radius = 0, tube_radius = 0, sigma = 0;
  CLI::Option *radius_opt = nullptr, *tube_opt = nullptr, *sigma_opt = nullptr;
};

void run_make_scene(const MakeSceneOptions& o) {
  if (o.res <= 0 || o.res % 32 || o.res > kMaxMicroRes)
    fail("--res {}: must be a multiple of 32 between 32 and {}", o.res, kMaxMicroRes);
  if (o.channels < 4 || o.channels > kMaxFeatureChannels)
    fail("--channels {}: must be between 4 and {}", o.channels, kMaxFeatureChannels);

  check_output_path(o.output, "-o");
  std::vector<Shape> shapes = procedural_shapes(o.scene);
  const bool overrides = !o.center.empty() || !o.half_size.empty() || !o.color.empty() || o.radius_opt->count() ||
                         o.tube_opt->count() || o.sigma_opt->count();
  if (overrides) {
    if (shapes.size() != 1)
      fail("--center, --radius, --tube-radius, --half-size, --sigma and --color apply to sphere, box and torus only");
    Shape& s = shapes[0];
    if (!o.center.empty()) s.center = parse_vec3(o.center, "--center");
    if (!o.color.empty()) s.color = parse_vec3(o.color, "--color");
    if (o.sigma_opt->count()) s.sigma = o.sigma;
    if (!o.half_size.empty()) {
      if (s.kind != ShapeKind::Box) fail("--half-size applies to the box scene only");
      s.half_size = parse_vec3(o.half_size, "--half-size");
    }
    if (o.radius_opt->count()) {
      if (s.kind == ShapeKind::Box) fail("--radius applies to the sphere and torus scenes only");
      s.radius = o.radius;
    }
    if (o.tube_opt->count()) {
      if (s.kind != ShapeKind::Torus) fail("--tube-radius applies to the torus scene only");
      s.tube_radius = o.tube_radius;
    }
    validate_shape(s, fmt::format("make-scene {} options", o.scene));
  }

  ProceduralOptions po;
  po.micro_res = o.res;
  po.feature_channels = o.channels;
  po.seed = o.seed;
  po.store_float = !o.quantized_only;
  const auto t0 = std::chrono::steady_clock::now();
  const SceneModel m = make_procedural_model(o.scene, shapes, po);
  const std::vector<uint8_t> bytes = serialize_model(m);
  write_file_atomic(o.output, bytes);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  fmt::print("{}: {} scene at micro resolution {}: {} occupied micro voxels, {} feature blocks, {} MLPs\n", o.output,
             o.scene, m.micro_res, m.occupancy[int(Tier::Micro)].count(), m.block_count(), m.mlp_count());
  fmt::print("  forms: {}; {} bytes; {:.2f} s\n", o.quantized_only ? "quantized" : "float and quantized", bytes.size(),
             seconds);
}

void register_make_scene_cmd(CLI::App& app) {
  auto o = std::make_shared<MakeSceneOptions>();
  CLI::App* cmd =
      app.add_subcommand("make-scene", "Write a procedural scene model (analytic solids) for tests and demos");
  cmd->add_option("scene", o->scene, "sphere, box, torus or several")
      ->required()
      ->check(CLI::IsMember({"sphere", "box", "torus", "several"}));
  cmd->add_option("-o,--output", o->output, "the .edrnr file to write")->required();
  cmd->add_option("--res", o->res, "micro-grid resolution (a multiple of 32)")->capture_default_str();
  cmd->add_option("--channels", o->channels, "feature channels (at least 4)")->capture_default_str();
  cmd->add_option("--seed", o->seed, "0: unused feature channels are 0; else pseudo-random values the MLPs ignore")
      ->capture_default_str();
  cmd->add_flag("--quantized-only", o->quantized_only, "store only the INT4 features and INT8 MLPs");
  cmd->add_option("--center", o->center, "single-shape scenes: centre X,Y,Z");
  o->radius_opt = cmd->add_option("--radius", o->radius, "sphere radius, or torus ring radius");
  o->tube_opt = cmd->add_option("--tube-radius", o->tube_radius, "torus tube radius");
  cmd->add_option("--half-size", o->half_size, "box half extents X,Y,Z");
  o->sigma_opt = cmd->add_option("--sigma", o->sigma, "density inside the shape, per scene unit");
  cmd->add_option("--color", o->color, "linear RGB colour R,G,B in [0, 1]");
  cmd->callback([o] { run_make_scene(*o); });
}

Registrar reg{20, register_make_scene_cmd};

}  // namespace
}  // namespace edrnr::cli
