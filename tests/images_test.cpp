// Images: PNGs decode (stb_image) with the right size and the colours mean what they say.
#include <gtest/gtest.h>
#include <stb/stb_image.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <optional>

#include "bvhopt/build.h"
#include "bvhopt/error.h"
#include "bvhopt/font.h"
#include "bvhopt/image_legend.h"
#include "bvhopt/images.h"
#include "bvhopt/png_file.h"
#include "bvhopt/ray_measure.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/references.h"
#include "bvhopt/testing/flatten_for_tracing.h"
#include "test_support.h"

namespace bvhopt {
namespace {

namespace fs = std::filesystem;

struct Decoded {
  int w = 0, h = 0, channels = 0;
  std::vector<uint8_t> rgb;
};

Decoded decode(const fs::path& p) {
  Decoded d;
  unsigned char* data = stbi_load(p.c_str(), &d.w, &d.h, &d.channels, 3);
  if (data) {
    d.rgb.assign(data, data + size_t(d.w) * d.h * 3);
    stbi_image_free(data);
  }
  return d;
}

TEST(Images, HeatScaleIsFixedAndMonotoneInRedness) {
  uint8_t lo[3], mid[3], hi[3], beyond[3];
  heat_color(0.0f, 100.0f, lo);
  heat_color(50.0f, 100.0f, mid);
  heat_color(100.0f, 100.0f, hi);
  heat_color(400.0f, 100.0f, beyond);
  EXPECT_GT(lo[2], lo[0]);  // blue at zero
  EXPECT_GT(hi[0], hi[2]);  // red at the top
  EXPECT_GT(hi[0], hi[1]);
  EXPECT_EQ(std::vector<uint8_t>(hi, hi + 3), std::vector<uint8_t>(beyond, beyond + 3));
  EXPECT_GT(mid[1], mid[2]);  // green in the middle
}

TEST(Images, HeatmapShadedAndDifferenceDecodeWithTheRightSize) {
  const Mesh mesh = testing::random_mesh(2000, 3, true);
  const PrimitiveRefs refs = make_references(mesh);
  BuildOptions a_opt, b_opt;
  b_opt.kind = BuilderKind::spatial_median;
  const Tracer a(flatten_for_tracing(build_bvh(refs, a_opt), refs), mesh);
  const Tracer b(flatten_for_tracing(build_bvh(refs, b_opt), refs), mesh);
  Camera cam = default_camera(mesh, a, 64, 48);
  const std::vector<Ray> rays = camera_rays(cam);
  std::vector<Hit> hits_a, hits_b;
  std::vector<TraceCounters> ca, cb;
  trace_rays(a, rays, RayQuery::closest, hits_a, &ca);
  trace_rays(b, rays, RayQuery::closest, hits_b, &cb);

  const fs::path dir = fs::temp_directory_path() / ("bvhopt_images_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  write_png(dir / "heat.png", heatmap_image(ca, 64, 48));
  write_png(dir / "shaded.png", shaded_image(mesh, rays, hits_a, 64, 48));
  write_png(dir / "diff.png", difference_image(ca, cb, 64, 48));
  write_png(dir / "same.png", difference_image(ca, ca, 64, 48));

  for (const char* name : {"heat.png", "shaded.png", "diff.png", "same.png"}) {
    const Decoded d = decode(dir / name);
    EXPECT_EQ(d.w, 64) << name;
    EXPECT_EQ(d.h, 48) << name;
  }
  // The heat map shows exactly the per-pixel colour of the steps.
  const Decoded heat = decode(dir / "heat.png");
  for (size_t i = 0; i < ca.size(); ++i) {
    uint8_t c[3];
    heat_color(float(ca[i].steps), 100.0f, c);
    ASSERT_EQ(heat.rgb[3 * i], c[0]);
    ASSERT_EQ(heat.rgb[3 * i + 2], c[2]);
  }
  // Shaded: black exactly where the ray missed.
  const Decoded shaded = decode(dir / "shaded.png");
  size_t hits = 0;
  for (size_t i = 0; i < hits_a.size(); ++i) {
    EXPECT_EQ(shaded.rgb[3 * i] == 0, !hits_a[i].hit());
    hits += hits_a[i].hit();
  }
  EXPECT_GT(hits, 0u);
  // A tree compared with itself is white (the diverging map's neutral colour) everywhere.
  const Decoded same = decode(dir / "same.png");
  for (uint8_t v : same.rgb) ASSERT_EQ(v, 255);
  fs::remove_all(dir);

  EXPECT_THROW(write_png(dir / "missing_folder" / "x.png", heatmap_image(ca, 64, 48)), Error);
  EXPECT_THROW(heatmap_image(ca, 10, 10), Error);
}

// The diverging map is symmetric: -d is +d with red and blue swapped, zero is white, and
// the colour moves away from white as |d| grows.
TEST(Images, DivergingMapIsSymmetricWithWhiteAtZero) {
  uint8_t zero[3];
  diverging_color(0.0f, 40.0f, zero);
  EXPECT_EQ(std::vector<uint8_t>(zero, zero + 3), std::vector<uint8_t>({255, 255, 255}));
  int previous_distance = 0;
  for (float d = 0.5f; d <= 60.0f; d += 0.5f) {
    uint8_t pos[3], neg[3];
    diverging_color(d, 40.0f, pos);
    diverging_color(-d, 40.0f, neg);
    ASSERT_EQ(pos[0], neg[2]) << d;
    ASSERT_EQ(pos[1], neg[1]) << d;
    ASSERT_EQ(pos[2], neg[0]) << d;
    EXPECT_GT(pos[0], pos[2]) << "positive differences are red: " << d;
    const int distance = 3 * 255 - pos[0] - pos[1] - pos[2];
    EXPECT_GE(distance, previous_distance) << d;
    previous_distance = distance;
  }
  uint8_t full[3], beyond[3];
  diverging_color(40.0f, 40.0f, full);
  diverging_color(400.0f, 40.0f, beyond);
  EXPECT_EQ(std::vector<uint8_t>(full, full + 3), std::vector<uint8_t>(beyond, beyond + 3));
}

std::vector<TraceCounters> steps_of(std::vector<uint32_t> steps) {
  std::vector<TraceCounters> out(steps.size());
  for (size_t i = 0; i < steps.size(); ++i) out[i].steps = steps[i];
  return out;
}

const uint8_t* pixel(const Image& img, uint32_t x, uint32_t y) { return &img.rgb[3 * (size_t(y) * img.width + x)]; }

// Pixels of `r` darker than mid grey: text or tick marks.
size_t dark_pixels(const Image& img, const PixelRect& r) {
  size_t n = 0;
  for (uint32_t y = r.y; y < r.y + r.height; ++y)
    for (uint32_t x = r.x; x < r.x + r.width; ++x) {
      const uint8_t* p = pixel(img, x, y);
      n += int(p[0]) + p[1] + p[2] < 3 * 128;
    }
  return n;
}

// The value of the key whose colour is nearest to `rgb`, searched over the key's range.
float nearest_value(const ColorKey& key, const uint8_t* rgb, float lo) {
  float best = lo, best_error = 1e9f;
  for (int i = 0; i <= 2000; ++i) {
    const float v = lo + (key.max - lo) * float(i) / 2000.0f;
    uint8_t c[3];
    key_color(key, v, c);
    const float e = std::fabs(float(c[0]) - rgb[0]) + std::fabs(float(c[1]) - rgb[1]) + std::fabs(float(c[2]) - rgb[2]);
    if (e < best_error) best = v, best_error = e;
  }
  return best;
}

// Reads the bar from top to bottom: each row's colour is the key's, and the values it
// shows fall monotonically from the top value to the bottom one.
void expect_monotone_bar(const LegendImage& legend, const ColorKey& key) {
  const float lo = key.map == ColorKey::Map::steps ? 0.0f : -key.max;
  const uint32_t x = legend.bar.x + legend.bar.width / 2;
  ASSERT_GE(legend.bar.height, 8u);
  float previous = 1e9f;
  for (uint32_t row = 0; row < legend.bar.height; ++row) {
    const float v = nearest_value(key, pixel(legend.image, x, legend.bar.y + row), lo);
    EXPECT_LE(v, previous + 1e-3f * key.max) << "row " << row;
    previous = v;
    if (row == 0) {
      EXPECT_NEAR(v, key.max, 0.02f * (key.max - lo));
    }
    if (row + 1 == legend.bar.height) {
      EXPECT_NEAR(v, lo, 0.02f * (key.max - lo));
    }
  }
}

TEST(Images, HeatmapLegendHasAMonotoneBarAndACaption) {
  std::string problem;
  const std::optional<Font> font = Font::load_default(problem);
  ASSERT_TRUE(font) << problem << " (scripts/install-deps.sh installs fonts-dejavu-core)";
  const uint32_t w = 160, h = 120;
  std::vector<uint32_t> steps(size_t(w) * h);
  for (size_t i = 0; i < steps.size(); ++i) steps[i] = uint32_t(i % 97);
  const auto counters = steps_of(steps);
  const LegendImage legend = heatmap_with_legend(counters, w, h, 80.0f, "sweep  \u00b7  test scene", &*font);
  ASSERT_TRUE(legend.has_text);
  // The picture is untouched at the top left.
  const Image bare = heatmap_image(counters, w, h, 80.0f);
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < w; ++x)
      ASSERT_EQ(std::vector<uint8_t>(pixel(bare, x, y), pixel(bare, x, y) + 3),
                std::vector<uint8_t>(pixel(legend.image, x, y), pixel(legend.image, x, y) + 3));
  EXPECT_GT(legend.image.width, w);
  EXPECT_GT(legend.image.height, h);
  ColorKey key;
  key.max = 80.0f;
  expect_monotone_bar(legend, key);
  // Text in the caption strip and tick labels beside the bar; none without a font.
  EXPECT_GT(dark_pixels(legend.image, legend.caption), 100u);
  const PixelRect labels{legend.bar.x + legend.bar.width + 1, 0, legend.image.width - legend.bar.x - legend.bar.width - 1,
                         h};
  EXPECT_GT(dark_pixels(legend.image, labels), 40u);
  const LegendImage plain = heatmap_with_legend(counters, w, h, 80.0f, "sweep", nullptr);
  EXPECT_FALSE(plain.has_text);
  EXPECT_EQ(dark_pixels(plain.image, plain.caption), 0u);
  // A longer caption draws more ink: the pixels are the text.
  const LegendImage longer = heatmap_with_legend(counters, w, h, 80.0f, "sweep  \u00b7  test scene  \u00b7  more", &*font);
  EXPECT_GT(dark_pixels(longer.image, longer.caption), dark_pixels(legend.image, legend.caption));
}

TEST(Images, DifferenceLegendIsDivergingWithWhiteInTheMiddle) {
  const uint32_t w = 64, h = 200;
  std::vector<uint32_t> a(size_t(w) * h, 50), b(size_t(w) * h);
  for (size_t i = 0; i < b.size(); ++i) b[i] = uint32_t(20 + i % 61);
  const LegendImage legend = difference_with_legend(steps_of(a), steps_of(b), w, h, 30.0f, "b minus a", nullptr);
  ColorKey key;
  key.map = ColorKey::Map::difference;
  key.max = 30.0f;
  expect_monotone_bar(legend, key);
  const uint32_t x = legend.bar.x + legend.bar.width / 2;
  const uint8_t* top = pixel(legend.image, x, legend.bar.y);
  const uint8_t* bottom = pixel(legend.image, x, legend.bar.y + legend.bar.height - 1);
  EXPECT_GT(top[0], top[2]);        // red: more steps
  EXPECT_GT(bottom[2], bottom[0]);  // blue: fewer
  EXPECT_EQ(top[0], bottom[2]);
  EXPECT_EQ(top[2], bottom[0]);
}

// Both heat maps of a pair share one scale: the 99th percentile of all their pixels,
// rounded up, whichever tree has the larger steps; their bars are the same pixels.
TEST(Images, HeatmapPairSharesOneScale) {
  const uint32_t w = 100, h = 80;
  std::vector<uint32_t> few(size_t(w) * h), many(size_t(w) * h);
  for (size_t i = 0; i < few.size(); ++i) {
    few[i] = uint32_t(i % 30);
    many[i] = uint32_t(i % 170);
  }
  const auto a = steps_of(few), b = steps_of(many);
  const float ab = shared_heat_scale({&a, &b}), ba = shared_heat_scale({&b, &a});
  EXPECT_EQ(ab, ba);
  EXPECT_GE(ab, 160.0f);  // above the 99th percentile of both together
  EXPECT_LE(ab, 200.0f);  // and only rounded up to a round number
  EXPECT_EQ(shared_heat_scale({&a}), 30.0f);
  const fs::path dir = fs::temp_directory_path() / ("bvhopt_pair_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  EXPECT_EQ(write_heatmaps({{&a, "a", dir / "a.png"}, {&b, "b", dir / "b.png"}}, w, h, nullptr), ab);
  const Decoded da = decode(dir / "a.png"), db = decode(dir / "b.png");
  ASSERT_EQ(da.w, db.w);
  ASSERT_EQ(da.h, db.h);
  const LegendImage layout = heatmap_with_legend(a, w, h, ab, "a", nullptr);
  ASSERT_EQ(uint32_t(da.w), layout.image.width);
  for (uint32_t row = 0; row < layout.bar.height; ++row) {
    const size_t p = 3 * (size_t(layout.bar.y + row) * da.w + layout.bar.x + layout.bar.width / 2);
    ASSERT_EQ(da.rgb[p], db.rgb[p]) << row;
    ASSERT_EQ(da.rgb[p + 2], db.rgb[p + 2]) << row;
  }
  fs::remove_all(dir);
  EXPECT_EQ(difference_scale(a, a), 1.0f);
  std::vector<uint32_t> zero(size_t(w) * h, 0), ramp(size_t(w) * h);
  for (size_t i = 0; i < ramp.size(); ++i) ramp[i] = uint32_t(i % 100);
  EXPECT_EQ(difference_scale(steps_of(zero), steps_of(ramp)), 100.0f);  // |difference| up to 99
}

}  // namespace
}  // namespace bvhopt
