#include "chip/zorg.h"

#include <algorithm>
#include <bit>
#include <cmath>

#include "chip/zorg_kernel.h"
#include "core/error.h"

namespace edrnr::chip {

namespace {
constexpr uint32_t kQuadCounterEnd = 1u << (kZorgCounterBits - 2);  // 2^20 quads
constexpr int kQuadCoordBits = kZorgCoordBits - 1;                  // 10

// Spreads the low 16 bits of v to the even bit positions.
uint32_t spread_bits(uint32_t v) {
  v &= 0xFFFFu;
  v = (v | (v << 8)) & 0x00FF00FFu;
  v = (v | (v << 4)) & 0x0F0F0F0Fu;
  v = (v | (v << 2)) & 0x33333333u;
  v = (v | (v << 1)) & 0x55555555u;
  return v;
}

// Gathers the even bits of v into the low 16 bits.
uint32_t gather_bits(uint32_t v) {
  v &= 0x55555555u;
  v = (v | (v >> 1)) & 0x33333333u;
  v = (v | (v >> 2)) & 0x0F0F0F0Fu;
  v = (v | (v >> 4)) & 0x00FF00FFu;
  v = (v | (v >> 8)) & 0x0000FFFFu;
  return v;
}
}  // namespace

uint32_t morton_interleave(uint32_t x, uint32_t y) { return spread_bits(x) | (spread_bits(y) << 1); }

void morton_split(uint32_t code, uint32_t& x, uint32_t& y) {
  x = gather_bits(code);
  y = gather_bits(code >> 1);
}

uint32_t zorg_next_in_bounds(uint32_t q, uint32_t quads_w, uint32_t quads_h) {
  while (q < kQuadCounterEnd) {
    uint32_t qx, qy;
    morton_split(q, qx, qy);
    if (qx < quads_w && qy < quads_h) return q;
    // The largest aligned block (side 2^level) around (qx, qy) that lies
    // wholly outside the grid: its low corner is already out of bounds.
    int level = 0;
    for (int l = kQuadCoordBits; l >= 1; --l) {
      uint32_t keep = ~((1u << l) - 1u);
      if ((qx & keep) >= quads_w || (qy & keep) >= quads_h) {
        level = l;
        break;
      }
    }
    q = (q | ((1u << (2 * level)) - 1u)) + 1u;  // first code after that block
  }
  return kQuadCounterEnd;
}

Zorg::Zorg(int width, int height, ScanOrder order) : width_(width), height_(height), order_(order) {
  if (width < 1 || width > kMaxImageSide || height < 1 || height > kMaxImageSide)
    fail("image size {}x{} is outside what ZORG's 11-bit coordinates address (1..{} per side)", width, height,
         kMaxImageSide);
  if (order_ == ScanOrder::ZOrder) {
    quads_w_ = uint32_t(width + 1) / 2;
    quads_h_ = uint32_t(height + 1) / 2;
    packet_count_ = quads_w_ * quads_h_;
    quad_counter_ = zorg_next_in_bounds(0, quads_w_, quads_h_);
  } else {
    quads_w_ = uint32_t(width + 3) / 4;  // RPs per row
    quads_h_ = uint32_t(height);
    packet_count_ = quads_w_ * quads_h_;
  }
}

PixelQuad Zorg::next() {
  PixelQuad quad;
  quad.sequence = issued_;
  if (order_ == ScanOrder::ZOrder) {
    uint32_t qx, qy;
    morton_split(quad_counter_, qx, qy);
    for (int r = 0; r < kRaysPerPacket; ++r) {
      uint32_t px = 2 * qx + uint32_t(r & 1), py = 2 * qy + uint32_t(r >> 1);
      if (px < uint32_t(width_) && py < uint32_t(height_)) {
        quad.x[r] = uint16_t(px);
        quad.y[r] = uint16_t(py);
        quad.valid_mask |= uint8_t(1u << r);
      }
    }
    uint32_t next = zorg_next_in_bounds(quad_counter_ + 1, quads_w_, quads_h_);
    if (next > quad_counter_ + 1 && next < kQuadCounterEnd) {
      skipped_quads_ += next - quad_counter_ - 1;
      ++jumps_;
    }
    quad_counter_ = next;
  } else {
    uint32_t row = quad_counter_ / quads_w_, group = quad_counter_ % quads_w_;
    for (int r = 0; r < kRaysPerPacket; ++r) {
      uint32_t px = 4 * group + uint32_t(r);
      if (px < uint32_t(width_)) {
        quad.x[r] = uint16_t(px);
        quad.y[r] = uint16_t(row);
        quad.valid_mask |= uint8_t(1u << r);
      }
    }
    ++quad_counter_;
  }
  ++issued_;
  return quad;
}

RayGenerator::RayGenerator(const Camera& camera, const Box3f& scene_box, int micro_res, const FloatFormat& ray_float,
                           const FloatFormat& traversal_float)
    : rf_(ray_float), tf_(traversal_float) {
  if (!(std::isfinite(camera.fx) && std::isfinite(camera.fy) && camera.fx != 0 && camera.fy != 0))
    fail("camera focal lengths {}, {} are not finite and non-zero", camera.fx, camera.fy);
  for (double v : camera.c2w)
    if (!std::isfinite(v)) fail("camera pose has a non-finite entry");
  const Vec3f size = scene_box.size();
  for (int a = 0; a < 3; ++a)
    if (!(size[a] > 0.f)) fail("scene box is empty along axis {}", a);
  cx_ = rf_.round(camera.cx);
  cy_ = rf_.round(camera.cy);
  fx_ = rf_.round(camera.fx);
  fy_ = rf_.round(camera.fy);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) rot_[i][j] = rf_.round(camera.c2w[size_t(4 * i + j)]);
  const Vec3d o = camera.origin();
  for (int a = 0; a < 3; ++a) {
    const double scale = rf_.round(double(micro_res) / double(size[a]));
    origin_m_[a] = tf_.round(rf_.mul(rf_.sub(rf_.round(o[a]), rf_.round(double(scene_box.lo[a]))), scale));
    dir_scale_[a] = rf_.round(double(size.x) / double(size[a]));
  }
  const int columns = std::clamp(camera.width, 0, kMaxImageSide), rows = std::clamp(camera.height, 0, kMaxImageSide);
  column_terms_.resize(size_t(columns));
  row_terms_.resize(size_t(rows));
  for (int x = 0; x < columns; ++x) column_terms_[size_t(x)] = column_term(x);
  for (int y = 0; y < rows; ++y) row_terms_[size_t(y)] = row_term(y);
  for (int i = 0; i < 3; ++i) z_term_[i] = rf_.mul(rot_[i][2], -1.0);
  lane_rf_ = {rf_.drop_bits(), rf_.min_normal(), rf_.overflow_threshold()};
  lane_tf_ = {tf_.drop_bits(), tf_.min_normal(), tf_.overflow_threshold()};
}

Vec3d RayGenerator::column_term(int x) const {
  const double cam_x = rf_.div(rf_.sub(rf_.round(x + 0.5), cx_), fx_);
  return {rf_.mul(rot_[0][0], cam_x), rf_.mul(rot_[1][0], cam_x), rf_.mul(rot_[2][0], cam_x)};
}

Vec3d RayGenerator::row_term(int y) const {
  const double cam_y = rf_.neg(rf_.div(rf_.sub(rf_.round(y + 0.5), cy_), fy_));
  return {rf_.mul(rot_[0][1], cam_y), rf_.mul(rot_[1][1], cam_y), rf_.mul(rot_[2][1], cam_y)};
}

GeneratedRay RayGenerator::generate(int x, int y) const {
  // w = R d_cam, summed in the order (x term + y term) + z term.
  const bool inside = x >= 0 && y >= 0 && size_t(x) < column_terms_.size() && size_t(y) < row_terms_.size();
  const Vec3d col = inside ? column_terms_[size_t(x)] : column_term(x);
  const Vec3d row = inside ? row_terms_[size_t(y)] : row_term(y);
  Vec3d w;
  for (int i = 0; i < 3; ++i) w[i] = rf_.add(rf_.add(col[i], row[i]), z_term_[i]);
  const double len = rf_.sqrt(rf_.add(rf_.add(rf_.mul(w.x, w.x), rf_.mul(w.y, w.y)), rf_.mul(w.z, w.z)));
  GeneratedRay g;
  for (int a = 0; a < 3; ++a) {
    g.world_dir[a] = len > 0 ? rf_.div(w[a], len) : 0.0;
    g.ray.dir[a] = tf_.round(rf_.mul(g.world_dir[a], dir_scale_[a]));
  }
  g.ray.origin = origin_m_;
  return g;
}

std::array<GeneratedRay, kRaysPerPacket> RayGenerator::generate(const PixelQuad& quad) const {
  std::array<GeneratedRay, kRaysPerPacket> out{};
  // The four rays in SIMD lanes (invalid rays repeat a valid one's pixel),
  // unless a pixel is outside the image or a value leaves the formats'
  // normal range: then one ray at a time (the same values).
  static_assert(kRaysPerPacket == 4, "zorg_directions computes four rays");
  const int lead = quad.valid_mask ? std::countr_zero(unsigned(quad.valid_mask)) : -1;
  bool lanes = lead >= 0;
  alignas(32) double col[3][4], row[3][4], world[3][4], dir[3][4];
  for (int r = 0; r < kRaysPerPacket && lanes; ++r) {
    const int src = quad.valid_mask >> r & 1 ? r : lead;
    const size_t x = quad.x[size_t(src)], y = quad.y[size_t(src)];
    lanes = x < column_terms_.size() && y < row_terms_.size();
    if (!lanes) break;
    for (int a = 0; a < 3; ++a) {
      col[a][r] = column_terms_[x][a];
      row[a][r] = row_terms_[y][a];
    }
  }
  const double z[3] = {z_term_.x, z_term_.y, z_term_.z}, scale[3] = {dir_scale_.x, dir_scale_.y, dir_scale_.z};
  if (lanes && zorg_directions(&col[0][0], &row[0][0], z, scale, lane_rf_, lane_tf_, &world[0][0], &dir[0][0])) {
    for (int r = 0; r < kRaysPerPacket; ++r) {
      if (!(quad.valid_mask >> r & 1)) continue;
      GeneratedRay& g = out[size_t(r)];
      for (int a = 0; a < 3; ++a) {
        g.world_dir[a] = world[a][r];
        g.ray.dir[a] = dir[a][r];
      }
      g.ray.origin = origin_m_;
    }
    return out;
  }
  for (int r = 0; r < kRaysPerPacket; ++r)
    if (quad.valid_mask >> r & 1) out[size_t(r)] = generate(quad.x[size_t(r)], quad.y[size_t(r)]);
  return out;
}

}  // namespace edrnr::chip
