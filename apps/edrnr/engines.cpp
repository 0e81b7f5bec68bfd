#include "engines.h"

#include <fmt/format.h>

#include <string>

#include "chip/chip.h"
#include "core/error.h"
#include "render/fast.h"
#include "render/reference.h"

namespace edrnr::cli {
namespace {

const Engine kEngines[] = {
    {"reference", "float volume rendering, the golden model", render_reference},
    {"chip", "bit-accurate EDR-NR chip model (configs/chip/default.yaml settings)", render_chip_engine},
    {"fast", "fast CPU renderer: INT8 path (the chip's arithmetic) on quantized models, float otherwise", render_fast},
    {"fast-float", "fast CPU renderer, float arithmetic (the reference's)", render_fast_float},
};

}  // namespace

const Engine& find_engine(const std::string& name) {
  std::string names;
  for (const Engine& e : kEngines) {
    if (name == e.name) return e;
    names += (names.empty() ? "" : ", ") + std::string(e.name);
  }
  fail("--engine '{}': unknown (available: {})", name, names);
}

void add_fast_transmittance_option(CLI::App* cmd, float* value) {
  const RenderSettings d;
  cmd->add_option(
         "--fast-transmittance", *value,
         fmt::format("fast engines: end rays below this transmittance (each pixel within it of the image with "
                     "the reference's samples; 0: those samples exactly); default {:g} on the float path, {:g} "
                     "on the INT8 path",
                     d.fast_transmittance_min, d.fast_int8_transmittance_min))
      ->check(CLI::Range(0.0, 1.0));
}

void apply_fast_transmittance(float value, RenderSettings& s) {
  if (value < 0.f) return;
  s.fast_transmittance_min = value;
  s.fast_int8_transmittance_min = value;
}

}  // namespace edrnr::cli
