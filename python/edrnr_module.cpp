// The Python module `edrnr`: models, cameras, the cycle simulator with a chip
// preset given as a name, a file or a dict, every renderer, and step(config)
// for search loops (docs/sweeps.md, "Python"). Errors are raised as
// ValueError with edrnr's message. Images are NumPy float32 arrays of shape
// (height, width, 3), linear RGB in [0, 1].
#include <fmt/format.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "chip/chip.h"
#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"
#include "data/dataset.h"
#include "model/model_io.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "render/fast.h"
#include "render/options.h"
#include "render/reference.h"
#include "sim/reproduce_runs.h"
#include "sim/simulator.h"
#include "sweep/evaluate.h"
#include "sweep/plan.h"

namespace py = pybind11;
namespace fs = std::filesystem;

namespace edrnr::python {
namespace {

struct Model {
  std::shared_ptr<const SceneModel> model;
  std::string source;
};

struct View {
  Camera camera;
  Image ground_truth;  // empty without a dataset
};

fs::path configs_dir(const char* kind) {
  if (const char* env = std::getenv("EDRNR_CONFIGS")) return fs::path(env) / kind;
  return fs::path(EDRNR_SOURCE_DIR) / "configs" / kind;
}

py::object json_to_py(const nlohmann::json& j) { return py::module_::import("json").attr("loads")(j.dump()); }
py::object json_to_py(const nlohmann::ordered_json& j) { return py::module_::import("json").attr("loads")(j.dump()); }

YAML::Node py_to_yaml(const py::handle& o) {
  // JSON is YAML: the dict goes through its JSON text.
  return YAML::Load(py::module_::import("json").attr("dumps")(o).cast<std::string>());
}

py::array_t<float> to_numpy(const Image& img) {
  py::array_t<float> a({img.height, img.width, img.channels});
  std::copy(img.data.begin(), img.data.end(), a.mutable_data());
  return a;
}

// A chip preset: a name in configs/chip, a YAML file, or a dict in the preset
// schema (nested maps); then `overrides`, dotted keys ("rp_rob.entries": 8).
sim::SimConfig resolve_preset(const py::object& preset, const py::object& overrides) {
  YAML::Node node;
  fs::path base_dir = configs_dir("chip");
  std::string where;
  if (py::isinstance<py::dict>(preset)) {
    node = py_to_yaml(preset);
    where = "preset dict";
  } else {
    const std::string name = py::str(preset);
    fs::path path = name;
    std::error_code ec;
    if (!fs::is_regular_file(path, ec)) path = configs_dir("chip") / (name + ".yaml");
    if (!fs::is_regular_file(path, ec))
      fail("preset '{}': no such file, and no preset {}.yaml in {}", name, name, configs_dir("chip").string());
    try {
      node = YAML::Load(read_file_text(path));
    } catch (const YAML::Exception& e) {
      fail("{}: not valid YAML: {}", path.string(), e.what());
    }
    base_dir = path.parent_path();
    where = path.string();
  }
  if (!overrides.is_none()) {
    for (const auto& kv : overrides.cast<py::dict>()) {
      const std::string key = py::str(kv.first);
      sweep::set_key(node, key, py_to_yaml(kv.second));
    }
    where += " with overrides";
  }
  return sim::sim_config_from_yaml(node, where, base_dir, {configs_dir("dram")});
}

RenderSettings settings_from(const py::kwargs& kw, const ChipConfig& defaults) {
  RenderSettings s;
  s.step_micro = defaults.step_micro;
  s.transmittance_min = defaults.transmittance_min;
  for (int c = 0; c < 3; ++c) s.background[c] = defaults.background[c];
  // fast_transmittance_min sets both fast paths' ray end (as the CLI's
  // --fast-transmittance), fast_int8_transmittance_min then the INT8 path's.
  std::optional<float> both, int8;
  for (const auto& kv : kw) {
    const std::string k = py::str(kv.first);
    if (k == "step_micro")
      s.step_micro = kv.second.cast<float>();
    else if (k == "transmittance_min")
      s.transmittance_min = kv.second.cast<float>();
    else if (k == "fast_transmittance_min")
      both = kv.second.cast<float>();
    else if (k == "fast_int8_transmittance_min")
      int8 = kv.second.cast<float>();
    else if (k == "background") {
      const auto b = kv.second.cast<std::vector<float>>();
      if (b.size() != 3) fail("background: expected 3 values (R, G, B), got {}", b.size());
      for (int c = 0; c < 3; ++c) s.background[c] = b[size_t(c)];
    } else if (k == "form")
      s.form = parse_model_form(kv.second.cast<std::string>(), "form");
    else if (k == "threads")
      s.threads = kv.second.cast<int>();
    else
      fail(
          "render: unknown option '{}' (known: step_micro, transmittance_min, fast_transmittance_min, "
          "fast_int8_transmittance_min, background, form, threads)",
          k);
  }
  if (both) s.fast_transmittance_min = s.fast_int8_transmittance_min = *both;
  if (int8) s.fast_int8_transmittance_min = *int8;
  return s;
}

struct Engine {
  const char* name;
  Image (*render)(const SceneModel&, const Camera&, const RenderSettings&, RenderStats*);
};
const Engine kEngines[] = {
    {"reference", render_reference},
    {"chip", render_chip_engine},
    {"fast", render_fast},
    {"fast-float", render_fast_float},
};

py::dict summary_dict(const sim::SimSummary& s) {
  py::dict d;
  d["cycles"] = s.cycles;
  d["clock_MHz"] = s.clock_MHz;
  d["frame_time_s"] = s.frame_time_s;
  d["fps"] = s.fps;
  d["pixels"] = s.pixels;
  d["samples"] = s.samples;
  d["samples_per_cycle"] = s.samples_per_cycle;
  d["micro_grid_hit_rate"] = s.micro_grid_hit_rate;
  d["feature_hit_rate"] = s.feature_hit_rate;
  d["mlp_hit_rate"] = s.mlp_hit_rate;
  d["dram_read_bytes"] = s.dram_read_bytes;
  d["dram_write_bytes"] = s.dram_write_bytes;
  return d;
}

// Statistics as {name: value}; a distribution as {count, mean, p50, ...}.
py::dict stats_dict(const StatsRegistry& stats) {
  py::dict d;
  const nlohmann::json j = stats.to_json();
  for (const auto& [name, e] : j.items()) {
    if (e.contains("value"))
      d[py::str(name)] = json_to_py(e["value"]);
    else {
      nlohmann::json x = e;
      x.erase("unit");
      x.erase("description");
      d[py::str(name)] = json_to_py(x);
    }
  }
  return d;
}

py::dict simulate(const Model& m, const View& v, const py::object& preset, const py::object& overrides, int threads,
                  bool allow_over_budget) {
  const sim::SimConfig cfg = resolve_preset(preset, overrides);
  const sim::SramBudget budget = sim::sram_budget_for(*m.model, cfg);
  if (budget.over_budget() && !allow_over_budget) {
    std::string why;
    for (const std::string& x : budget.violations()) why += "; " + x;
    fail("the preset does not fit Table I's on-chip SRAM{} (allow_over_budget=True simulates it anyway)", why);
  }
  sim::SimOptions o;
  o.threads = threads;
  sim::SimResult r;
  {
    py::gil_scoped_release release;
    r = sim::simulate_chip(*m.model, v.camera, cfg, o);
  }
  py::dict d;
  d["summary"] = summary_dict(r.summary);
  d["stats"] = stats_dict(*r.stats);
  d["image"] = to_numpy(r.image);
  d["sram_budget"] = json_to_py(r.sram_budget.to_json());
  d["energy"] = r.energy ? json_to_py(sim::energy_report_json(*r.energy)) : py::object(py::none());
  d["config_hash"] = sim::config_hash(cfg);
  return d;
}

py::dict step(const py::dict& config, const Model& m, const View& v, const py::object& base, bool allow_over_budget,
              bool psnr) {
  std::optional<sim::SimConfig> cfg;
  std::string error;
  try {
    cfg = resolve_preset(base, config);
  } catch (const Error& e) {
    error = e.what();
  }
  sweep::Row row;
  sweep::EvalInput in;
  in.config = cfg ? &*cfg : nullptr;
  in.config_error = error;
  in.model = m.model.get();
  in.camera = &v.camera;
  in.ground_truth = &v.ground_truth;
  in.allow_over_budget = allow_over_budget;
  Image reference;
  if (psnr)
    in.reference = [&]() -> const Image& {
      RenderSettings s;
      s.step_micro = cfg->chip.step_micro;
      s.transmittance_min = cfg->chip.transmittance_min;
      for (int c = 0; c < 3; ++c) s.background[c] = cfg->chip.background[c];
      s.form = sweep::float_form(*m.model) ? ModelForm::Float : ModelForm::Auto;
      reference = render_reference(*m.model, v.camera, s);
      return reference;
    };
  {
    py::gil_scoped_release release;
    sweep::evaluate_config(row, in);
  }
  sweep::Row out = row["metrics"];
  out["status"] = row["status"];
  out["error"] = row["error"];
  out["config_hash"] = cfg ? sweep::Row(sim::config_hash(*cfg)) : sweep::Row(nullptr);
  return json_to_py(out).cast<py::dict>();
}

}  // namespace
}  // namespace edrnr::python

PYBIND11_MODULE(edrnr, m) {
  using namespace edrnr;
  using namespace edrnr::python;
  m.doc() =
      "EDR-NR, an edge coprocessor for neural rendering, in software: models, cameras, the cycle simulator "
      "(simulate, step) and the renderers (render). See docs/sweeps.md.";
  m.attr("__version__") = "0.1.0";
  py::register_exception<Error>(m, "Error", PyExc_ValueError);

  py::class_<Model>(m, "Model", "A scene model (.edrnr): occupancy tiers, INT4 features, INT8 MLPs.")
      .def_property_readonly("source", [](const Model& x) { return x.source; })
      .def_property_readonly("micro_res", [](const Model& x) { return x.model->micro_res; })
      .def_property_readonly("feature_channels", [](const Model& x) { return x.model->feature_channels; })
      .def_property_readonly("blocks", [](const Model& x) { return x.model->block_count(); })
      .def_property_readonly("mlps", [](const Model& x) { return x.model->mlp_count(); })
      .def("__repr__", [](const Model& x) {
        return fmt::format("<edrnr.Model {} micro_res={} blocks={} mlps={}>", x.source, x.model->micro_res,
                           x.model->block_count(), x.model->mlp_count());
      });
  py::class_<View>(m, "Camera", "A pinhole camera, with the dataset's ground-truth image when it has one.")
      .def_property_readonly("width", [](const View& v) { return v.camera.width; })
      .def_property_readonly("height", [](const View& v) { return v.camera.height; })
      .def_property_readonly("ground_truth", [](const View& v) -> py::object {
        if (v.ground_truth.data.empty()) return py::none();
        return to_numpy(v.ground_truth);
      });

  m.def(
      "load_model",
      [](const std::string& path) {
        return Model{std::make_shared<const SceneModel>(load_model(path)), path};
      },
      py::arg("path"), "Loads a .edrnr model file (ValueError naming what is wrong with a bad file).");
  m.def(
      "make_scene",
      [](const std::string& name, int res, int channels, uint64_t seed) {
        if (res < 32 || res % 32 || res > kMaxMicroRes)
          fail("make_scene: res {} must be a multiple of 32 between 32 and {}", res, kMaxMicroRes);
        if (channels < 4 || channels > kMaxFeatureChannels)
          fail("make_scene: channels {} must be between 4 and {}", channels, kMaxFeatureChannels);
        ProceduralOptions o;
        o.micro_res = res;
        o.feature_channels = channels;
        o.seed = seed;
        return Model{std::make_shared<const SceneModel>(make_procedural_model(name, procedural_shapes(name), o)),
                     fmt::format("procedural {} res {}", name, res)};
      },
      py::arg("name") = "sphere", py::arg("res") = 64, py::arg("channels") = 8, py::arg("seed") = 0,
      "A procedural scene (sphere, box, torus or several), as edrnr make-scene writes it.");
  m.def(
      "orbit_camera",
      [](int width, int height, double azimuth, double elevation, double radius, double fov) {
        if (height <= 0) height = width;
        limits::check_image_size(width, height, "orbit_camera width/height");
        return View{orbit_camera(width, height, azimuth, elevation, radius, fov), Image()};
      },
      py::arg("width") = 64, py::arg("height") = 0, py::arg("azimuth") = 30.0, py::arg("elevation") = 30.0,
      py::arg("radius") = 4.0, py::arg("fov") = 40.0,
      "A camera on a circle around the scene, looking at its centre (angles in degrees).");
  m.def(
      "dataset_view",
      [](const std::string& root, int index, const std::string& split, int factor) {
        DatasetOptions d;
        d.split = split;
        d.load_images = false;
        d.downscale = factor;
        const Dataset ds = load_dataset(root, d);
        if (index < 0 || size_t(index) >= ds.frames.size())
          fail("dataset_view: index {}: the {} split of '{}' has views 0..{}", index, split, root,
               int(ds.frames.size()) - 1);
        const Frame& f = ds.frames[size_t(index)];
        return View{f.camera, downscale(composite_rgba(read_frame_rgba(f, factor), d.background), factor)};
      },
      py::arg("root"), py::arg("index") = 0, py::arg("split") = "test", py::arg("downscale") = 1,
      "A view of a NeRF dataset (transforms_<split>.json) with its ground truth on a white background.");
  m.def(
      "preset",
      [](const py::object& preset, const py::object& overrides) {
        const sim::SimConfig c = resolve_preset(preset, overrides);
        return json_to_py(sweep::yaml_to_json(sim::sim_config_to_yaml(c)));
      },
      py::arg("preset") = "edr_nr_40nm", py::arg("overrides") = py::none(),
      "The fully resolved chip config, as a dict (give it back to simulate as preset=).");
  m.def("simulate", &simulate, py::arg("model"), py::arg("camera"), py::arg("preset") = "edr_nr_40nm",
        py::arg("overrides") = py::none(), py::arg("threads") = 1, py::arg("allow_over_budget") = false,
        "Simulates one frame on the chip. preset: a name in configs/chip, a YAML file or a dict; overrides: "
        "{dotted key: value}. Returns {summary, stats, image, sram_budget, energy, config_hash}.");
  m.def(
      "render",
      [](const Model& model, const View& v, const std::string& engine, py::kwargs kw) {
        for (const Engine& e : kEngines)
          if (engine == e.name) {
            const RenderSettings s = settings_from(kw, ChipConfig{});
            Image img;
            {
              py::gil_scoped_release release;
              img = e.render(*model.model, v.camera, s, nullptr);
            }
            return to_numpy(img);
          }
        fail("render: unknown engine '{}' (known: reference, chip, fast, fast-float)", engine);
      },
      py::arg("model"), py::arg("camera"), py::arg("engine") = "reference",
      "Renders an image with an engine (reference, chip, fast, fast-float). Options: step_micro, "
      "transmittance_min, background, form ('auto', 'float', 'quantized'), threads.");
  m.def("engines", [] {
    std::vector<std::string> names;
    for (const Engine& e : kEngines) names.push_back(e.name);
    return names;
  });
  m.def("step", &step, py::arg("config"), py::arg("model"), py::arg("camera"), py::arg("base") = "edr_nr_40nm",
        py::arg("allow_over_budget") = false, py::arg("psnr") = true,
        "One design point: the base preset with config's dotted keys, simulated. Returns the sweep's metrics "
        "(fps, nJ_per_pixel, power_mW, sram_*_bytes, dram_*_bytes, hit rates, psnr_dB) with status ('ok' or "
        "'error'), error and config_hash; a bad config is a result with status 'error', not an exception.");
}
