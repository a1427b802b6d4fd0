// Pictures that explain themselves: a heat map or a difference image with its colour bar
// (the scale, in traversal steps) to the right and a caption strip below, drawn into the
// image (bvhopt::io; the colour maps themselves are in bvhopt/images.h).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "bvhopt/font.h"
#include "bvhopt/images.h"
#include "bvhopt/tracer.h"

namespace bvhopt {

// What the colours mean.
struct ColorKey {
  enum class Map { steps, difference };
  Map map = Map::steps;
  // steps: heat_color from 0 to max (full red at max and beyond); difference:
  // diverging_color from -max to +max.
  float max = 100.0f;
  std::string heading = "steps";  // above the bar
};

// The colour of `value` in the key's map.
void key_color(const ColorKey& key, float value, uint8_t rgb[3]);

struct PixelRect {
  uint32_t x = 0, y = 0, width = 0, height = 0;
};

struct LegendImage {
  Image image;
  PixelRect picture;  // the picture, unchanged, at the top left
  // The colour bar: its top row shows the key's top value, its bottom row the bottom one
  // (0 steps, or -max), linear in between.
  PixelRect bar;
  PixelRect caption;  // the strip below the picture and the bar
  bool has_text = false;  // false when drawn without a font: bar and strip, no labels
};

// The picture with the key's colour bar to its right, ticks labelled in the key's units,
// and the caption lines in a strip below. Without a font (nullptr) the same layout is drawn
// without any text.
LegendImage add_legend(const Image& picture, const ColorKey& key, const std::vector<std::string>& caption,
                       const Font* font);

// The top of the heat scale shared by heat maps of one view (a --compare pair): the
// `percentile` of every pixel's steps in all of them, rounded up to a round number
// (1, 1.5, 2, 2.5, 3, 4, 5, 6 or 8 times a power of ten), at least 1.
float shared_heat_scale(const std::vector<const std::vector<TraceCounters>*>& maps, double percentile = 0.99);

// The same for the difference b - a: the percentile of |b - a| per pixel, rounded up.
float difference_scale(const std::vector<TraceCounters>& a, const std::vector<TraceCounters>& b,
                       double percentile = 0.99);

// Mean steps per pixel.
double mean_steps(const std::vector<TraceCounters>& counters);

// A heat map (heatmap_image) on the scale 0..max_steps with its legend; the caption is
// `name` and the mean steps per pixel.
LegendImage heatmap_with_legend(const std::vector<TraceCounters>& counters, uint32_t width, uint32_t height,
                                float max_steps, const std::string& name, const Font* font);

// The difference b - a (difference_image) on the scale -range..range with its legend; the
// caption is `name` and the mean difference.
LegendImage difference_with_legend(const std::vector<TraceCounters>& a, const std::vector<TraceCounters>& b,
                                   uint32_t width, uint32_t height, float range, const std::string& name,
                                   const Font* font);

// One heat map of a set written together.
struct HeatmapFile {
  const std::vector<TraceCounters>* counters = nullptr;
  std::string name;  // its caption's first line
  std::filesystem::path file;
};

// Writes heat maps of one view (width x height pixels each) as PNG on one shared scale
// (shared_heat_scale of all of them), each with its legend; `font` null: without text.
// Returns the scale's top.
float write_heatmaps(const std::vector<HeatmapFile>& maps, uint32_t width, uint32_t height, const Font* font);

}  // namespace bvhopt
