// bvhopt render: the --compare pair shares one scale, the difference and the other tree's
// heat map are written, pictures carry their legend (wider and taller than the rays'
// image) unless --no-legend, and --max-steps keeps a fixed scale.
#include <gtest/gtest.h>
#include <stb/stb_image.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "test_support.h"

namespace fs = std::filesystem;

namespace {

using RenderCli = bvhopt::testing::ProgramTest;

struct Size {
  int w = 0, h = 0;
};
Size png_size(const fs::path& p) {
  Size s;
  int channels = 0;
  if (!stbi_info(p.c_str(), &s.w, &s.h, &channels)) ADD_FAILURE() << "not a PNG: " << p;
  return s;
}

TEST_F(RenderCli, ComparePairSharesOneScaleWithLegends) {
  const std::string scene = "'builtin?triangles=4000'";
  const fs::path sweep = dir_ / "sweep.bvh", median = dir_ / "median.bvh";
  ASSERT_EQ(run("build " + scene + " --builder sweep -o " + sweep.string()).exit_code, 0);
  ASSERT_EQ(run("build " + scene + " --builder object-median -o " + median.string()).exit_code, 0);
  const std::string common = "render " + sweep.string() + " --scene " + scene + " --compare " + median.string() +
                             " --width 160 --height 120 --json --heatmap ";
  auto r = run(common + (dir_ / "a.png").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["scale"], "auto");
  EXPECT_TRUE(j["legend"].get<bool>());
  EXPECT_GE(j["hit_fraction"].get<double>(), 0.99);  // the built-in hall, seen from inside
  EXPECT_GT(j["difference_range"].get<double>(), 0.0);
  // One scale for both: at least the larger tree's mean (the median tree takes more steps).
  EXPECT_GE(j["max_steps"].get<double>(), std::max(j["mean_steps"].get<double>(), j["compare_mean_steps"].get<double>()));
  for (const char* f : {"a.png", "a-other.png", "a-diff.png"}) {
    const Size s = png_size(dir_ / f);
    EXPECT_GT(s.w, 160) << f << ": the colour bar is beside the picture";
    EXPECT_GT(s.h, 120) << f << ": the caption is below it";
  }
  EXPECT_EQ(j["other_heatmap"], (dir_ / "a-other.png").string());

  auto bare = run(common + (dir_ / "b.png").string() + " --no-legend --max-steps 100");
  ASSERT_EQ(bare.exit_code, 0) << bare.err;
  const auto jb = nlohmann::json::parse(bare.out);
  EXPECT_EQ(jb["scale"], "fixed");
  EXPECT_EQ(jb["max_steps"].get<double>(), 100.0);
  EXPECT_EQ(jb["difference_range"].get<double>(), 50.0);
  const Size s = png_size(dir_ / "b.png");
  EXPECT_EQ(s.w, 160);
  EXPECT_EQ(s.h, 120);
}

}  // namespace
