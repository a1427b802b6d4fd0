// Colour bars and caption strips drawn into heat maps and difference images.
#include "bvhopt/image_legend.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "bvhopt/error.h"
#include "bvhopt/png_file.h"

namespace bvhopt {
namespace {

constexpr uint8_t kBackground[3] = {255, 255, 255};
constexpr uint8_t kInk[3] = {25, 25, 25};
constexpr int kTicks = 5;  // bottom, quarter, half, three quarters, top

// Sizes in pixels, from the picture's height so the text reads the same on any image.
struct Layout {
  float text_px;  // line height of the text
  int margin, bar_width, line;
};

Layout layout_for(uint32_t picture_height) {
  const float px = std::clamp(std::round(float(picture_height) / 28.0f), 10.0f, 26.0f);
  return {px, int(std::lround(px * 0.5f)), std::max(6, int(std::lround(px * 0.9f))), int(std::lround(px * 1.3f))};
}

void fill(Image& img, const PixelRect& r, const uint8_t rgb[3]) {
  for (uint32_t y = r.y; y < r.y + r.height && y < img.height; ++y)
    for (uint32_t x = r.x; x < r.x + r.width && x < img.width; ++x) std::copy(rgb, rgb + 3, &img.rgb[3 * (size_t(y) * img.width + x)]);
}

// Tick k of kTicks from the bottom of the bar.
float tick_value(const ColorKey& key, int k) {
  const float lo = key.map == ColorKey::Map::steps ? 0.0f : -key.max;
  return lo + (key.max - lo) * float(k) / float(kTicks - 1);
}

std::string tick_label(const ColorKey& key, int k) {
  const float v = tick_value(key, k);
  bool whole = true;
  for (int i = 0; i < kTicks; ++i) whole = whole && std::fabs(tick_value(key, i) - std::round(tick_value(key, i))) < 1e-3f;
  char number[32];
  std::snprintf(number, sizeof number, whole ? "%.0f" : "%.1f", double(std::fabs(v)));
  std::string text = number;
  if (key.map == ColorKey::Map::difference && v != 0.0f) text = (v < 0.0f ? "\u2212" : "+") + text;
  // Values beyond the ends show in the end colours.
  if (k == kTicks - 1) text += "+";
  if (k == 0 && key.map == ColorKey::Map::difference) text = "\u2264" + text;
  return text;
}

// The rounded-up top of a scale: 1, 1.5, 2, 2.5, 3, 4, 5, 6 or 8 times a power of ten.
float round_up_scale(double value) {
  if (!(value > 1.0)) return 1.0f;
  const double decade = std::pow(10.0, std::floor(std::log10(value)));
  for (double m : {1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0})
    if (m * decade >= value * (1.0 - 1e-9)) return float(m * decade);
  return float(10.0 * decade);
}

double percentile_of(std::vector<float>& values, double percentile) {
  if (values.empty()) return 0.0;
  const size_t k = std::min(values.size() - 1, size_t(std::clamp(percentile, 0.0, 1.0) * double(values.size() - 1) + 0.5));
  std::nth_element(values.begin(), values.begin() + k, values.end());
  return values[k];
}

std::string format_steps(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%.1f", v);
  return text;
}

void draw_bar(LegendImage& out, const ColorKey& key, const Layout& L, const Font* font) {
  const PixelRect bar = out.bar;
  const float lo = tick_value(key, 0);
  for (uint32_t row = 0; row < bar.height; ++row) {
    const float f = bar.height > 1 ? float(bar.height - 1 - row) / float(bar.height - 1) : 1.0f;
    uint8_t rgb[3];
    key_color(key, lo + (key.max - lo) * f, rgb);
    fill(out.image, {bar.x, bar.y + row, bar.width, 1}, rgb);
  }
  // A thin frame, so the white of a difference bar's middle shows against the background.
  fill(out.image, {bar.x - 1, bar.y - 1, bar.width + 2, 1}, kInk);
  fill(out.image, {bar.x - 1, bar.y + bar.height, bar.width + 2, 1}, kInk);
  fill(out.image, {bar.x - 1, bar.y, 1, bar.height}, kInk);
  fill(out.image, {bar.x + bar.width, bar.y, 1, bar.height}, kInk);
  const uint32_t tick_x = bar.x + bar.width + 1, tick_len = uint32_t(std::max(2, L.margin / 2));
  for (int k = 0; k < kTicks; ++k) {
    const uint32_t y = bar.y + uint32_t(std::lround(float(bar.height - 1) * (1.0f - float(k) / float(kTicks - 1))));
    fill(out.image, {tick_x, y, tick_len, 1}, kInk);
    if (font)
      font->draw(out.image, int(tick_x + tick_len + 2), int(y) - int(L.text_px * 0.55f), tick_label(key, k), L.text_px,
                 kInk);
  }
  if (font) font->draw(out.image, int(bar.x) - 1, L.margin / 2, key.heading, L.text_px, kInk);
}

}  // namespace

void key_color(const ColorKey& key, float value, uint8_t rgb[3]) {
  if (key.map == ColorKey::Map::steps)
    heat_color(value, key.max, rgb);
  else
    diverging_color(value, key.max, rgb);
}

LegendImage add_legend(const Image& picture, const ColorKey& key, const std::vector<std::string>& caption,
                       const Font* font) {
  if (picture.width == 0 || picture.height == 0 || picture.rgb.size() != size_t(picture.width) * picture.height * 3)
    throw Error("legend: empty or malformed picture");
  if (!(key.max > 0.0f) || !std::isfinite(key.max)) throw Error("legend: the scale's top must be positive and finite");
  const Layout L = layout_for(picture.height);
  int labels = 0;
  if (font) {
    labels = font->text_width(key.heading, L.text_px) - L.bar_width - L.margin;
    for (int k = 0; k < kTicks; ++k) labels = std::max(labels, font->text_width(tick_label(key, k), L.text_px));
  } else {
    labels = int(L.text_px * 2.0f);
  }
  const uint32_t panel = uint32_t(L.margin + L.bar_width + L.margin / 2 + 2 + labels + L.margin);
  const uint32_t strip = uint32_t(int(caption.size()) * L.line + L.margin);

  LegendImage out;
  out.has_text = font != nullptr;
  out.picture = {0, 0, picture.width, picture.height};
  out.image = Image{picture.width + panel, picture.height + strip, {}};
  out.image.rgb.assign(size_t(out.image.width) * out.image.height * 3, 0);
  fill(out.image, {0, 0, out.image.width, out.image.height}, kBackground);
  for (uint32_t y = 0; y < picture.height; ++y)
    std::copy_n(&picture.rgb[3 * size_t(y) * picture.width], 3 * size_t(picture.width),
                &out.image.rgb[3 * size_t(y) * out.image.width]);

  // The bar under its heading, with room for half a label line at each end.
  const uint32_t top = uint32_t(L.margin / 2 + L.line), bottom_room = uint32_t(L.margin);
  const uint32_t bar_height = picture.height > top + bottom_room + 2 ? picture.height - top - bottom_room : 2;
  out.bar = {picture.width + uint32_t(L.margin), top, uint32_t(L.bar_width), bar_height};
  draw_bar(out, key, L, font);

  out.caption = {0, picture.height, out.image.width, strip};
  if (font)
    for (size_t i = 0; i < caption.size(); ++i)
      font->draw(out.image, L.margin, int(picture.height) + L.margin / 2 + int(i) * L.line, caption[i], L.text_px, kInk);
  return out;
}

float shared_heat_scale(const std::vector<const std::vector<TraceCounters>*>& maps, double percentile) {
  std::vector<float> steps;
  for (const auto* map : maps)
    for (const TraceCounters& c : *map) steps.push_back(float(c.steps));
  return round_up_scale(percentile_of(steps, percentile));
}

float difference_scale(const std::vector<TraceCounters>& a, const std::vector<TraceCounters>& b, double percentile) {
  if (a.size() != b.size()) throw Error("difference scale: images of different sizes");
  std::vector<float> diff(a.size());
  for (size_t i = 0; i < a.size(); ++i) diff[i] = std::fabs(float(b[i].steps) - float(a[i].steps));
  return round_up_scale(percentile_of(diff, percentile));
}

double mean_steps(const std::vector<TraceCounters>& counters) {
  double sum = 0.0;
  for (const TraceCounters& c : counters) sum += c.steps;
  return counters.empty() ? 0.0 : sum / double(counters.size());
}

LegendImage heatmap_with_legend(const std::vector<TraceCounters>& counters, uint32_t width, uint32_t height,
                                float max_steps, const std::string& name, const Font* font) {
  ColorKey key;
  key.max = max_steps;
  key.heading = "steps";
  return add_legend(heatmap_image(counters, width, height, max_steps), key,
                    {name, "mean " + format_steps(mean_steps(counters)) + " traversal steps per pixel"}, font);
}

LegendImage difference_with_legend(const std::vector<TraceCounters>& a, const std::vector<TraceCounters>& b,
                                   uint32_t width, uint32_t height, float range, const std::string& name,
                                   const Font* font) {
  ColorKey key;
  key.map = ColorKey::Map::difference;
  key.max = range;
  key.heading = "\u0394 steps";
  const double mean = mean_steps(b) - mean_steps(a);
  return add_legend(difference_image(a, b, width, height, range), key,
                    {name, "mean " + std::string(mean > 0 ? "+" : "") + format_steps(mean) +
                               " steps per pixel; blue: fewer steps, red: more"},
                    font);
}

float write_heatmaps(const std::vector<HeatmapFile>& maps, uint32_t width, uint32_t height, const Font* font) {
  std::vector<const std::vector<TraceCounters>*> all;
  for (const HeatmapFile& m : maps) all.push_back(m.counters);
  const float max_steps = shared_heat_scale(all);
  for (const HeatmapFile& m : maps)
    write_png(m.file, heatmap_with_legend(*m.counters, width, height, max_steps, m.name, font).image);
  return max_steps;
}

}  // namespace bvhopt
