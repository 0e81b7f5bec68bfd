#include "model/procedural.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "model/mlp.h"

namespace edrnr {
namespace {

bool finite3(const Vec3f& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

// Distance from x to the interval [lo, hi] (0 inside).
float interval_gap(float x, float lo, float hi) {
  if (x < lo) return lo - x;
  if (x > hi) return x - hi;
  return 0.f;
}

// Deterministic hash to a float in [-1, 1) (splitmix64 finalizer).
float hash_to_unit(uint64_t seed, uint64_t index) {
  uint64_t z = seed * 0x9E3779B97F4A7C15ull + index + 0x632BE59BD9B4E019ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return float(z >> 40) * (1.f / 16777216.f) * 2.f - 1.f;
}

// A net of zero weights and biases with the given widths.
std::vector<DenseF> zero_net(const std::vector<int>& widths) {
  std::vector<DenseF> net;
  for (size_t l = 1; l < widths.size(); ++l) {
    DenseF d;
    d.in = widths[l - 1];
    d.out = widths[l];
    d.w.assign(size_t(d.in) * size_t(d.out), 0.f);
    d.b.assign(size_t(d.out), 0.f);
    net.push_back(std::move(d));
  }
  return net;
}

// Sets the weights of `net` so that output i equals input inputs[i]: the first
// hidden layer holds relu(x) and relu(-x) for each passed input, further
// hidden layers copy those units, the output layer subtracts the pair.
void make_pass_through(std::vector<DenseF>& net, const std::vector<int>& inputs, const char* what) {
  const int n = int(inputs.size());
  auto w = [](DenseF& d, int o, int i) -> float& { return d.w[size_t(o) * size_t(d.in) + size_t(i)]; };
  if (net.back().out < n) fail("{} net has {} outputs, the procedural model needs {}", what, net.back().out, n);
  if (net.size() == 1) {
    for (int i = 0; i < n; ++i) w(net[0], i, inputs[size_t(i)]) = 1.f;
    return;
  }
  for (size_t l = 0; l + 1 < net.size(); ++l)
    if (net[l].out < 2 * n)
      fail("{} net hidden layer {} has {} neurons, the procedural model needs {}", what, l, net[l].out, 2 * n);
  for (int i = 0; i < n; ++i) {
    w(net[0], 2 * i, inputs[size_t(i)]) = 1.f;
    w(net[0], 2 * i + 1, inputs[size_t(i)]) = -1.f;
  }
  for (size_t l = 1; l + 1 < net.size(); ++l)
    for (int u = 0; u < 2 * n; ++u) w(net[l], u, u) = 1.f;
  DenseF& last = net.back();
  for (int i = 0; i < n; ++i) {
    w(last, i, 2 * i) = 1.f;
    w(last, i, 2 * i + 1) = -1.f;
  }
}

// INT8 form of a net whose weights are all in {-1, 0, 1}: w_q = 64 w with
// scale 1/64, exact. in_scales[l] is the quantization step of layer l's input.
std::vector<DenseQ> quantize_unit_net(const std::vector<DenseF>& net, const std::vector<float>& in_scales) {
  std::vector<DenseQ> q;
  for (size_t l = 0; l < net.size(); ++l) {
    const DenseF& f = net[l];
    DenseQ d;
    d.in = f.in;
    d.out = f.out;
    d.w.resize(f.w.size());
    for (size_t k = 0; k < f.w.size(); ++k) d.w[k] = int8_t(std::lround(f.w[k] * 64.f));
    d.w_scale.assign(size_t(f.out), 1.f / 64.f);
    d.b = f.b;
    d.in_scale = in_scales[l];
    q.push_back(std::move(d));
  }
  return q;
}

double json_num(float v) { return std::strtod(fmt::format("{}", v).c_str(), nullptr); }
nlohmann::json json_vec(const Vec3f& v) { return {json_num(v.x), json_num(v.y), json_num(v.z)}; }

nlohmann::json shape_json(const Shape& s) {
  nlohmann::json j;
  j["kind"] = shape_kind_name(s.kind);
  j["center"] = json_vec(s.center);
  switch (s.kind) {
    case ShapeKind::Sphere:
      j["radius"] = json_num(s.radius);
      break;
    case ShapeKind::Box:
      j["half_size"] = json_vec(s.half_size);
      break;
    case ShapeKind::Torus:
      j["radius"] = json_num(s.radius);
      j["tube_radius"] = json_num(s.tube_radius);
      break;
  }
  j["sigma"] = json_num(s.sigma);
  j["color"] = json_vec(s.color);
  return j;
}

}  // namespace

const char* shape_kind_name(ShapeKind kind) {
  switch (kind) {
    case ShapeKind::Sphere:
      return "sphere";
    case ShapeKind::Box:
      return "box";
    case ShapeKind::Torus:
      return "torus";
  }
  return "?";
}

float shape_distance(const Shape& s, const Vec3f& p) {
  const Vec3f d = p - s.center;
  switch (s.kind) {
    case ShapeKind::Sphere:
      return length(d) - s.radius;
    case ShapeKind::Box: {
      const Vec3f q{std::abs(d.x) - s.half_size.x, std::abs(d.y) - s.half_size.y, std::abs(d.z) - s.half_size.z};
      const float outside = length(vmax(q, Vec3f{0.f, 0.f, 0.f}));
      const float inside = std::min(std::max(q.x, std::max(q.y, q.z)), 0.f);
      return outside + inside;
    }
    case ShapeKind::Torus: {
      const float rho = std::sqrt(d.x * d.x + d.y * d.y);
      const float a = rho - s.radius;
      return std::sqrt(a * a + d.z * d.z) - s.tube_radius;
    }
  }
  return INFINITY;
}

bool shape_overlaps_box(const Shape& s, const Box3f& box) {
  const Vec3f c = s.center;
  switch (s.kind) {
    case ShapeKind::Sphere: {
      float d2 = 0.f;
      for (int a = 0; a < 3; ++a) {
        const float g = interval_gap(c[a], box.lo[a], box.hi[a]);
        d2 += g * g;
      }
      return d2 <= s.radius * s.radius;
    }
    case ShapeKind::Box:
      for (int a = 0; a < 3; ++a)
        if (c[a] + s.half_size[a] < box.lo[a] || c[a] - s.half_size[a] > box.hi[a]) return false;
      return true;
    case ShapeKind::Torus: {
      // The squared distance to the ring circle separates into a radial part
      // (x, y only) and an axial part (z only). Over the box's xy rectangle
      // the radial distance rho covers [rho_min, rho_max] continuously.
      const float gx = interval_gap(c.x, box.lo.x, box.hi.x), gy = interval_gap(c.y, box.lo.y, box.hi.y);
      const float rho_min = std::sqrt(gx * gx + gy * gy);
      const float fx = std::max(std::abs(box.lo.x - c.x), std::abs(box.hi.x - c.x));
      const float fy = std::max(std::abs(box.lo.y - c.y), std::abs(box.hi.y - c.y));
      const float rho_max = std::sqrt(fx * fx + fy * fy);
      const float dr = interval_gap(s.radius, rho_min, rho_max);
      const float dz = interval_gap(c.z, box.lo.z, box.hi.z);
      return dr * dr + dz * dz <= s.tube_radius * s.tube_radius;
    }
  }
  return false;
}

Box3f shape_bounds(const Shape& s) {
  Vec3f h;
  switch (s.kind) {
    case ShapeKind::Sphere:
      h = {s.radius, s.radius, s.radius};
      break;
    case ShapeKind::Box:
      h = s.half_size;
      break;
    case ShapeKind::Torus: {
      const float r = s.radius + s.tube_radius;
      h = {r, r, s.tube_radius};
      break;
    }
  }
  return {s.center - h, s.center + h};
}

void validate_shape(const Shape& s, const std::string& what) {
  if (!finite3(s.center)) fail("{}: center is not finite", what);
  if (s.kind == ShapeKind::Sphere || s.kind == ShapeKind::Torus)
    if (!(s.radius > 0.f && std::isfinite(s.radius))) fail("{}: radius {} must be positive", what, s.radius);
  if (s.kind == ShapeKind::Torus && !(s.tube_radius > 0.f && std::isfinite(s.tube_radius)))
    fail("{}: tube radius {} must be positive", what, s.tube_radius);
  if (s.kind == ShapeKind::Box)
    for (int a = 0; a < 3; ++a)
      if (!(s.half_size[a] > 0.f && std::isfinite(s.half_size[a])))
        fail("{}: half size {} must be positive on every axis", what, s.half_size[a]);
  if (!(s.sigma >= kMinShapeSigma && s.sigma <= kMaxShapeSigma))
    fail("{}: sigma {} is outside [{}, {}]", what, s.sigma, kMinShapeSigma, kMaxShapeSigma);
  for (int a = 0; a < 3; ++a)
    if (!(s.color[a] >= 0.f && s.color[a] <= 1.f)) fail("{}: colour component {} is outside [0, 1]", what, s.color[a]);
}

FieldSample procedural_field(const std::vector<Shape>& shapes, const Vec3f& p) {
  FieldSample f;
  if (shapes.empty()) return f;
  size_t owner = 0;
  float best = shape_distance(shapes[0], p);
  for (size_t i = 1; i < shapes.size(); ++i) {
    const float d = shape_distance(shapes[i], p);
    if (d < best) {
      best = d;
      owner = i;
    }
  }
  f.sigma = best <= 0.f ? shapes[owner].sigma : 0.f;
  f.color = shapes[owner].color;
  return f;
}

std::vector<std::string> procedural_scene_names() { return {"sphere", "box", "torus", "several"}; }

std::vector<Shape> procedural_shapes(const std::string& scene) {
  if (scene == "sphere") return {Shape{}};
  if (scene == "box") {
    Shape s;
    s.kind = ShapeKind::Box;
    s.half_size = {0.7f, 0.7f, 0.7f};
    s.color = {0.2f, 0.5f, 0.8f};
    return {s};
  }
  if (scene == "torus") {
    Shape s;
    s.kind = ShapeKind::Torus;
    s.radius = 0.9f;
    s.tube_radius = 0.3f;
    s.color = {0.3f, 0.75f, 0.35f};
    return {s};
  }
  if (scene == "several") {
    Shape red;  // dense sphere
    red.center = {-0.6f, -0.6f, 0.2f};
    red.radius = 0.45f;
    red.sigma = 30.f;
    red.color = {0.85f, 0.2f, 0.15f};
    Shape blue;  // upright box
    blue.kind = ShapeKind::Box;
    blue.center = {0.6f, -0.5f, -0.3f};
    blue.half_size = {0.35f, 0.35f, 0.5f};
    blue.sigma = 10.f;
    blue.color = {0.15f, 0.35f, 0.85f};
    Shape green;  // thin, very dense ring
    green.kind = ShapeKind::Torus;
    green.center = {0.1f, 0.6f, 0.f};
    green.radius = 0.5f;
    green.tube_radius = 0.15f;
    green.sigma = 50.f;
    green.color = {0.2f, 0.75f, 0.25f};
    Shape yellow;  // translucent sphere: optical depth about 1.8 through its centre
    yellow.center = {-0.2f, -0.1f, -0.9f};
    yellow.radius = 0.3f;
    yellow.sigma = 3.f;
    yellow.color = {0.9f, 0.8f, 0.2f};
    return {red, blue, green, yellow};
  }
  fail("unknown procedural scene '{}' (expected sphere, box, torus or several)", scene);
}

SceneModel make_procedural_model(const std::string& scene_name, const std::vector<Shape>& shapes,
                                 const ProceduralOptions& options) {
  if (options.feature_channels < 4)
    fail("procedural model needs at least 4 feature channels, got {}", options.feature_channels);
  for (size_t i = 0; i < shapes.size(); ++i) validate_shape(shapes[i], fmt::format("shape {}", i));

  SceneModel m;
  m.scene_box = options.scene_box;
  m.micro_res = options.micro_res;
  m.feature_channels = options.feature_channels;
  m.mlp_arch = default_mlp_arch(options.feature_channels);
  m.init_grids();

  // Micro occupancy: voxels that overlap a shape.
  const int R = m.micro_res;
  const Vec3f lo = m.scene_box.lo;
  const Vec3f vs = m.micro_voxel_size();
  Bitmap3& micro = m.occupancy[int(Tier::Micro)];
  Vec3i occ_lo{R, R, R}, occ_hi{-1, -1, -1};
  for (const Shape& s : shapes) {
    const Box3f b = shape_bounds(s);
    Vec3i i0, i1;
    bool empty = false;
    for (int a = 0; a < 3; ++a) {
      const float f0 = std::floor((b.lo[a] - lo[a]) / vs[a]), f1 = std::floor((b.hi[a] - lo[a]) / vs[a]);
      if (f1 < 0.f || f0 > float(R - 1)) empty = true;
      i0[a] = int(std::clamp(f0, 0.f, float(R - 1)));
      i1[a] = int(std::clamp(f1, 0.f, float(R - 1)));
    }
    if (empty) continue;
    for (int z = i0.z; z <= i1.z; ++z)
      for (int y = i0.y; y <= i1.y; ++y)
        for (int x = i0.x; x <= i1.x; ++x) {
          const Vec3f v0 = lo + vs * Vec3f{float(x), float(y), float(z)};
          const Vec3f v1 = lo + vs * Vec3f{float(x + 1), float(y + 1), float(z + 1)};
          if (!shape_overlaps_box(s, Box3f{v0, v1})) continue;
          micro.set(x, y, z);
          occ_lo = vmin(occ_lo, Vec3i{x, y, z});
          occ_hi = vmax(occ_hi, Vec3i{x, y, z});
        }
  }
  if (occ_hi.x < 0) {  // nothing occupied: a zero-size AABB at the box centre
    const Vec3f c = (m.scene_box.lo + m.scene_box.hi) * 0.5f;
    m.object_aabb = {c, c};
  } else {
    m.object_aabb = {lo + vs * occ_lo.cast<float>(), lo + vs * (occ_hi + Vec3i{1, 1, 1}).cast<float>()};
  }
  m.rebuild_upper_tiers();

  // One block per occupied fine voxel: the field at its 5^3 lattice vertices.
  const Bitmap3& fine = m.occupancy[int(Tier::Fine)];
  const int fr = m.fine_res();
  for (size_t i = 0; i < fine.size(); ++i)
    if (fine.get(i)) m.block_fine_index.push_back(uint32_t(i));
  const int F = m.feature_channels;
  const size_t nblocks = m.block_fine_index.size();
  m.features_f32.assign(nblocks * kBlockVerts * size_t(F), 0.f);
#pragma omp parallel for schedule(static)
  for (size_t b = 0; b < nblocks; ++b) {
    const uint32_t fi = m.block_fine_index[b];
    const int fx = int(fi % uint32_t(fr)), fy = int((fi / uint32_t(fr)) % uint32_t(fr)),
              fz = int(fi / uint32_t(fr * fr));
    for (int v = 0; v < kBlockVerts; ++v) {
      const int i = v % 5, j = (v / 5) % 5, k = v / 25;
      const Vec3i g{kMicroPerFine * fx + i, kMicroPerFine * fy + j, kMicroPerFine * fz + k};
      const FieldSample f = procedural_field(shapes, lo + vs * g.cast<float>());
      float* out = &m.features_f32[(b * kBlockVerts + size_t(v)) * size_t(F)];
      out[0] = f.sigma > 0.f ? std::log(f.sigma) : kEmptyRawDensity;
      for (int c = 0; c < 3; ++c) {
        const float col = std::clamp(f.color[c], kMinColor, kMaxColor);
        out[1 + c] = std::log(col / (1.f - col));
      }
      if (options.seed != 0) {
        // Keyed by the lattice point, so vertices shared by blocks agree.
        const uint64_t point = uint64_t(g.x) + uint64_t(R + 1) * (uint64_t(g.y) + uint64_t(R + 1) * uint64_t(g.z));
        for (int c = 4; c < F; ++c) out[c] = hash_to_unit(options.seed, point * uint64_t(F) + uint64_t(c));
      }
    }
  }

  // One MLP per occupied CV, all the same.
  MlpF mlp;
  mlp.density = zero_net(m.mlp_arch.density_widths);
  mlp.color = zero_net(m.mlp_arch.color_widths);
  make_pass_through(mlp.density, {0, 1, 2, 3}, "density");
  make_pass_through(mlp.color, {1, 2, 3}, "colour");
  float max_all = 0.f, max_03 = 0.f, max_13 = 0.f;  // largest |feature| over all / 0..3 / 1..3 channels
  for (size_t v = 0; v < nblocks * kBlockVerts; ++v)
    for (int c = 0; c < F; ++c) {
      const float a = std::abs(m.features_f32[v * size_t(F) + size_t(c)]);
      max_all = std::max(max_all, a);
      if (c < 4) max_03 = std::max(max_03, a);
      if (c >= 1 && c < 4) max_13 = std::max(max_13, a);
    }
  auto step = [](float range) { return range > 0.f ? range / 127.f : 1.f; };
  std::vector<float> density_in(mlp.density.size(), step(max_03));
  density_in[0] = step(max_all);
  std::vector<float> color_in(mlp.color.size(), step(max_13));
  color_in[0] = step(std::max(max_03, 1.f));  // density outputs and the direction encoding (|x| <= 1)
  MlpQ mlp_q;
  mlp_q.density = quantize_unit_net(mlp.density, density_in);
  mlp_q.color = quantize_unit_net(mlp.color, color_in);

  const Bitmap3& coarse = m.occupancy[int(Tier::Coarse)];
  for (size_t i = 0; i < coarse.size(); ++i)
    if (coarse.get(i)) m.mlp_coarse_index.push_back(uint32_t(i));
  m.mlps_f32.assign(m.mlp_coarse_index.size(), mlp);
  m.mlps_q8.assign(m.mlp_coarse_index.size(), mlp_q);

  m.quantize_features();
  if (!options.store_float) {
    m.features_f32.clear();
    m.features_f32.shrink_to_fit();
    m.mlps_f32.clear();
  }

  nlohmann::json meta;
  meta["generator"] = "procedural";
  meta["scene"] = scene_name;
  meta["micro_res"] = m.micro_res;
  meta["feature_channels"] = F;
  meta["seed"] = options.seed;
  meta["empty_raw_density"] = json_num(kEmptyRawDensity);
  meta["shapes"] = nlohmann::json::array();
  for (const Shape& s : shapes) meta["shapes"].push_back(shape_json(s));
  m.metadata_json = meta.dump();
  m.finalize();
  return m;
}

}  // namespace edrnr
