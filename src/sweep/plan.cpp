#include "sweep/plan.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <cmath>
#include <map>
#include <set>
#include <sstream>

#include "core/error.h"
#include "core/file_io.h"
#include "data/dataset.h"
#include "model/model_io.h"
#include "model/procedural.h"
#include "render/cameras.h"
#include "sim/reproduce_runs.h"

namespace edrnr::sweep {

namespace fs = std::filesystem;

namespace {

std::string spec_at(const SweepSpec& s, int line) {
  return line > 0 ? fmt::format("{}:{}", s.path.string(), line) : s.path.string();
}

std::string yaml_text(const YAML::Node& n) {
  YAML::Emitter e;
  e.SetMapFormat(YAML::Flow);
  e.SetSeqFormat(YAML::Flow);
  e << n;
  return e.c_str();
}

// A file named in SPEC: beside SPEC, else from the working folder.
fs::path resolve_spec_file(const SweepSpec& s, const std::string& name, int line, const char* what) {
  const fs::path p(name);
  std::error_code ec;
  if (p.is_absolute()) {
    if (fs::exists(p, ec)) return p;
    fail("{}: {} '{}': no such file or folder", spec_at(s, line), what, name);
  }
  const fs::path beside = s.path.parent_path() / p;
  if (fs::exists(beside, ec)) return beside;
  if (fs::exists(p, ec)) return p;
  fail("{}: {} '{}': not found beside the SPEC ({}) nor in the working folder", spec_at(s, line), what, name,
       beside.string());
}

fs::path find_base_preset(const SweepSpec& s, const SearchDirs& dirs) {
  std::error_code ec;
  const bool looks_like_file = s.base.find('/') != std::string::npos || s.base.ends_with(".yaml");
  if (looks_like_file) return resolve_spec_file(s, s.base, s.base_line, "base");
  std::string searched;
  for (const fs::path& d : dirs.chip) {
    const fs::path p = d / (s.base + ".yaml");
    if (fs::is_regular_file(p, ec)) return p;
    searched += "\n  " + d.string();
  }
  fail("{}: base '{}': no chip preset {}.yaml in:{}", spec_at(s, s.base_line), s.base, s.base, searched);
}

// The node at a dotted path, or an undefined node.
YAML::Node find_key(const YAML::Node& root, const std::string& dotted) {
  YAML::Node n = YAML::Clone(root);
  size_t start = 0;
  for (;;) {
    const size_t dot = dotted.find('.', start);
    const std::string part = dotted.substr(start, dot == std::string::npos ? std::string::npos : dot - start);
    if (!n.IsMap() || !n[part]) return YAML::Node(YAML::NodeType::Undefined);
    n.reset(n[part]);
    if (dot == std::string::npos) return n;
    start = dot + 1;
  }
}

enum class ScalarKind { Bool, Number, Text };
ScalarKind scalar_kind(const YAML::Node& n) {
  const std::string& t = n.Scalar();
  if (t == "true" || t == "false") return ScalarKind::Bool;
  try {
    (void)n.as<double>();
    return ScalarKind::Number;
  } catch (const YAML::Exception&) {
    return ScalarKind::Text;
  }
}

// Checks that `key` is a key of the resolved preset and `value` has its type.
void check_key_and_value(const SweepSpec& s, const YAML::Node& resolved, const std::string& section,
                         const std::string& key, const YAML::Node& value, int line) {
  const YAML::Node target = find_key(resolved, key);
  if (!target.IsDefined()) {
    // Name the keys that do exist at the deepest level reached.
    std::string parent = key.find('.') == std::string::npos ? "" : key.substr(0, key.rfind('.'));
    YAML::Node at = parent.empty() ? YAML::Clone(resolved) : find_key(resolved, parent);
    while (!at.IsDefined() || !at.IsMap()) {
      parent = parent.find('.') == std::string::npos ? "" : parent.substr(0, parent.rfind('.'));
      at.reset(parent.empty() ? YAML::Clone(resolved) : find_key(resolved, parent));
    }
    std::string known;
    for (const auto& kv : at) known.append(known.empty() ? "" : ", ").append(kv.first.Scalar());
    fail("{}: {}.{}: the chip preset has no key '{}' (keys{}: {})", spec_at(s, line), section, key, key,
         parent.empty() ? " at the top" : " under " + parent, known);
  }
  if (!target.IsScalar()) return;  // a map or list (e.g. a DRAM part): any value, checked per point
  if (!value.IsScalar())
    fail("{}: {}.{}: expected a single value like the preset's '{}', got a {}", spec_at(s, line), section, key,
         target.Scalar(), value.IsMap() ? "map" : "list");
  const ScalarKind want = scalar_kind(target), got = scalar_kind(value);
  if (want == ScalarKind::Bool && got != ScalarKind::Bool)
    fail("{}: {}.{}: '{}' is not true or false", spec_at(s, line), section, key, value.Scalar());
  if (want == ScalarKind::Number && got != ScalarKind::Number)
    fail("{}: {}.{}: '{}' is not a number (the preset has {})", spec_at(s, line), section, key, value.Scalar(),
         target.Scalar());
}

YAML::Node number_node(double v) { return YAML::Node(fmt::format("{}", v)); }

// The points' values, in SPEC order, before resolution.
std::vector<std::vector<YAML::Node>> expand_points(const SweepSpec& s) {
  std::vector<std::vector<YAML::Node>> out;
  const size_t k = s.vary.size();
  if (k == 0) return {{}};
  if (s.combine == Combine::Zip) {
    for (size_t i = 0; i < s.vary[0].domain.values.size(); ++i) {
      std::vector<YAML::Node> p;
      for (const VariedKey& v : s.vary) p.push_back(v.domain.values[i]);
      out.push_back(std::move(p));
    }
    return out;
  }
  if (s.combine == Combine::Product) {
    size_t total = 1;
    for (const VariedKey& v : s.vary) total *= v.domain.values.size();
    for (size_t i = 0; i < total; ++i) {
      std::vector<YAML::Node> p(k);
      size_t rest = i;
      for (size_t j = k; j-- > 0;) {
        const size_t n = s.vary[j].domain.values.size();
        p[j].reset(s.vary[j].domain.values[rest % n]);
        rest /= n;
      }
      out.push_back(std::move(p));
    }
    return out;
  }
  // Random: distinct value sets, drawn key by key from one splitmix stream.
  std::set<std::string> seen;
  uint64_t draw = 0;
  const uint64_t max_draws = s.samples * 100 + 1000;
  while (out.size() < s.samples && draw < max_draws * k) {
    std::vector<YAML::Node> p;
    std::string signature;
    for (const VariedKey& v : s.vary) {
      const uint64_t u = splitmix64(s.seed, draw++);
      YAML::Node value;
      if (v.domain.kind == Domain::Kind::List) {
        value.reset(v.domain.values[u % v.domain.values.size()]);
      } else {
        const double f = double(u >> 11) * 0x1.0p-53;
        value.reset(number_node(v.domain.from + (v.domain.to - v.domain.from) * f));
      }
      signature += yaml_text(value) + "\n";
      p.push_back(value);
    }
    if (seen.insert(signature).second) out.push_back(std::move(p));
  }
  return out;
}

std::string camera_text(const Camera& c) {
  std::string s = fmt::format("{} {} {:.17g} {:.17g} {:.17g} {:.17g}", c.width, c.height, c.fx, c.fy, c.cx, c.cy);
  for (double v : c.c2w) s += fmt::format(" {:.17g}", v);
  return s;
}

SweepModel load_sweep_model(const SweepSpec& s, const ModelSpec& m) {
  SweepModel out;
  if (!m.procedural.empty()) {
    ProceduralOptions po;
    po.micro_res = m.res;
    po.feature_channels = m.channels;
    po.seed = m.seed;
    SceneModel model = make_procedural_model(m.procedural, procedural_shapes(m.procedural), po);
    const std::vector<uint8_t> bytes = serialize_model(model);
    out.name = m.procedural;
    out.source = fmt::format("procedural {} res {} channels {} seed {}", m.procedural, m.res, m.channels, m.seed);
    out.hash = sim::run_hash(bytes.data(), bytes.size());
    out.model = std::make_shared<const SceneModel>(std::move(model));
    return out;
  }
  const fs::path path = resolve_spec_file(s, m.file, m.line, "model");
  std::vector<uint8_t> bytes;
  SceneModel model;
  try {
    bytes = read_model_file(path);
    model = parse_model(bytes.data(), bytes.size(), path.string());
  } catch (const Error& e) {
    fail("{}: model '{}': {}", spec_at(s, m.line), m.file, e.what());
  }
  out.name = path.stem().string();
  out.source = m.file;
  out.hash = sim::run_hash(bytes.data(), bytes.size());
  out.model = std::make_shared<const SceneModel>(std::move(model));
  if (!m.dataset.empty()) out.dataset = resolve_spec_file(s, m.dataset, m.line, "dataset").string();
  return out;
}

std::vector<SweepView> make_views(const SweepSpec& s, const ModelSpec& ms, const SweepModel& m,
                                  const ChipConfig& chip) {
  const ViewSpec& v = s.views;
  std::vector<SweepView> out;
  if (m.dataset.empty()) {
    const int h = v.height_set ? v.height : v.width;
    for (double az : v.orbit_azimuths_deg)
      out.push_back(
          {fmt::format("orbit{:g}", az), orbit_camera(v.width, h, az, v.elevation_deg, v.radius, v.fov_deg), Image()});
    return out;
  }
  try {
    DatasetOptions d;
    d.split = v.split;
    d.load_images = false;
    const Dataset full = load_dataset(m.dataset, d);
    const Camera& c0 = full.frames.front().camera;
    // The ground truth scales down by whole factors only.
    int factor = 1;
    if (v.width_set) factor = v.width > 0 && c0.width % v.width == 0 ? c0.width / v.width : 0;
    if (v.height_set) {
      const int fh = v.height > 0 && c0.height % v.height == 0 ? c0.height / v.height : 0;
      if (v.width_set && fh != factor) factor = 0;
      if (!v.width_set) factor = fh;
    }
    if (factor < 1)
      fail("views: the dataset's {}x{} views scale down by whole factors only (e.g. {}x{})", c0.width, c0.height,
           c0.width / 2, c0.height / 2);
    d.downscale = factor;
    for (int i = 0; i < 3; ++i) d.background[i] = chip.background[i];
    const Dataset ds = load_dataset(m.dataset, d);
    for (int index : v.indices) {
      if (index < 0 || size_t(index) >= ds.frames.size())
        fail("views.indices: {} is not a view of the {} split (0..{})", index, v.split, int(ds.frames.size()) - 1);
      const Frame& f = ds.frames[size_t(index)];
      Image gt = downscale(composite_rgba(read_frame_rgba(f, factor), d.background), factor);
      out.push_back({fmt::format("{}/{}", v.split, index), f.camera, std::move(gt)});
    }
  } catch (const Error& e) {
    fail("{}: dataset '{}' of model '{}': {}", spec_at(s, ms.line), ms.dataset, ms.file, e.what());
  }
  return out;
}

}  // namespace

uint64_t splitmix64(uint64_t seed, uint64_t n) {
  uint64_t z = seed + (n + 1) * 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

void set_key(YAML::Node& node, const std::string& dotted, const YAML::Node& value) {
  std::vector<std::string> parts;
  size_t start = 0;
  for (;;) {
    const size_t dot = dotted.find('.', start);
    parts.push_back(dotted.substr(start, dot == std::string::npos ? std::string::npos : dot - start));
    if (dot == std::string::npos) break;
    start = dot + 1;
  }
  // Walk down with fresh handles (yaml-cpp's assignment to a handle would
  // overwrite the node it refers to).
  std::vector<YAML::Node> chain = {node};
  for (size_t i = 0; i + 1 < parts.size(); ++i) {
    YAML::Node parent = chain.back();
    if (!parent.IsMap() && !parent.IsNull())
      fail("{}: '{}' is a single value in the preset, not a map", dotted,
           fmt::join(parts.begin(), parts.begin() + long(i), "."));
    if (!parent[parts[i]] || parent[parts[i]].IsNull()) parent[parts[i]] = YAML::Node(YAML::NodeType::Map);
    if (!parent[parts[i]].IsMap())
      fail("{}: '{}' is a single value in the preset, not a map", dotted,
           fmt::join(parts.begin(), parts.begin() + long(i) + 1, "."));
    chain.push_back(parent[parts[i]]);
  }
  chain.back()[parts.back()] = YAML::Clone(value);
}

nlohmann::json yaml_to_json(const YAML::Node& n) {
  if (n.IsMap()) {
    nlohmann::json j = nlohmann::json::object();
    for (const auto& kv : n) j[kv.first.Scalar()] = yaml_to_json(kv.second);
    return j;
  }
  if (n.IsSequence()) {
    nlohmann::json j = nlohmann::json::array();
    for (const YAML::Node& x : n) j.push_back(yaml_to_json(x));
    return j;
  }
  if (!n.IsScalar()) return nullptr;
  const std::string& t = n.Scalar();
  if (t == "true") return true;
  if (t == "false") return false;
  try {
    size_t used = 0;
    const long long v = std::stoll(t, &used);
    if (used == t.size()) return v;
  } catch (const std::exception&) {
  }
  try {
    size_t used = 0;
    const double v = std::stod(t, &used);
    if (used == t.size() && std::isfinite(v)) return v;
  } catch (const std::exception&) {
  }
  return t;
}

std::string plan_hash(const SweepPlan& plan) {
  std::string text;
  for (const Job& j : plan.jobs) text += j.key + "\n";
  return sim::run_hash(text.data(), text.size());
}

SweepPlan make_plan(const SweepSpec& spec, const SearchDirs& dirs) {
  SweepPlan plan;
  plan.spec = spec;
  plan.base_preset = find_base_preset(spec, dirs);
  const std::string base_text = read_file_text(plan.base_preset);
  try {
    plan.base_yaml = YAML::Load(base_text);
  } catch (const YAML::Exception& e) {
    fail("{}: base preset {}: not valid YAML: {}", spec_at(spec, spec.base_line), plan.base_preset.string(), e.what());
  }
  const fs::path base_dir = plan.base_preset.parent_path();
  const std::string base_where = plan.base_preset.string();
  sim::SimConfig raw;
  try {
    raw = sim::sim_config_from_yaml(plan.base_yaml, base_where, base_dir, dirs.dram);
  } catch (const Error& e) {
    fail("{}: base preset: {}", spec_at(spec, spec.base_line), e.what());
  }
  const YAML::Node resolved = sim::sim_config_to_yaml(raw);

  // The fixed keys, checked and applied to the base.
  YAML::Node fixed_yaml = YAML::Clone(plan.base_yaml);
  for (const FixedKey& f : spec.fixed) {
    check_key_and_value(spec, resolved, "set", f.key, f.value, f.line);
    try {
      set_key(fixed_yaml, f.key, f.value);
    } catch (const Error& e) {
      fail("{}: set.{}", spec_at(spec, f.line), e.what());
    }
  }
  try {
    plan.base_config = sim::sim_config_from_yaml(fixed_yaml, base_where + " with SPEC's set", base_dir, dirs.dram);
  } catch (const Error& e) {
    fail("{}: set: {}", spec.path.string(), e.what());
  }
  for (const VariedKey& v : spec.vary) {
    plan.varied.push_back(v.key);
    for (const YAML::Node& value : v.domain.values) check_key_and_value(spec, resolved, "vary", v.key, value, v.line);
    if (v.domain.kind == Domain::Kind::Uniform)
      check_key_and_value(spec, resolved, "vary", v.key, number_node(v.domain.from), v.line);
  }

  // Points, each resolved; a later point with the same config as an earlier
  // one is a duplicate and dropped.
  plan.base_config_hash = sim::config_hash(plan.base_config);
  std::vector<std::vector<YAML::Node>> all_values = expand_points(spec);
  const size_t expanded = all_values.size();
  if (spec.include_base && !spec.vary.empty()) {
    const YAML::Node base_resolved = sim::sim_config_to_yaml(plan.base_config);
    std::vector<YAML::Node> values;
    for (const VariedKey& v : spec.vary) values.push_back(find_key(base_resolved, v.key));
    all_values.push_back(std::move(values));
  }
  std::set<std::string> seen;
  for (size_t n = 0; n < all_values.size(); ++n) {
    std::vector<YAML::Node>& values = all_values[n];
    Point p;
    p.values = std::move(values);
    YAML::Node y = YAML::Clone(fixed_yaml);
    std::string signature;
    for (size_t i = 0; i < spec.vary.size(); ++i) signature += spec.vary[i].key + "=" + yaml_text(p.values[i]) + "\n";
    try {
      for (size_t i = 0; i < spec.vary.size(); ++i) set_key(y, spec.vary[i].key, p.values[i]);
      p.config = sim::sim_config_from_yaml(y, "point", base_dir, dirs.dram);
      std::ostringstream text;
      text << sim::sim_config_to_yaml(*p.config);
      p.config_yaml = text.str();
      p.config_hash = sim::config_hash(*p.config);
    } catch (const Error& e) {
      p.config.reset();
      p.config_error = e.what();
      const std::string text = "invalid\n" + base_text + "\n" + signature;
      p.config_hash = sim::run_hash(text.data(), text.size());
    }
    if (!seen.insert(p.config_hash).second) {
      if (n < expanded) ++plan.duplicate_points;
      continue;
    }
    p.index = plan.points.size();
    if (p.config_hash == plan.base_config_hash) plan.base_point = p.index;
    plan.points.push_back(std::move(p));
  }

  for (const ModelSpec& m : spec.models) {
    plan.models.push_back(load_sweep_model(spec, m));
    plan.views.push_back(make_views(spec, m, plan.models.back(), plan.base_config.chip));
  }
  for (const Point& p : plan.points)
    for (size_t m = 0; m < plan.models.size(); ++m)
      for (size_t v = 0; v < plan.views[m].size(); ++v) {
        const std::string text = "edrnr-sweep-job-1\nconfig " + p.config_hash + "\nmodel " + plan.models[m].hash +
                                 "\nview " + plan.views[m][v].name + " " + camera_text(plan.views[m][v].camera);
        plan.jobs.push_back({p.index, m, v, sim::run_hash(text.data(), text.size())});
      }
  return plan;
}

}  // namespace edrnr::sweep
