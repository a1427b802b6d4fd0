// Images: PNGs decode (stb_image) with the right size and the colours mean what they say.
#include <gtest/gtest.h>
#include <stb/stb_image.h>
#include <unistd.h>

#include <filesystem>

#include "bvhopt/build.h"
#include "bvhopt/error.h"
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
  // A tree compared with itself is white everywhere.
  const Decoded same = decode(dir / "same.png");
  for (uint8_t v : same.rgb) ASSERT_EQ(v, 255);
  fs::remove_all(dir);

  EXPECT_THROW(write_png(dir / "missing_folder" / "x.png", heatmap_image(ca, 64, 48)), Error);
  EXPECT_THROW(heatmap_image(ca, 10, 10), Error);
}

}  // namespace
}  // namespace bvhopt
