#pragma once
// ZORG, the Z-order ray generator (paper Section IV-B, Fig. 11).
//
// A 22-bit pixel counter FC walks the image along a Z-order (Morton) curve:
// the even bits of FC form the 11-bit X coordinate CX, the odd bits the 11-bit
// Y coordinate CY. The counter advances by 4 per ray packet (RP): the two low
// bits select the pixel inside a 2x2 quad, so one RP is the quad
// (2QX..2QX+1, 2QY..2QY+1) with the quad coordinates (QX, QY) taken from
// FC >> 2.
//
// For an image that is not a power-of-two square, the curve leaves the image
// and comes back. ZORG never issues an out-of-bounds quad: before the counter
// reaches an out-of-bounds stretch it jumps over every aligned Z-order block
// that lies wholly outside the image, straight to the next in-bounds quad.
// A quad on the right or bottom edge of an image with an odd width or height
// is issued with only its in-bounds pixels valid (valid_mask), so every pixel
// of the image is issued exactly once and no out-of-bounds coordinate is ever
// emitted.
//
// Row order (for comparison, the paper's Fig. 4(a)): RPs of four consecutive
// pixels of one row, rows top to bottom; the last RP of a row may be partial.
#include <array>
#include <cstdint>
#include <vector>

#include "chip/chip_ray.h"
#include "chip/zorg_kernel.h"
#include "core/custom_float.h"
#include "data/camera.h"

namespace edrnr::chip {

enum class ScanOrder { ZOrder, RowOrder };

inline constexpr int kZorgCounterBits = 22;
inline constexpr int kZorgCoordBits = 11;
inline constexpr int kMaxImageSide = 1 << kZorgCoordBits;  // 2048
inline constexpr int kRaysPerPacket = 4;

// The pixels of one ray packet. Ray r of the packet is pixel (x[r], y[r]);
// only rays whose bit is set in valid_mask exist (x, y of the others are 0).
struct PixelQuad {
  uint32_t sequence = 0;  // issue index, 0, 1, 2, ...
  std::array<uint16_t, kRaysPerPacket> x{}, y{};
  uint8_t valid_mask = 0;
};

// Morton helpers: interleave (x in even bits, y in odd bits) and split.
uint32_t morton_interleave(uint32_t x, uint32_t y);
void morton_split(uint32_t code, uint32_t& x, uint32_t& y);

// The smallest quad counter value >= q whose quad (QX, QY) lies inside a
// quads_w x quads_h grid, or 2^20 (the end of the curve) if there is none.
// It skips, in one step each, whole aligned Z-order blocks outside the grid.
uint32_t zorg_next_in_bounds(uint32_t q, uint32_t quads_w, uint32_t quads_h);

class Zorg {
 public:
  // Throws Error unless 1 <= width, height <= 2048.
  Zorg(int width, int height, ScanOrder order = ScanOrder::ZOrder);

  bool done() const { return issued_ == packet_count_; }
  // The next ray packet. Precondition: !done().
  PixelQuad next();

  int width() const { return width_; }
  int height() const { return height_; }
  ScanOrder order() const { return order_; }
  // Number of RPs one frame issues: ceil(W/2) * ceil(H/2) in Z order,
  // H * ceil(W/4) in row order.
  uint32_t packet_count() const { return packet_count_; }
  // Z order: the counter value FC of the next RP's first pixel.
  uint32_t counter() const { return quad_counter_ << 2; }
  // Z order: how many out-of-bounds quad positions were jumped over so far.
  uint64_t skipped_quads() const { return skipped_quads_; }
  // Z order: how many jumps (corrections before an out-of-bounds step) so far.
  uint64_t jumps() const { return jumps_; }

 private:
  int width_, height_;
  ScanOrder order_;
  uint32_t quads_w_, quads_h_;
  uint32_t packet_count_ = 0;
  uint32_t issued_ = 0;
  uint32_t quad_counter_ = 0;  // Z order: FC >> 2; row order: RP index
  uint64_t skipped_quads_ = 0;
  uint64_t jumps_ = 0;
};

// One generated ray: its unit world direction (for the TME's direction
// encoding) and the ray in micro-grid units (for the traversal units).
struct GeneratedRay {
  Vec3d world_dir;  // ray float values
  ChipRay ray;      // traversal float values
};

// ZORG's direction datapath, computing the rays of a packet in parallel, all
// in the ray float format with one rounding per operation:
//   d_cam = ((u - cx) / fx, -((v - cy) / fy), -1) at the pixel centre (u, v)
//   d     = R d_cam / |R d_cam|  (R: the camera-to-world rotation)
//   o_m   = (o - box_lo) * (Rm / box_size),  d_m = d * (box_size_x / box_size)
// then rounded to the traversal float. Pure: the same pixel always gives the
// same ray.
class RayGenerator {
 public:
  // Throws Error for a camera with a non-finite or zero focal length, or an
  // empty scene box.
  RayGenerator(const Camera& camera, const Box3f& scene_box, int micro_res, const FloatFormat& ray_float,
               const FloatFormat& traversal_float);

  GeneratedRay generate(int x, int y) const;
  // Every ray's origin: the camera's, in micro units and the traversal float.
  const Vec3d& origin() const { return origin_m_; }
  // The rays of a packet (invalid rays are left default).
  std::array<GeneratedRay, kRaysPerPacket> generate(const PixelQuad& quad) const;

 private:
  // R's first column times d_cam.x of column x, its second times d_cam.y of
  // row y (one rounding per product): the products of R d_cam that depend on
  // x or y alone.
  Vec3d column_term(int x) const;
  Vec3d row_term(int y) const;

  FloatFormat rf_, tf_;
  double cx_, cy_, fx_, fy_;
  double rot_[3][3];
  Vec3d origin_m_;   // camera origin in micro units
  Vec3d dir_scale_;  // box_size_x / box_size per axis
  // column_term / row_term of the camera's image columns and rows, computed
  // once (pixels outside the image compute theirs), and R's third column
  // times d_cam.z = -1.
  std::vector<Vec3d> column_terms_, row_terms_;
  Vec3d z_term_;
  LaneRounding lane_rf_, lane_tf_;  // the two formats for zorg_directions
};

}  // namespace edrnr::chip
