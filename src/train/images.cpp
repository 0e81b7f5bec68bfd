#include "train/images.h"

#include <exception>

#include "core/error.h"

namespace edrnr::train {

void load_premultiplied_rgba(Dataset& data, int downscale_factor) {
  const int n = int(data.frames.size());
  std::exception_ptr error;
#pragma omp parallel for schedule(dynamic, 1)
  for (int i = 0; i < n; ++i) {
    try {
      Frame& f = data.frames[size_t(i)];
      Image rgba = read_frame_rgba(f, downscale_factor);
      for (size_t p = 0; p < rgba.data.size(); p += 4)
        for (int c = 0; c < 3; ++c) rgba.data[p + size_t(c)] *= rgba.data[p + 3];
      f.image = downscale(rgba, downscale_factor);
    } catch (...) {
#pragma omp critical
      if (!error) error = std::current_exception();
    }
  }
  if (error) std::rethrow_exception(error);
}

}  // namespace edrnr::train
