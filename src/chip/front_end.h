#pragma once
// The chip's front end for one ray packet: ZORG's direction datapath, the ABT
// and the TSPS. It turns a pixel quad into a ray packet ready for the CTU:
// each valid ray generated, tested against the traversal box, given its run
// of candidates, its VRU state started and its direction encoding computed.
#include <cstdint>

#include "chip/abt.h"
#include "chip/chip_ray.h"
#include "chip/numerics.h"
#include "chip/rp_buffer.h"
#include "chip/tsps.h"
#include "chip/vru.h"
#include "chip/zorg.h"
#include "data/camera.h"
#include "model/scene_model.h"

namespace edrnr::chip {

// The traversal box in micro units: the object AABB widened to whole micro
// voxels (use_aabb), or the whole grid [0, Rm]^3.
void traversal_box(const SceneModel& model, bool use_aabb, Vec3d& lo, Vec3d& hi);

struct FrontEndCounters {
  uint64_t rays = 0;               // valid rays generated
  uint64_t rays_dropped_abt = 0;   // dropped by the ABT
  uint64_t rays_dropped_tsps = 0;  // passed the ABT but have no candidate in the box
};

class FrontEnd {
 public:
  // math: the traversal arithmetic the rays' runs are found with (kept by
  // reference). Throws Error for an unusable camera.
  FrontEnd(const SceneModel& model, const Camera& camera, const ChipNumerics& numerics, const RayMath& math,
           bool use_aabb);

  // The packet of `quad`. Its live_mask() is 0 when no ray reaches the
  // traversal (all pixels take the background).
  RayPacket build(const PixelQuad& quad, const Vru& vru);
  // The same packet built in p, whatever p held (its vectors' storage is reused).
  void build(const PixelQuad& quad, const Vru& vru, RayPacket& p);
  // On (the default): build() fills each traversed ray's dir_code. Off: it
  // leaves dir_code empty for the consumer to encode (Tme::encode_direction
  // of world_dir) where the ray's samples are evaluated.
  void set_encode_directions(bool on) { encode_directions_ = on; }

  const Vec3d& box_lo() const { return lo_; }
  const Vec3d& box_hi() const { return hi_; }
  const FrontEndCounters& counters() const { return counters_; }
  uint64_t tsps_position_evals() const { return tsps_.position_evals(); }

 private:
  const SceneModel& model_;
  ChipNumerics n_;
  RayGenerator gen_;
  Vec3d lo_, hi_;
  Abt abt_;
  Abt::Origin abt_origin_;  // the slab terms of the camera origin
  Tsps tsps_;
  FrontEndCounters counters_;
  bool encode_directions_ = true;
};

}  // namespace edrnr::chip
