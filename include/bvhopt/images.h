// Pictures of traversal: steps-per-pixel heat maps, an eye-light shaded image, and the
// difference of two trees. Written as PNG by bvhopt/png_file.h (bvhopt::io).
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

#include "bvhopt/mesh.h"
#include "bvhopt/ray.h"
#include "bvhopt/tracer.h"

namespace bvhopt {

struct Image {
  uint32_t width = 0, height = 0;
  std::vector<uint8_t> rgb;  // 3 bytes per pixel, row-major from the top left
};

// The fixed heat scale of Bittner's Figure 1: 0 steps dark blue, through cyan, green and
// yellow, to red at `max_steps` and beyond. Fixed so images of different trees compare.
void heat_color(float steps, float max_steps, uint8_t rgb[3]);

// One pixel per primary ray (counters.size() == width * height).
Image heatmap_image(const std::vector<TraceCounters>& counters, uint32_t width, uint32_t height,
                    float max_steps = 100.0f);

// Eye light: grey level |cos| between the ray and the geometric normal of the hit; misses black.
Image shaded_image(const Mesh& mesh, const std::vector<Ray>& rays, const std::vector<Hit>& hits, uint32_t width,
                   uint32_t height);

// The diverging map of differences: white at 0, through light to dark red at +`range` and
// beyond, and the mirror image in blue (red and blue swapped) for negative values, so that
// equal differences of opposite sign look equally strong.
void diverging_color(float difference, float range, uint8_t rgb[3]);

// Steps of tree B minus steps of tree A per pixel, in diverging_color: blue where B takes
// fewer steps, red where it takes more, white where equal; full colour at +-`range` steps.
Image difference_image(const std::vector<TraceCounters>& a, const std::vector<TraceCounters>& b, uint32_t width,
                       uint32_t height, float range = 50.0f);

}  // namespace bvhopt

// Callers written before PNG writing moved to bvhopt::io get write_png from here too; new
// code includes bvhopt/png_file.h itself.
#include "bvhopt/png_file.h"
