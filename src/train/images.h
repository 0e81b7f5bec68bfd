#pragma once
// Training images with their alpha: the trainer composites each ray's target
// on a random background when it has the alpha (Instant-NGP's trick), which
// teaches empty space to be transparent instead of background-coloured.
#include "data/dataset.h"

namespace edrnr::train {

// Loads every frame's PNG as premultiplied RGBA (r a, g a, b a, a), box-filtered
// by `downscale` after premultiplying (so any background composited later
// equals compositing before the downscale). The frames' cameras must already
// be downscaled (load_dataset with load_images = false and the same factor).
// Throws Error naming the image if it is missing, invalid or of the wrong size.
void load_premultiplied_rgba(Dataset& data, int downscale);

}  // namespace edrnr::train
