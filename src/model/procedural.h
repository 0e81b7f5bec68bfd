#pragma once
// Procedural scene models: valid SceneModels built from analytic solids of
// constant density and colour, so that renderers can be checked against
// closed forms without a trained model.
//
// The field: at a point p, the "owner" is the shape with the smallest signed
// distance (the first such shape on ties). The density is the owner's sigma
// if p lies in it (closed solid) and 0 otherwise; the colour is the owner's
// colour everywhere, so colour is constant across a single object's surface.
//
// The model: a micro voxel is occupied iff it overlaps a shape (exact
// geometry, closed sets); the object AABB is the tight box of occupied micro
// voxels; every occupied fine voxel gets a block and every occupied CV an
// MLP. Feature channel 0 holds log(sigma) at the vertex (kEmptyRawDensity
// where sigma = 0), channels 1..3 the logit of the colour, other channels 0
// (or seeded pseudo-random values that the MLPs ignore). The MLPs pass
// channel 0 to the raw density and channels 1..3 to the colour logits through
// relu(x) - relu(-x) pairs, so the model renders the field up to trilinear
// interpolation of the vertex values. Float and quantized forms are both
// stored; the INT8 weights (+-64 with scale 1/64) are exact.
#include <cstdint>
#include <string>
#include <vector>

#include "core/vec.h"
#include "model/scene_model.h"

namespace edrnr {

enum class ShapeKind { Sphere, Box, Torus };

// One solid of constant density and colour, in scene (world) units.
struct Shape {
  ShapeKind kind = ShapeKind::Sphere;
  Vec3f center{0.f, 0.f, 0.f};
  float radius = 1.f;                 // sphere: radius; torus: ring radius (ring in the plane z = center.z)
  float tube_radius = 0.3f;           // torus: tube radius
  Vec3f half_size{0.7f, 0.7f, 0.7f};  // box: half extents
  float sigma = 20.f;                 // density inside, per scene unit, in [kMinShapeSigma, kMaxShapeSigma]
  Vec3f color{0.8f, 0.3f, 0.2f};      // linear RGB, each in [0, 1]
};

inline constexpr float kMinShapeSigma = 1e-3f;
inline constexpr float kMaxShapeSigma = 1e6f;
// Feature channel 0 at vertices where the density is 0: exp(-10) = 4.5e-5 per
// scene unit, negligible at any step used here.
inline constexpr float kEmptyRawDensity = -10.f;
// Colours are clamped to this range before the logit, so logits stay finite.
inline constexpr float kMinColor = 0.005f;
inline constexpr float kMaxColor = 0.995f;

const char* shape_kind_name(ShapeKind kind);

// Signed distance to the solid: < 0 inside, 0 on the surface, > 0 outside
// (exact Euclidean distance outside for all three kinds).
float shape_distance(const Shape& s, const Vec3f& p);
// Whether the closed solid and the closed box have a point in common.
bool shape_overlaps_box(const Shape& s, const Box3f& box);
// Axis-aligned bounds of the solid.
Box3f shape_bounds(const Shape& s);
// Throws Error naming `what` and the parameter if a shape's parameters are invalid.
void validate_shape(const Shape& s, const std::string& what);

struct FieldSample {
  float sigma = 0.f;
  Vec3f color{0.f, 0.f, 0.f};
};
// The analytic field the model represents (see the top of this file).
FieldSample procedural_field(const std::vector<Shape>& shapes, const Vec3f& p);

// Names make_procedural_model understands: sphere, box, torus, several.
std::vector<std::string> procedural_scene_names();
// The default shapes of a named scene ("several": four objects of different
// colours and densities, one of them translucent). Error for an unknown name.
std::vector<Shape> procedural_shapes(const std::string& scene);

struct ProceduralOptions {
  int micro_res = 256;        // Rm, a multiple of 32
  int feature_channels = 16;  // F, at least 4
  uint64_t seed = 0;          // 0: unused channels are 0; else pseudo-random in [-1, 1]
  bool store_float = true;    // false: keep only the quantized features and MLPs
  Box3f scene_box{{-1.5f, -1.5f, -1.5f}, {1.5f, 1.5f, 1.5f}};
};

// Builds a finalize()d, valid model of `shapes` (MLP shape default_mlp_arch(F)).
// `scene_name` goes into the metadata JSON with every parameter. Shapes may be
// empty or outside the scene box: the model is then empty.
SceneModel make_procedural_model(const std::string& scene_name, const std::vector<Shape>& shapes,
                                 const ProceduralOptions& options);

}  // namespace edrnr
