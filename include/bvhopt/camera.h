// A pinhole camera: where primary rays start and where they look.
#pragma once

#include <cstdint>

#include "bvhopt/vec3.h"

namespace bvhopt {

struct Camera {
  Vec3 position;
  Vec3 target{0.0f, 0.0f, -1.0f};
  Vec3 up{0.0f, 1.0f, 0.0f};
  float fov_degrees = 60.0f;  // vertical field of view
  uint32_t width = 1024;
  uint32_t height = 768;
};

}  // namespace bvhopt
