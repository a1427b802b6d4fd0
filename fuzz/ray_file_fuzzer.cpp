// read_ray_file on arbitrary bytes: it either throws Error or returns rays that can be
// traced (finite numbers, non-zero direction, tmin <= tmax), as its header promises.
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "bvhopt/error.h"
#include "bvhopt/ray_file.h"
#include "fuzz_input_file.h"

namespace {

bool finite(const bvhopt::Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = bvhopt::fuzz::write_input_file(data, size, ".rays");
  try {
    const bvhopt::RaySet set = bvhopt::read_ray_file(path);
    for (const bvhopt::Ray& r : set.rays) {
      const bool zero_dir = r.dir.x == 0.0f && r.dir.y == 0.0f && r.dir.z == 0.0f;
      if (!finite(r.org) || !finite(r.dir) || zero_dir || std::isnan(r.tmin) || std::isnan(r.tmax) ||
          !(r.tmin <= r.tmax)) {
        std::fprintf(stderr, "read_ray_file accepted a ray that cannot be traced\n");
        std::abort();
      }
    }
  } catch (const bvhopt::Error&) {
  }
  return 0;
}
