// Heat maps, shaded images and difference images (written as PNG by src/io/png_file.cpp).
#include "bvhopt/images.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "bvhopt/error.h"

namespace bvhopt {
namespace {

uint8_t to_byte(float x) { return static_cast<uint8_t>(std::lround(std::clamp(x, 0.0f, 1.0f) * 255.0f)); }

void check_size(size_t n, uint32_t w, uint32_t h, const char* what) {
  if (n != size_t(w) * h)
    throw Error(std::string(what) + ": " + std::to_string(n) + " values for a " + std::to_string(w) + "x" +
                std::to_string(h) + " image");
}

}  // namespace

void heat_color(float steps, float max_steps, uint8_t rgb[3]) {
  // Piecewise linear through dark blue, blue, cyan, green, yellow, red.
  static constexpr float stops[6][3] = {{0.0f, 0.0f, 0.35f}, {0.0f, 0.2f, 1.0f}, {0.0f, 0.9f, 1.0f},
                                        {0.1f, 0.9f, 0.1f},  {1.0f, 0.95f, 0.0f}, {0.9f, 0.0f, 0.0f}};
  const float x = std::clamp(max_steps > 0.0f ? steps / max_steps : 1.0f, 0.0f, 1.0f) * 5.0f;
  const int i = std::min(static_cast<int>(x), 4);
  const float f = x - float(i);
  for (int c = 0; c < 3; ++c) rgb[c] = to_byte(stops[i][c] * (1.0f - f) + stops[i + 1][c] * f);
}

Image heatmap_image(const std::vector<TraceCounters>& counters, uint32_t width, uint32_t height, float max_steps) {
  check_size(counters.size(), width, height, "heat map");
  Image img{width, height, std::vector<uint8_t>(size_t(width) * height * 3)};
  for (size_t i = 0; i < counters.size(); ++i) heat_color(float(counters[i].steps), max_steps, &img.rgb[3 * i]);
  return img;
}

Image shaded_image(const Mesh& mesh, const std::vector<Ray>& rays, const std::vector<Hit>& hits, uint32_t width,
                   uint32_t height) {
  check_size(rays.size(), width, height, "shaded image");
  check_size(hits.size(), width, height, "shaded image");
  Image img{width, height, std::vector<uint8_t>(size_t(width) * height * 3, 0)};
  for (size_t i = 0; i < hits.size(); ++i) {
    if (!hits[i].hit()) continue;
    const Triangle t = mesh.triangle(hits[i].triangle_id);
    const Vec3 n = cross(t.v1 - t.v0, t.v2 - t.v0);
    const float denom = length(n) * length(rays[i].dir);
    const float c = denom > 0.0f ? std::fabs(dot(n, rays[i].dir)) / denom : 0.0f;
    // A little ambient so surfaces seen edge-on stay visible against the black background.
    const uint8_t g = to_byte(0.1f + 0.9f * c);
    img.rgb[3 * i] = img.rgb[3 * i + 1] = img.rgb[3 * i + 2] = g;
  }
  return img;
}

void diverging_color(float difference, float range, uint8_t rgb[3]) {
  // The red half, piecewise linear from white through salmon to dark red; the blue half is
  // the same with red and blue swapped.
  static constexpr float stops[3][3] = {{1.0f, 1.0f, 1.0f}, {0.96f, 0.50f, 0.40f}, {0.60f, 0.02f, 0.08f}};
  const float d = std::clamp(range > 0.0f ? difference / range : 0.0f, -1.0f, 1.0f);
  const float x = std::fabs(d) * 2.0f;
  const int i = std::min(static_cast<int>(x), 1);
  const float f = x - float(i);
  uint8_t c[3];
  for (int k = 0; k < 3; ++k) c[k] = to_byte(stops[i][k] * (1.0f - f) + stops[i + 1][k] * f);
  const bool red = d >= 0.0f;
  rgb[0] = red ? c[0] : c[2];
  rgb[1] = c[1];
  rgb[2] = red ? c[2] : c[0];
}

Image difference_image(const std::vector<TraceCounters>& a, const std::vector<TraceCounters>& b, uint32_t width,
                       uint32_t height, float range) {
  check_size(a.size(), width, height, "difference image");
  check_size(b.size(), width, height, "difference image");
  Image img{width, height, std::vector<uint8_t>(size_t(width) * height * 3)};
  const float r = std::max(range, 1e-6f);
  for (size_t i = 0; i < a.size(); ++i) diverging_color(float(b[i].steps) - float(a[i].steps), r, &img.rgb[3 * i]);
  return img;
}

}  // namespace bvhopt
