// bvhopt trace / render / demo with --layout: every layout traces the same rays, passes the
// brute-force check, and the JSON says which layout and which ISA ran; BVHOPT_ISA forces one.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "bvhopt/ray_file.h"
#include "bvhopt/wide_tracer.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace {

using CliRun = bvhopt::testing::ProgramTest::Result;
using WideCli = bvhopt::testing::ProgramTest;

TEST_F(WideCli, TraceEveryLayoutAgreesWithBruteForceAndReportsTheIsa) {
  const fs::path bvh = dir_ / "s.bvh";
  ASSERT_EQ(run("build 'builtin?triangles=4000' --leaf-size 4 -o " + bvh.string()).exit_code, 0);
  double hit_rate = -1.0;
  for (const char* layout : {"bvh2", "bvh4", "bvh8"}) {
    CliRun r = run("trace " + bvh.string() + " --scene 'builtin?triangles=4000' --rays random --count 3000 --check 3000 "
                   "--repeats 1 --json --layout " + layout);
    ASSERT_EQ(r.exit_code, 0) << layout << ": " << r.err;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j["layout"], layout);
    EXPECT_EQ(j["brute_force"]["mismatches"], 0) << layout;
    EXPECT_EQ(j["brute_force"]["checked"], 3000);
    if (std::string(layout) == "bvh2") {
      EXPECT_EQ(j["isa"], "sse");
      EXPECT_EQ(j["layout_seconds"].get<double>(), 0.0);
    } else {
      EXPECT_EQ(j["isa"], std::string(bvhopt::isa_name(bvhopt::default_isa())));
      EXPECT_GT(j["layout_seconds"].get<double>(), 0.0);
    }
    // The same rays and, whatever the triangle test, the same hits or misses.
    if (hit_rate < 0) hit_rate = j["hit_rate"].get<double>();
    EXPECT_NEAR(j["hit_rate"].get<double>(), hit_rate, 0.002) << layout;
  }
}

// --rays-per-call times the rays in calls of that many (1: one ray a call) and the JSON and
// text say so; a bad count is an error naming the option. (That calls of any size give the
// same hits is Trace.RaysPerCallGiveTheHitsOfOneRayACall's, on the library function.)
TEST_F(WideCli, TraceTimesRaysInCallsOfTheAskedSize) {
  const fs::path bvh = dir_ / "s.bvh";
  ASSERT_EQ(run("build 'builtin?triangles=4000' -o " + bvh.string()).exit_code, 0);
  for (const char* rays : {"random", "shadow"}) {
    for (const char* per_call : {"0", "1", "5"}) {
      CliRun r = run("trace " + bvh.string() + " --scene 'builtin?triangles=4000' --rays " + rays +
                     " --count 2000 --repeats 1 --json --rays-per-call " + per_call);
      ASSERT_EQ(r.exit_code, 0) << rays << " " << per_call << ": " << r.err;
      const auto j = nlohmann::json::parse(r.out);
      EXPECT_EQ(j["rays_per_call"], std::stoi(per_call));
      EXPECT_EQ(j["brute_force"]["mismatches"], 0);
      EXPECT_GT(j["threads_1"]["rays_per_second"].get<double>(), 0.0);
    }
  }
  CliRun text = run("trace " + bvh.string() + " --scene 'builtin?triangles=4000' --rays random --count 500 --repeats 1 "
                    "--rays-per-call 1");
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find("calls of 1 ray\n"), std::string::npos) << text.out;
  CliRun bad = run("trace " + bvh.string() + " --scene 'builtin?triangles=4000' --rays-per-call -3");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.err.find("--rays-per-call"), std::string::npos) << bad.err;
}

// --closest-hit-order: ambient occlusion rays nearest first or in slot order where they
// mostly miss give the same answers (the hit rate, and no disagreement with brute force), the
// JSON says which ran, the default is auto; an unknown value is refused by name.
TEST_F(WideCli, TraceOrdersClosestHitRaysAsAsked) {
  const fs::path bvh = dir_ / "s.bvh";
  const std::string scene = " --scene 'builtin?triangles=4000'";
  ASSERT_EQ(run("build 'builtin?triangles=4000' -o " + bvh.string()).exit_code, 0);
  nlohmann::json j[3];
  const char* asked[3] = {"", " --closest-hit-order auto", " --closest-hit-order near"};
  for (int i = 0; i < 3; ++i) {
    CliRun r = run("trace " + bvh.string() + scene + " --rays ao --count 3000 --check 3000 --repeats 1 --json" + asked[i]);
    ASSERT_EQ(r.exit_code, 0) << asked[i] << ": " << r.err;
    j[i] = nlohmann::json::parse(r.out);
    EXPECT_EQ(j[i]["brute_force"]["mismatches"], 0) << asked[i];
    EXPECT_EQ(j[i]["closest_hit_order"], i == 2 ? "near" : "auto");
    EXPECT_EQ(j[i]["hit_rate"], j[0]["hit_rate"]);
  }
  EXPECT_GT(j[0]["hit_rate"].get<double>(), 0.0);
  CliRun bad = run("trace " + bvh.string() + scene + " --rays ao --closest-hit-order far");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.err.find("--closest-hit-order"), std::string::npos) << bad.err;
}

// --any-hit-order: shadow rays in any order give the same answers (the hit rate, and no
// disagreement with brute force), the JSON and the text say which ran, the default is
// 'auto' (the far end, slot order where a batch mostly misses), and the far and near ends
// walk the tree differently; an unknown value is refused by name.
TEST_F(WideCli, TraceSearchesAnyHitRaysFromTheEndAskedFor) {
  const fs::path bvh = dir_ / "s.bvh";
  const std::string scene = " --scene 'builtin?triangles=4000'";
  ASSERT_EQ(run("build 'builtin?triangles=4000' -o " + bvh.string()).exit_code, 0);
  nlohmann::json j[4];
  const char* asked[4] = {"", " --any-hit-order far", " --any-hit-order near", " --any-hit-order auto"};
  const char* named[4] = {"auto", "far", "near", "auto"};
  for (int i = 0; i < 4; ++i) {
    CliRun r = run("trace " + bvh.string() + scene + " --rays shadow --count 3000 --check 3000 --repeats 1 --json" + asked[i]);
    ASSERT_EQ(r.exit_code, 0) << asked[i] << ": " << r.err;
    j[i] = nlohmann::json::parse(r.out);
    EXPECT_EQ(j[i]["brute_force"]["mismatches"], 0) << asked[i];
    EXPECT_EQ(j[i]["any_hit_order"], named[i]);
    EXPECT_EQ(j[i]["hit_rate"], j[0]["hit_rate"]);
  }
  EXPECT_GT(j[0]["hit_rate"].get<double>(), 0.0);
  EXPECT_EQ(j[0]["steps"]["mean"], j[3]["steps"]["mean"]);
  EXPECT_EQ(j[0]["triangle_tests"]["mean"], j[3]["triangle_tests"]["mean"]);
  EXPECT_NE(j[1]["steps"]["mean"].get<double>() + j[1]["triangle_tests"]["mean"].get<double>(),
            j[2]["steps"]["mean"].get<double>() + j[2]["triangle_tests"]["mean"].get<double>());
  CliRun text = run("trace " + bvh.string() + scene + " --rays shadow --count 500 --repeats 1 --any-hit-order near");
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find("(any hit, near end first)"), std::string::npos) << text.out;
  CliRun bad = run("trace " + bvh.string() + scene + " --rays shadow --any-hit-order middle");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.err.find("--any-hit-order"), std::string::npos) << bad.err;
}

// --light places the shadow rays' light: every saved ray ends there, the JSON reports it
// (the default one too, where the default rays end), and moving it changes what is lit.
// --query traces any set as closest-hit or any-hit queries: the same rays hit or miss
// either way, brute force agrees, and a saved file carries the query that was traced.
TEST_F(WideCli, TraceTakesTheShadowLightAndTheQuery) {
  const fs::path bvh = dir_ / "s.bvh";
  const std::string scene = " --scene 'builtin?triangles=4000'";
  ASSERT_EQ(run("build 'builtin?triangles=4000' -o " + bvh.string()).exit_code, 0);
  const std::string shadow = "trace " + bvh.string() + scene + " --rays shadow --count 2000 --check 2000 --repeats 1 --json";
  auto ends_at = [](const fs::path& file, const bvhopt::Vec3& light) {
    const bvhopt::RaySet set = bvhopt::read_ray_file(file);
    EXPECT_EQ(set.query, bvhopt::RayQuery::any);
    size_t far = 0;
    for (const bvhopt::Ray& r : set.rays)
      if (bvhopt::length(r.org + r.dir - light) > 1e-3f * (1.0f + bvhopt::length(light))) ++far;
    return set.rays.size() == 2000 && far == 0;
  };
  double hit_rate[2];
  for (int i = 0; i < 2; ++i) {
    const fs::path rays = dir_ / ("shadow" + std::to_string(i) + ".rays");
    CliRun r = run(shadow + " --save-rays " + rays.string() + (i ? " --light 0.5,40,-0.25" : ""));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j["brute_force"]["mismatches"], 0);
    ASSERT_TRUE(j.contains("light")) << r.out;
    const bvhopt::Vec3 light(j["light"][0].get<float>(), j["light"][1].get<float>(), j["light"][2].get<float>());
    if (i) {
      EXPECT_EQ(light, bvhopt::Vec3(0.5f, 40.0f, -0.25f));
    }
    EXPECT_TRUE(ends_at(rays, light)) << (i ? "given" : "default") << " light";
    hit_rate[i] = j["hit_rate"].get<double>();
  }
  EXPECT_NE(hit_rate[0], hit_rate[1]);

  const std::string ao = "trace " + bvh.string() + scene + " --rays ao --count 3000 --check 3000 --repeats 1 --json";
  const fs::path any_rays = dir_ / "ao_any.rays";
  CliRun closest = run(ao), any = run(ao + " --query any --save-rays " + any_rays.string());
  ASSERT_EQ(closest.exit_code, 0) << closest.err;
  ASSERT_EQ(any.exit_code, 0) << any.err;
  const auto jc = nlohmann::json::parse(closest.out), ja = nlohmann::json::parse(any.out);
  EXPECT_EQ(jc["query"], "closest");
  EXPECT_EQ(ja["query"], "any");
  EXPECT_FALSE(ja.contains("light"));
  EXPECT_EQ(ja["brute_force"]["mismatches"], 0);
  EXPECT_GT(jc["hit_rate"].get<double>(), 0.0);
  EXPECT_EQ(ja["hit_rate"], jc["hit_rate"]);
  EXPECT_NE(ja["triangle_tests"]["mean"], jc["triangle_tests"]["mean"]);  // any hit stops at the first
  EXPECT_EQ(bvhopt::read_ray_file(any_rays).query, bvhopt::RayQuery::any);
  CliRun back = run("trace " + bvh.string() + scene + " --load-rays " + any_rays.string() +
                    " --query closest --check 3000 --repeats 1 --json");
  ASSERT_EQ(back.exit_code, 0) << back.err;
  const auto jb = nlohmann::json::parse(back.out);
  EXPECT_EQ(jb["query"], "closest");
  EXPECT_EQ(jb["hit_rate"], jc["hit_rate"]);
  EXPECT_EQ(jb["triangle_tests"]["mean"], jc["triangle_tests"]["mean"]);

  struct Bad { std::string args, says; };
  for (const Bad& bad : {Bad{" --rays ao --light 1,2,3", "only shadow rays have a light"},
                         Bad{" --load-rays " + any_rays.string() + " --light 1,2,3", "--load-rays"},
                         Bad{" --rays shadow --light 1,2", "'1,2' is not X,Y,Z"},
                         Bad{" --rays shadow --light nan,1,2", "--light"},
                         Bad{" --rays shadow --query first", "--query"}}) {
    CliRun r = run("trace " + bvh.string() + scene + " --count 100 --repeats 1" + bad.args);
    EXPECT_NE(r.exit_code, 0) << bad.args;
    EXPECT_NE(r.err.find(bad.says), std::string::npos) << bad.args << ": " << r.err;
  }
}

// --wide-block sets the collapse's c_blk: the layout still traces exactly, the JSON says
// which cost ran (the library's default when not given), and a dearer leaf block gives a
// dearer optimal collapse (its cost, nodes + c_blk * blocks, grows with c_blk wherever a
// leaf block is left).
TEST_F(WideCli, TraceAndExportTakeTheCollapsesBlockCost) {
  const fs::path bvh = dir_ / "s.bvh";
  const std::string scene = " --scene 'builtin?triangles=4000'";
  ASSERT_EQ(run("build 'builtin?triangles=4000' -o " + bvh.string()).exit_code, 0);
  for (const char* block : {"", " --wide-block 2"}) {
    CliRun r = run("trace " + bvh.string() + scene + " --rays random --count 2000 --check 2000 --repeats 1 --json" + block);
    ASSERT_EQ(r.exit_code, 0) << block << ": " << r.err;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j["brute_force"]["mismatches"], 0) << block;
    EXPECT_EQ(j["wide_block_cost"].get<double>(), *block ? 2.0 : bvhopt::WideCostModel{}.block);
  }
  double sah[2];
  for (int i = 0; i < 2; ++i) {
    const fs::path out = dir_ / ("w" + std::to_string(i) + ".flat");
    CliRun r = run("export " + bvh.string() + scene + " --json -o " + out.string() + (i ? " --wide-block 2" : ""));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto j = nlohmann::json::parse(r.out);
    sah[i] = j["wide_sah"].get<double>();
    EXPECT_EQ(j["wide_block_cost"].get<double>(), i ? 2.0 : bvhopt::WideCostModel{}.block);
  }
  EXPECT_GT(sah[1], sah[0]);
  for (const char* bad : {"0", "-1", "nan"}) {
    CliRun r = run("trace " + bvh.string() + scene + " --rays random --count 10 --wide-block " + bad);
    EXPECT_NE(r.exit_code, 0) << bad;
    EXPECT_NE(r.err.find("--wide-block"), std::string::npos) << r.err;
  }
}

TEST_F(WideCli, StatsReportsTheWideSahCosts) {
  const fs::path bvh = dir_ / "s.bvh";
  ASSERT_EQ(run("build 'builtin?triangles=4000' -o " + bvh.string()).exit_code, 0);
  CliRun r = run("stats --json " + bvh.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  const double w4 = j["wide_sah_bvh4"].get<double>(), w8 = j["wide_sah_bvh8"].get<double>();
  EXPECT_GT(w8, 1.0);
  // Every 4-wide collapse is also an 8-wide one, so the optimal 8-wide costs no more.
  EXPECT_LE(w8, w4 * (1.0 + 1e-6));
  EXPECT_EQ(j["wide_block_cost"].get<double>(), bvhopt::WideCostModel{}.block);
  // --wide-block: the costs of the collapses under that c_blk, dearer for a dearer block, and
  // the same figures as export's for the layout it writes.
  CliRun dear = run("stats --json --wide-block 2 " + bvh.string());
  ASSERT_EQ(dear.exit_code, 0) << dear.err;
  const auto d = nlohmann::json::parse(dear.out);
  EXPECT_EQ(d["wide_block_cost"].get<double>(), 2.0);
  EXPECT_GT(d["wide_sah_bvh8"].get<double>(), w8);
  EXPECT_GT(d["wide_sah_bvh4"].get<double>(), w4);
  CliRun e = run("export " + bvh.string() + " --scene 'builtin?triangles=4000' --json --wide-block 2 -o " +
                 (dir_ / "w.flat").string());
  ASSERT_EQ(e.exit_code, 0) << e.err;
  EXPECT_NEAR(nlohmann::json::parse(e.out)["wide_sah"].get<double>(), d["wide_sah_bvh8"].get<double>(),
              1e-9 * d["wide_sah_bvh8"].get<double>());
  CliRun text = run("stats --wide-block 2 " + bvh.string());
  EXPECT_NE(text.out.find("c_blk 2)"), std::string::npos) << text.out;
  EXPECT_NE(run("stats --wide-block 0 " + bvh.string()).exit_code, 0);
}

TEST_F(WideCli, ForcedIsaRunsAndAMissingOrUnknownOneIsAnError) {
  const fs::path bvh = dir_ / "s.bvh";
  ASSERT_EQ(run("build 'builtin?triangles=4000' -o " + bvh.string()).exit_code, 0);
  const std::string trace = "trace " + bvh.string() + " --scene 'builtin?triangles=4000' --rays random --count 500 "
                            "--check 500 --repeats 1 --json --layout bvh8";
  for (bvhopt::Isa isa : {bvhopt::Isa::sse42, bvhopt::Isa::avx2, bvhopt::Isa::avx512}) {
    const std::string name(bvhopt::isa_name(isa));
    ::setenv("BVHOPT_ISA", name.c_str(), 1);
    CliRun r = run(trace);
    ::unsetenv("BVHOPT_ISA");
    if (bvhopt::isa_supported(isa)) {
      ASSERT_EQ(r.exit_code, 0) << name << ": " << r.err;
      EXPECT_EQ(nlohmann::json::parse(r.out)["isa"], name);
    } else {
      EXPECT_NE(r.exit_code, 0) << name;
      EXPECT_NE(r.err.find("does not support"), std::string::npos) << r.err;
    }
  }
  ::setenv("BVHOPT_ISA", "neon", 1);
  CliRun r = run(trace);
  ::unsetenv("BVHOPT_ISA");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("BVHOPT_ISA=neon"), std::string::npos) << r.err;
}

TEST_F(WideCli, RenderAndDemoTakeTheLayout) {
  const fs::path bvh = dir_ / "s.bvh";
  ASSERT_EQ(run("build 'builtin?triangles=4000' -o " + bvh.string()).exit_code, 0);
  for (const char* layout : {"bvh2", "bvh8"}) {
    CliRun r = run("render " + bvh.string() + " --scene 'builtin?triangles=4000' --width 64 --height 48 --json --layout " +
                   layout + " --heatmap " + (dir_ / (std::string(layout) + ".png")).string());
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j["layout"], layout);
    EXPECT_GT(j["mean_steps"].get<double>(), 0.0);
  }
  CliRun d = run("demo --triangles 4000 --rays 2000 --quick --json --layout bvh4 --wide-block 0.5 --images " +
                 (dir_ / "demo").string());
  ASSERT_EQ(d.exit_code, 0) << d.err;
  EXPECT_EQ(nlohmann::json::parse(d.out)["layout"], "bvh4");
  EXPECT_EQ(nlohmann::json::parse(d.out)["wide_block_cost"].get<double>(), 0.5);
  CliRun bad = run("trace " + bvh.string() + " --scene 'builtin?triangles=4000' --layout bvh16");
  EXPECT_NE(bad.exit_code, 0);
}

}  // namespace
