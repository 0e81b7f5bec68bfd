#include "sweep/spec.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <optional>

#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"

namespace edrnr::sweep {

namespace {

// Where in SPEC a node is, for messages: "<file>:<line>".
struct Ctx {
  std::string file;
  std::string at(const YAML::Node& n) const {
    const int line = n.Mark().line;
    return line >= 0 ? fmt::format("{}:{}", file, line + 1) : file;
  }
};

int line_of(const YAML::Node& n) { return n.Mark().line >= 0 ? n.Mark().line + 1 : 0; }

const char* node_kind(const YAML::Node& n) {
  if (n.IsNull()) return "nothing";
  if (n.IsSequence()) return "a list";
  if (n.IsMap()) return "a map";
  return "a single value";
}

bool is_integer_text(const YAML::Node& n, int64_t* out = nullptr) {
  if (!n.IsScalar()) return false;
  try {
    const int64_t v = n.as<int64_t>();
    if (out) *out = v;
    return true;
  } catch (const YAML::Exception&) {
    return false;
  }
}

bool is_number_text(const YAML::Node& n, double* out = nullptr) {
  if (!n.IsScalar()) return false;
  try {
    const double v = n.as<double>();
    if (!std::isfinite(v)) return false;
    if (out) *out = v;
    return true;
  } catch (const YAML::Exception&) {
    return false;
  }
}

double number(const Ctx& c, const YAML::Node& n, const std::string& key) {
  double v = 0;
  if (!is_number_text(n, &v))
    fail("{}: {}: expected a finite number, got {}", c.at(n), key,
         n.IsScalar() ? "'" + n.Scalar() + "'" : node_kind(n));
  return v;
}

int64_t integer(const Ctx& c, const YAML::Node& n, const std::string& key, int64_t lo, int64_t hi) {
  int64_t v = 0;
  if (!is_integer_text(n, &v))
    fail("{}: {}: expected a whole number, got {}", c.at(n), key, n.IsScalar() ? "'" + n.Scalar() + "'" : node_kind(n));
  if (v < lo || v > hi) fail("{}: {}: {} is out of range [{}, {}]", c.at(n), key, v, lo, hi);
  return v;
}

std::string text(const Ctx& c, const YAML::Node& n, const std::string& key) {
  if (!n.IsScalar()) fail("{}: {}: expected a single value, got {}", c.at(n), key, node_kind(n));
  return n.Scalar();
}

bool boolean(const Ctx& c, const YAML::Node& n, const std::string& key) {
  try {
    if (n.IsScalar()) return n.as<bool>();
  } catch (const YAML::Exception&) {
  }
  fail("{}: {}: expected true or false, got {}", c.at(n), key, n.IsScalar() ? "'" + n.Scalar() + "'" : node_kind(n));
}

template <class F>
void for_each_key(const Ctx& c, const YAML::Node& node, const std::string& where,
                  std::initializer_list<const char*> known, F f) {
  if (!node.IsMap()) fail("{}: {}: expected a map, got {}", c.at(node), where, node_kind(node));
  for (const auto& kv : node) {
    const std::string key = kv.first.Scalar();
    if (std::none_of(known.begin(), known.end(), [&](const char* k) { return key == k; })) {
      std::string list;
      for (const char* k : known) list.append(list.empty() ? "" : ", ").append(k);
      fail("{}: {}: unknown key '{}' (known: {})", c.at(kv.first), where, key, list);
    }
    f(key, kv.second, where.empty() ? key : where + "." + key);
  }
}

// A number as a YAML scalar: whole numbers without a point, others in the
// shortest form that reads back to the same double.
YAML::Node number_node(double v, bool integral) {
  if (integral) return YAML::Node(int64_t(std::llround(v)));
  return YAML::Node(fmt::format("{}", v));
}

constexpr uint64_t kMaxDomainValues = 100000;

// A domain: a list, {from, to, step}, {from, to, factor}, or {from, to}.
Domain parse_domain(const Ctx& c, const YAML::Node& n, const std::string& key) {
  Domain d;
  if (n.IsSequence()) {
    if (n.size() == 0) fail("{}: vary.{}: the list is empty", c.at(n), key);
    if (n.size() > kMaxDomainValues)
      fail("{}: vary.{}: {} values, more than the limit of {}", c.at(n), key, n.size(), kMaxDomainValues);
    for (const YAML::Node& v : n) {
      if (!v.IsScalar() && !v.IsMap())
        fail("{}: vary.{}: a value must be a single value or a map, got {}", c.at(v), key, node_kind(v));
      d.values.push_back(YAML::Clone(v));
    }
    return d;
  }
  if (!n.IsMap())
    fail("{}: vary.{}: expected a list of values or a range {{from, to, step | factor}}, got {}", c.at(n), key,
         node_kind(n));
  std::optional<YAML::Node> from, to, step, factor, values;
  for_each_key(c, n, "vary." + key, {"from", "to", "step", "factor", "values"},
               [&](const std::string& k, const YAML::Node& v, const std::string&) {
                 if (k == "from") from = v;
                 if (k == "to") to = v;
                 if (k == "step") step = v;
                 if (k == "factor") factor = v;
                 if (k == "values") values = v;
               });
  const std::string where = "vary." + key;
  if (values) {
    if (from || to || step || factor)
      fail("{}: {}: 'values' cannot be combined with from/to/step/factor", c.at(n), where);
    if (!values->IsSequence()) fail("{}: {}.values: expected a list, got {}", c.at(*values), where, node_kind(*values));
    return parse_domain(c, *values, key);
  }
  if (!from || !to) fail("{}: {}: a range needs 'from' and 'to'", c.at(n), where);
  const double a = number(c, *from, where + ".from"), b = number(c, *to, where + ".to");
  if (b < a) fail("{}: {}: the range is empty ('to' {} is below 'from' {})", c.at(n), where, b, a);
  if (step && factor) fail("{}: {}: give 'step' or 'factor', not both", c.at(n), where);
  const bool ints = is_integer_text(*from) && is_integer_text(*to);
  if (step) {
    const double s = number(c, *step, where + ".step");
    if (!(s > 0)) fail("{}: {}.step: {} must be positive", c.at(*step), where, s);
    const double count = std::floor((b - a) / s + 1e-9) + 1;
    if (count > double(kMaxDomainValues))
      fail("{}: {}: {:.0f} values, more than the limit of {}", c.at(n), where, count, kMaxDomainValues);
    const bool integral = ints && is_integer_text(*step);
    for (uint64_t i = 0; i < uint64_t(count); ++i) d.values.push_back(number_node(a + double(i) * s, integral));
    return d;
  }
  if (factor) {
    const double f = number(c, *factor, where + ".factor");
    if (!(f > 1)) fail("{}: {}.factor: {} must be greater than 1", c.at(*factor), where, f);
    if (!(a > 0)) fail("{}: {}.from: {} must be positive with a factor", c.at(*from), where, a);
    const bool integral = ints && is_integer_text(*factor);
    for (double v = a; v <= b * (1 + 1e-12); v *= f) {
      if (d.values.size() >= kMaxDomainValues)
        fail("{}: {}: more values than the limit of {}", c.at(n), where, kMaxDomainValues);
      d.values.push_back(number_node(v, integral));
    }
    return d;
  }
  d.kind = Domain::Kind::Uniform;
  d.from = a;
  d.to = b;
  return d;
}

// A dotted key of the preset: words of letters, digits and '_' joined by '.'.
void check_key_syntax(const Ctx& c, const YAML::Node& at, const std::string& section, const std::string& key) {
  bool ok = !key.empty() && key.front() != '.' && key.back() != '.' && key.find("..") == std::string::npos;
  for (char ch : key) ok = ok && (std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '.');
  if (!ok)
    fail("{}: {}: '{}' is not a preset key (dotted words, e.g. rp_rob.entries or simulator.clock_MHz)", c.at(at),
         section, key);
}

ModelSpec parse_model(const Ctx& c, const YAML::Node& n, size_t index) {
  ModelSpec m;
  m.line = line_of(n);
  const std::string where = fmt::format("models[{}]", index);
  if (n.IsScalar()) {
    m.file = n.Scalar();
    if (m.file.empty()) fail("{}: {}: the file name is empty", c.at(n), where);
    return m;
  }
  for_each_key(c, n, where, {"file", "dataset", "procedural", "res", "channels", "seed"},
               [&](const std::string& k, const YAML::Node& v, const std::string& at) {
                 if (k == "file") m.file = text(c, v, at);
                 if (k == "dataset") m.dataset = text(c, v, at);
                 if (k == "procedural") m.procedural = text(c, v, at);
                 if (k == "res") m.res = int(integer(c, v, at, 32, 1024));
                 if (k == "channels") m.channels = int(integer(c, v, at, 4, 64));
                 if (k == "seed") m.seed = uint64_t(integer(c, v, at, 0, std::numeric_limits<int64_t>::max()));
               });
  if (m.file.empty() == m.procedural.empty())
    fail("{}: {}: give either 'file' or 'procedural' (sphere, box, torus, several)", c.at(n), where);
  if (!m.procedural.empty()) {
    static const char* kScenes[] = {"sphere", "box", "torus", "several"};
    if (std::none_of(std::begin(kScenes), std::end(kScenes), [&](const char* s) { return m.procedural == s; }))
      fail("{}: {}.procedural: unknown scene '{}' (known: sphere, box, torus, several)", c.at(n), where, m.procedural);
    if (m.res % 32) fail("{}: {}.res: {} must be a multiple of 32", c.at(n), where, m.res);
    if (!m.dataset.empty()) fail("{}: {}: a procedural model has no dataset", c.at(n), where);
  }
  return m;
}

void parse_views(const Ctx& c, const YAML::Node& n, ViewSpec& v) {
  for_each_key(c, n, "views", {"width", "height", "orbit", "elevation", "radius", "fov", "indices", "split"},
               [&](const std::string& k, const YAML::Node& x, const std::string& at) {
                 if (k == "width") v.width = int(integer(c, x, at, 1, limits::kMaxImageSide)), v.width_set = true;
                 if (k == "height") v.height = int(integer(c, x, at, 1, limits::kMaxImageSide)), v.height_set = true;
                 if (k == "elevation") v.elevation_deg = number(c, x, at);
                 if (k == "radius") v.radius = number(c, x, at);
                 if (k == "fov") v.fov_deg = number(c, x, at);
                 if (k == "split") v.split = text(c, x, at);
                 if (k == "orbit" || k == "indices") {
                   if (!x.IsSequence() && !x.IsScalar())
                     fail("{}: {}: expected a list, got {}", c.at(x), at, node_kind(x));
                   std::vector<YAML::Node> items;
                   if (x.IsScalar())
                     items.push_back(x);
                   else
                     for (const YAML::Node& i : x) items.push_back(i);
                   if (items.empty()) fail("{}: {}: the list is empty", c.at(x), at);
                   if (items.size() > kMaxSweepViews)
                     fail("{}: {}: {} views, more than the limit of {}", c.at(x), at, items.size(), kMaxSweepViews);
                   if (k == "orbit") {
                     v.orbit_azimuths_deg.clear();
                     for (const YAML::Node& i : items) v.orbit_azimuths_deg.push_back(number(c, i, at));
                   } else {
                     v.indices.clear();
                     for (const YAML::Node& i : items) v.indices.push_back(int(integer(c, i, at, 0, 1000000)));
                   }
                 }
               });
  if (!(v.radius > 0)) fail("{}: views.radius: {} must be positive", c.at(n), v.radius);
  if (!(v.fov_deg > 0 && v.fov_deg < 180)) fail("{}: views.fov: {} must be in (0, 180) degrees", c.at(n), v.fov_deg);
  const int h = v.height_set ? v.height : v.width;
  if (int64_t(v.width) * h > limits::kMaxImagePixels)
    fail("{}: views: {}x{} is more than the limit of {} pixels", c.at(n), v.width, h, limits::kMaxImagePixels);
}

}  // namespace

const char* combine_name(Combine c) {
  switch (c) {
    case Combine::Product:
      return "product";
    case Combine::Zip:
      return "zip";
    case Combine::Random:
      return "random";
  }
  return "?";
}

SweepSpec parse_sweep_spec(const std::string& spec_text, const std::filesystem::path& path) {
  const Ctx c{path.string()};
  YAML::Node root;
  try {
    root = YAML::Load(spec_text);
  } catch (const YAML::Exception& e) {
    fail("{}:{}: not valid YAML: {}", path.string(), e.mark.line + 1, e.msg);
  }
  if (!root.IsMap())
    fail("{}: a sweep SPEC is a YAML map (base, vary, models, views; docs/sweeps.md), but the file holds {}",
         path.string(), root.IsNull() ? "nothing" : node_kind(root));
  SweepSpec s;
  s.path = path;
  s.text = spec_text;
  bool has_samples = false, has_seed = false, has_models = false;
  std::optional<YAML::Node> vary_node;
  for_each_key(
      c, root, "",
      {"base", "combine", "samples", "seed", "set", "vary", "models", "views", "allow_over_budget", "include_base"},
      [&](const std::string& k, const YAML::Node& v, const std::string& at) {
        if (k == "base") s.base = text(c, v, at), s.base_line = line_of(v);
        if (k == "combine") {
          const std::string m = text(c, v, at);
          if (m == "product")
            s.combine = Combine::Product;
          else if (m == "zip")
            s.combine = Combine::Zip;
          else if (m == "random")
            s.combine = Combine::Random;
          else
            fail("{}: combine: unknown mode '{}' (known: product, zip, random)", c.at(v), m);
        }
        if (k == "samples") s.samples = uint64_t(integer(c, v, at, 1, int64_t(kMaxSweepPoints))), has_samples = true;
        if (k == "seed") s.seed = uint64_t(integer(c, v, at, 0, std::numeric_limits<int64_t>::max())), has_seed = true;
        if (k == "allow_over_budget") s.allow_over_budget = boolean(c, v, at);
        if (k == "include_base") s.include_base = boolean(c, v, at);
        if (k == "set") {
          if (!v.IsMap()) fail("{}: set: expected a map of preset keys, got {}", c.at(v), node_kind(v));
          for (const auto& kv : v) {
            const std::string key = kv.first.Scalar();
            check_key_syntax(c, kv.first, "set", key);
            s.fixed.push_back({key, YAML::Clone(kv.second), line_of(kv.first)});
          }
        }
        if (k == "vary") vary_node = v;
        if (k == "models") {
          has_models = true;
          if (!v.IsSequence() && !v.IsScalar() && !v.IsMap())
            fail("{}: models: expected a list, got {}", c.at(v), node_kind(v));
          if (v.IsSequence()) {
            if (v.size() == 0) fail("{}: models: the list is empty", c.at(v));
            if (v.size() > kMaxSweepModels)
              fail("{}: models: {} models, more than the limit of {}", c.at(v), v.size(), kMaxSweepModels);
            for (size_t i = 0; i < v.size(); ++i) s.models.push_back(parse_model(c, v[i], i));
          } else {
            s.models.push_back(parse_model(c, v, 0));
          }
        }
        if (k == "views") parse_views(c, v, s.views);
      });
  if (!has_models) fail("{}: no 'models': name at least one model (a file or {{procedural: sphere}})", path.string());
  if (vary_node) {
    if (!vary_node->IsMap())
      fail("{}: vary: expected a map of preset keys to values, got {}", c.at(*vary_node), node_kind(*vary_node));
    for (const auto& kv : *vary_node) {
      VariedKey vk;
      vk.key = kv.first.Scalar();
      vk.line = line_of(kv.first);
      check_key_syntax(c, kv.first, "vary", vk.key);
      for (const VariedKey& other : s.vary)
        if (other.key == vk.key) fail("{}: vary: '{}' is given twice (line {})", c.at(kv.first), vk.key, other.line);
      vk.domain = parse_domain(c, kv.second, vk.key);
      if (vk.domain.kind == Domain::Kind::Uniform && s.combine != Combine::Random)
        fail("{}: vary.{}: a range without 'step' or 'factor' is an interval, usable only with combine: random",
             c.at(kv.second), vk.key);
      s.vary.push_back(std::move(vk));
    }
  }
  for (const FixedKey& f : s.fixed)
    for (const VariedKey& v : s.vary)
      if (f.key == v.key) fail("{}:{}: set.{}: the key is also varied (line {})", path.string(), f.line, f.key, v.line);

  if (s.combine == Combine::Random) {
    if (!has_samples) fail("{}: combine: random needs 'samples' (how many points)", path.string());
    if (s.vary.empty()) fail("{}: combine: random needs keys under 'vary'", path.string());
  } else {
    if (has_samples || has_seed)
      fail("{}: 'samples' and 'seed' apply to combine: random only (combine is {})", path.string(),
           combine_name(s.combine));
    if (s.combine == Combine::Zip && !s.vary.empty()) {
      for (const VariedKey& v : s.vary)
        if (v.domain.values.size() != s.vary.front().domain.values.size())
          fail("{}:{}: vary.{}: combine: zip needs lists of one length, but it has {} values and {} (line {}) has {}",
               path.string(), v.line, v.key, v.domain.values.size(), s.vary.front().key, s.vary.front().line,
               s.vary.front().domain.values.size());
    }
    if (s.combine == Combine::Product) {
      double points = 1;
      for (const VariedKey& v : s.vary) points *= double(v.domain.values.size());
      if (points > double(kMaxSweepPoints))
        fail("{}: vary: the product has {:.0f} points, more than the limit of {} (use combine: random)", path.string(),
             points, kMaxSweepPoints);
    }
  }
  return s;
}

SweepSpec load_sweep_spec(const std::filesystem::path& path) { return parse_sweep_spec(read_file_text(path), path); }

}  // namespace edrnr::sweep
