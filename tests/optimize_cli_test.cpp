// End-to-end tests of `bvhopt optimize` (mostly the rotation methods) and `bvhopt bake`: the written file, the
// summary, the cost trace, and errors that name the input.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "bvhopt/bvh_file.h"
#include "bvhopt/cost.h"
#include "bvhopt/leaf_dedup.h"
#include "bvhopt/triangle_cost.h"
#include "bvhopt/validate.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace bvhopt {
namespace {


class OptimizeCli : public testing::ProgramTest {
 protected:
  int run(const std::string& args, std::string* out = nullptr, std::string* err = nullptr) {
    Result r = ProgramTest::run(args);
    if (out) *out = r.out;
    if (err) *err = r.err;
    return r.exit_code;
  }
};

std::vector<std::string> lines(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string l; std::getline(ss, l);) out.push_back(l);
  return out;
}

TEST_F(OptimizeCli, SceneToAnnealedFileWithTraceAndJson) {
  const fs::path bvh = dir_ / "out.bvh", csv = dir_ / "trace.csv";
  std::string out, err;
  ASSERT_EQ(run("optimize 'builtin:atrium?triangles=4000' --method anneal --schedule-passes 60 --seed 3 --threads 2 "
                "--cost-trace " + csv.string() + " --json -o " + bvh.string(),
                &out, &err),
            0)
      << err;
  nlohmann::json j = nlohmann::json::parse(out);
  EXPECT_EQ(j["method"], "anneal");
  EXPECT_FALSE(j.contains("insertion_form"));
  EXPECT_EQ(j["file_method"], "sweep+anneal");
  EXPECT_LT(j["cost_after"].get<double>(), j["cost_before"].get<double>());
  EXPECT_LE(j["ocost"].get<double>(), j["cost_after"].get<double>() + 1e-9);
  EXPECT_GE(j["passes"].get<uint32_t>(), 60u);  // the schedule, then the quench
  EXPECT_GT(j["moves"].get<uint64_t>(), 0u);

  BvhFile file = read_bvh_file(bvh);
  EXPECT_TRUE(validate(file.bvh, file.refs).ok());
  EXPECT_NEAR(sah_cost(file.bvh, file.info.cost), j["cost_after"].get<double>(), 1e-9 * j["cost_after"].get<double>());
  EXPECT_EQ(file.info.method, "sweep+anneal");

  std::vector<std::string> rows = lines(testing::read_text(csv));
  ASSERT_FALSE(rows.empty());
  // Columns only ever added at the end: the first seven as they always were.
  EXPECT_EQ(rows[0], "pass,cost,best_cost,temperature,moves,seconds,stage,stage_name");
  EXPECT_EQ(rows.size(), j["passes"].get<size_t>() + 2);  // header, pass 0 (the input), every pass
  EXPECT_EQ(rows[1].substr(rows[1].size() - 3), ",0,");     // the input: no stage ran yet
  for (size_t i = 2; i < rows.size(); ++i) EXPECT_EQ(rows[i].substr(rows[i].size() - 9), ",0,anneal") << rows[i];
  // One stage, named after the method, with every pass; the seconds add up to the run's.
  ASSERT_EQ(j["stages"].size(), 1u);
  EXPECT_EQ(j["stages"][0]["name"], "anneal");
  EXPECT_EQ(j["stages"][0]["passes"], j["passes"]);
  EXPECT_EQ(j["stages"][0]["cost"], j["cost_after"]);
  EXPECT_NEAR(j["setup_seconds"].get<double>() + j["stages"][0]["seconds"].get<double>() +
                  j["finish_seconds"].get<double>(),
              j["seconds"].get<double>(), 1e-9);
}

TEST_F(OptimizeCli, BvhFileInputHillClimbAndPassLimit) {
  const fs::path a = dir_ / "a.bvh", b = dir_ / "b.bvh";
  ASSERT_EQ(run("optimize 'builtin:atrium?triangles=4000' --method hill-climb --passes 1 -o " + a.string()), 0);
  std::string out;
  ASSERT_EQ(run("optimize " + a.string() + " --method hill-climb --json -o " + b.string(), &out), 0);
  nlohmann::json j = nlohmann::json::parse(out);
  EXPECT_EQ(j["file_method"], "sweep+hill-climb+hill-climb");
  EXPECT_EQ(j["stop_reason"], "converged");
  EXPECT_LE(j["cost_after"].get<double>(), j["cost_before"].get<double>());
  ASSERT_EQ(run("optimize " + a.string() + " --method anneal --passes 1 --json -o " + b.string(), &out), 0);
  j = nlohmann::json::parse(out);
  EXPECT_EQ(j["passes"], 1);
  EXPECT_EQ(j["stop_reason"], "pass limit");
}

TEST_F(OptimizeCli, SameSeedSameFileOnOneAndTwoThreads) {
  const fs::path a = dir_ / "a.bvh", b = dir_ / "b.bvh";
  const std::string common = "optimize 'builtin:atrium?triangles=5000' --method anneal --schedule-passes 50 --seed 9 ";
  ASSERT_EQ(run(common + "--threads 1 -o " + a.string()), 0);
  ASSERT_EQ(run(common + "--threads 2 -o " + b.string()), 0);
  BvhFile fa = read_bvh_file(a), fb = read_bvh_file(b);
  EXPECT_EQ(sah_cost(fa.bvh, fa.info.cost), sah_cost(fb.bvh, fb.info.cost));
  EXPECT_EQ(fa.bvh.ref_indices, fb.bvh.ref_indices);  // compacted depth-first: same tree, same order
}

// A scene is built over its mesh, without references (build_sweep_sah(const Mesh&)), and its
// references are made only for the file: the file must be the one that building first and
// optimizing the built file gives.
TEST_F(OptimizeCli, SceneInputGivesTheFileOfBuildThenOptimize) {
  const fs::path built = dir_ / "built.bvh", from_file = dir_ / "f.bvh", from_scene = dir_ / "s.bvh";
  const std::string scene = "'builtin:atrium?triangles=5000'";
  ASSERT_EQ(run("build " + scene + " -o " + built.string()), 0);
  ASSERT_EQ(run("optimize " + built.string() + " --threads 2 -o " + from_file.string()), 0);
  ASSERT_EQ(run("optimize " + scene + " --threads 2 -o " + from_scene.string()), 0);
  const BvhFile f = read_bvh_file(from_file), s = read_bvh_file(from_scene);
  EXPECT_TRUE(testing::same_nodes(s.bvh, f.bvh));
  EXPECT_EQ(f.refs.triangle_ids, s.refs.triangle_ids);
  EXPECT_EQ(f.refs.boxes, s.refs.boxes);
  EXPECT_EQ(f.info.method, s.info.method);
}

TEST_F(OptimizeCli, DefaultMethodIsInsertionAndTimeBudgetStopsOnTheBestTree) {
  const fs::path a = dir_ / "a.bvh";
  std::string out, err;
  // A budget of 0x the build time stops after the first pass, on a tree no worse than the input.
  ASSERT_EQ(run("optimize 'builtin:atrium?triangles=4000' --time-budget 0.0001x --threads 2 --json -o " + a.string(),
                &out, &err),
            0)
      << err;
  nlohmann::json j = nlohmann::json::parse(out);
  EXPECT_EQ(j["method"], "insertion");
  EXPECT_EQ(j["insertion_form"], "hybrid");  // a small tree: hybrid stays itself
  EXPECT_EQ(j["insertion_rotations"], true);
  EXPECT_EQ(j["insertion_parallel_start"], false);  // only the regional form has one
  EXPECT_EQ(j["stop_reason"], "time limit");
  EXPECT_EQ(j["passes"], 1);
  EXPECT_LE(j["cost_after"].get<double>(), j["cost_before"].get<double>());
  BvhFile file = read_bvh_file(a);
  EXPECT_TRUE(validate(file.bvh, file.refs).ok());
  EXPECT_NEAR(sah_cost(file.bvh, file.info.cost), j["cost_after"].get<double>(), 1e-9 * j["cost_after"].get<double>());
  // A multiple of the build time needs a build; words are no budget; it excludes --time-limit.
  EXPECT_EQ(run("optimize " + a.string() + " --time-budget 2x -o " + (dir_ / "x.bvh").string(), nullptr, &err), 1);
  EXPECT_NE(err.find("build time"), std::string::npos) << err;
  EXPECT_EQ(run("optimize " + a.string() + " --time-budget soon -o " + (dir_ / "x.bvh").string(), nullptr, &err), 1);
  EXPECT_NE(err.find("soon"), std::string::npos) << err;
  EXPECT_NE(run("optimize " + a.string() + " --time-budget 1 --time-limit 1 -o " + (dir_ / "x.bvh").string()), 0);
}

TEST_F(OptimizeCli, BakeBuildsOptimizesAndCollapses) {
  const fs::path a = dir_ / "baked.bvh";
  std::string out, err;
  ASSERT_EQ(run("bake 'builtin:atrium?triangles=4000' --quality best --threads 2 --json -o " + a.string(), &out, &err), 0)
      << err;
  nlohmann::json j = nlohmann::json::parse(out);
  EXPECT_EQ(j["quality"], "best");
  EXPECT_EQ(j["builder"], "sbvh");  // best builds with spatial splits (docs/spatial-splits.md)
  EXPECT_LE(j["references"].get<double>(), 1.3 * j["triangles"].get<double>());
  EXPECT_EQ(j["stop_reason"], "converged");  // best has no budget
  EXPECT_EQ(j["time_budget_seconds"], 0.0);
  EXPECT_LT(j["cost_optimized"].get<double>(), j["cost_built"].get<double>());
  EXPECT_LE(j["cost"].get<double>(), j["cost_optimized"].get<double>());
  EXPECT_GT(j["peak_rss_bytes"].get<uint64_t>(), 0u);
  // Best runs from leaves of one, from the builder's SAH leaves of up to 8, and from those
  // with spatial splits only in nodes of at most 256 references, and keeps the cheapest
  // tree: the reported cost, start and file are that start's.
  ASSERT_EQ(j["starts"].size(), 3u);
  // Each start's optimizer profile: its stages hold every pass, the last ending at the start's
  // optimized cost.
  for (const nlohmann::json& s : j["starts"]) {
    const nlohmann::json& stages = s["optimize_profile"]["stages"];
    ASSERT_FALSE(stages.empty());
    uint32_t passes = 0;
    for (const nlohmann::json& st : stages) passes += st["passes"].get<uint32_t>();
    EXPECT_EQ(passes, s["passes"].get<uint32_t>());
    // The optimizer's tracked sum against the file's cost recomputed from scratch.
    EXPECT_NEAR(stages.back()["cost"].get<double>(), s["cost_optimized"].get<double>(),
                1e-9 * s["cost_optimized"].get<double>());
  }
  EXPECT_EQ(j["starts"][0]["leaf_size"], 1);
  EXPECT_EQ(j["starts"][1]["leaf_size"], 8);
  EXPECT_EQ(j["starts"][2]["leaf_size"], 8);
  EXPECT_EQ(j["starts"][0]["spatial_max"], 0);
  EXPECT_EQ(j["starts"][1]["spatial_max"], 0);
  EXPECT_EQ(j["starts"][2]["spatial_max"], 256);
  // Each start's build reports its splits (as build --json), its references within the budget.
  for (const nlohmann::json& s : j["starts"]) {
    ASSERT_TRUE(s.contains("spatial_split")) << s.dump();
    EXPECT_LE(s["references"].get<size_t>(), s["spatial_split"]["budget_references"].get<size_t>());
    EXPECT_GE(s["spatial_split"]["budget_references"].get<double>(), 1.25 * j["triangles"].get<double>());
    EXPECT_GT(s["spatial_split"]["object_splits"].get<size_t>(), 0u);
    EXPECT_GT(s["spatial_split"]["spatial_splits"].get<size_t>(), 0u);
  }
  const double c1 = j["starts"][0]["cost"].get<double>(), c8 = j["starts"][1]["cost"].get<double>(),
               c256 = j["starts"][2]["cost"].get<double>();
  EXPECT_NE(c256, c8) << "the limited start builds another tree";
  const double cheapest = std::min({c1, c8, c256});
  EXPECT_EQ(j["cost"].get<double>(), cheapest);
  EXPECT_EQ(j["start_leaf_size"], cheapest == c1 ? 1 : 8);
  EXPECT_EQ(j["start_spatial_max"], cheapest == c256 && cheapest < c8 && cheapest < c1 ? 256 : 0);
  // The top level's counts are the kept start's.
  for (const nlohmann::json& s : j["starts"]) {
    if (s["cost"].get<double>() == cheapest) {
      EXPECT_EQ(j["spatial_split"], s["spatial_split"]);
    }
  }
  EXPECT_LT(j["starts"][0]["cost"].get<double>(), j["starts"][0]["cost_optimized"].get<double>());  // collapsing one-triangle leaves gains
  for (const auto& s : j["starts"]) EXPECT_EQ(s["stop_reason"], "converged");
  BvhFile file = read_bvh_file(a);
  // Collapsed leaves keep one reference per triangle: the dropped pieces are in no leaf.
  EXPECT_TRUE(validate_deduplicated(file.bvh, file.refs).ok());
  EXPECT_EQ(file.info.method, "sbvh+insertion+collapse");
  // Each leaf then holds distinct triangles: both costs are the same.
  EXPECT_NEAR(sah_cost(file.bvh, file.info.cost), j["cost"].get<double>(), 1e-9 * j["cost"].get<double>());
  EXPECT_NEAR(sah_cost(file.bvh, file.refs, file.info.cost), j["cost"].get<double>(), 1e-9 * j["cost"].get<double>());
  EXPECT_EQ(file.info.scene_triangles, j["triangles"].get<uint64_t>());

  // One start on request: the same tree as that start of the two (the build is deterministic).
  const fs::path one = dir_ / "one-start.bvh";
  ASSERT_EQ(run("bake 'builtin:atrium?triangles=4000' --quality best --start-leaf-sizes 8 --threads 2 --json -o " +
                    one.string(),
                &out, &err),
            0)
      << err;
  const nlohmann::json j8 = nlohmann::json::parse(out);
  EXPECT_EQ(j8["starts"].size(), 1u);
  EXPECT_EQ(j8["cost"].get<double>(), c8);
  EXPECT_NEAR(sah_cost(read_bvh_file(one).bvh, file.info.cost), c8, 1e-9 * c8);
  // The cheaper start is kept whichever order they run in.
  ASSERT_EQ(run("bake 'builtin:atrium?triangles=4000' --quality best --start-leaf-sizes 8,1 --threads 2 --json -o " +
                    one.string(),
                &out, &err),
            0)
      << err;
  const nlohmann::json jr = nlohmann::json::parse(out);
  EXPECT_EQ(jr["cost"].get<double>(), std::min(c1, c8));
  EXPECT_EQ(jr["start_leaf_size"], c8 < c1 ? 8 : 1);
  EXPECT_NEAR(sah_cost(read_bvh_file(one).bvh, file.info.cost), std::min(c1, c8), 1e-9 * c8);
  EXPECT_NE(run("bake 'builtin:atrium?triangles=4000' --start-leaf-sizes 0 -o " + one.string(), nullptr, &err), 0);
  EXPECT_NE(err.find("start-leaf-sizes"), std::string::npos) << err;
  // --starts names the spatial limit too: the third start alone is that start's tree, as is
  // --start-leaf-sizes with --spatial-max.
  ASSERT_EQ(run("bake 'builtin:atrium?triangles=4000' --quality best --starts 8:256 --threads 2 --json -o " +
                    one.string(),
                &out, &err),
            0)
      << err;
  EXPECT_EQ(nlohmann::json::parse(out)["cost"].get<double>(), c256);
  ASSERT_EQ(run("bake 'builtin:atrium?triangles=4000' --quality best --start-leaf-sizes 8 --spatial-max 256 --threads 2 "
                "--json -o " + one.string(),
                &out, &err),
            0)
      << err;
  EXPECT_EQ(nlohmann::json::parse(out)["cost"].get<double>(), c256);
  // --spatial-max applies to the default starts too: the first two take it, and a start
  // equal to an earlier one runs once.
  ASSERT_EQ(run("bake 'builtin:atrium?triangles=4000' --quality best --spatial-max 256 --threads 2 --json -o " +
                    one.string(),
                &out, &err),
            0)
      << err;
  const nlohmann::json jm = nlohmann::json::parse(out);
  ASSERT_EQ(jm["starts"].size(), 2u);
  EXPECT_EQ(jm["starts"][0]["spatial_max"], 256);
  EXPECT_EQ(jm["starts"][1]["spatial_max"], 256);
  EXPECT_EQ(jm["starts"][1]["cost"].get<double>(), c256);
  for (const char* bad : {"0", "8:", "8:x", ":8", "70000", "8:-1", "8:1:2"}) {
    EXPECT_NE(run("bake 'builtin:atrium?triangles=4000' --starts " + std::string(bad) + " -o " + one.string(), nullptr,
                  &err),
              0)
        << bad;
    EXPECT_NE(err.find("is not LEAF[:SPATIAL_MAX]"), std::string::npos) << bad << ": " << err;
  }
  EXPECT_NE(run("bake 'builtin:atrium?triangles=4000' --starts 8 --start-leaf-sizes 8 -o " + one.string(), nullptr, &err),
            0);
  // The spatial limit means nothing to the sweep builder: best runs its two distinct starts.
  ASSERT_EQ(run("bake 'builtin:atrium?triangles=4000' --quality best --builder sweep --threads 2 --json -o " +
                    one.string(),
                &out, &err),
            0)
      << err;
  EXPECT_EQ(nlohmann::json::parse(out)["starts"].size(), 2u);
  // Nor does it report spatial splits.
  EXPECT_FALSE(nlohmann::json::parse(out).contains("spatial_split"));
  EXPECT_FALSE(nlohmann::json::parse(out)["starts"][1].contains("spatial_split"));

  // What bake writes traces in every layout: its collapse stops at the 64 triangles a wide
  // leaf holds, even where one leaf would cost less (here c_T so high that the whole scene
  // would be one leaf). --max-leaf-size 0 lifts the limit; then only bvh2 traces it.
  const std::string dense = "'builtin:atrium?triangles=4000' --ct 1000 --ci 1 --threads 2 --json -o " + one.string();
  ASSERT_EQ(run("bake " + dense, &out, &err), 0) << err;
  const nlohmann::json jc = nlohmann::json::parse(out);
  EXPECT_EQ(jc["max_leaf_size"], 64);
  BvhFile capped = read_bvh_file(one);
  uint32_t largest = 0;
  for (uint32_t n : capped.bvh.depth_first_order())
    if (capped.bvh.nodes[n].is_leaf()) largest = std::max(largest, capped.bvh.nodes[n].ref_count());
  EXPECT_LE(largest, 64u);
  EXPECT_GT(largest, 32u);  // the limit is what stopped it
  const std::string trace = "trace " + one.string() + " --scene 'builtin:atrium?triangles=4000' --rays random --count 200 "
                            "--repeats 1 --threads 1";
  EXPECT_EQ(run(trace + " --layout bvh8", nullptr, &err), 0) << err;
  ASSERT_EQ(run("bake " + dense + " --max-leaf-size 0", &out, &err), 0) << err;
  EXPECT_LT(nlohmann::json::parse(out)["cost"].get<double>(), jc["cost"].get<double>());
  EXPECT_NE(run(trace + " --layout bvh8", nullptr, &err), 0);
  EXPECT_NE(err.find("--max-leaf-size"), std::string::npos) << err;
  EXPECT_EQ(run(trace + " --layout bvh2", nullptr, &err), 0) << err;

  // Another builder on request, and sweep for the other qualities.
  ASSERT_EQ(run("bake 'builtin:atrium?triangles=4000' --quality fast --json -o " + a.string(), &out, &err), 0) << err;
  EXPECT_EQ(nlohmann::json::parse(out)["builder"], "sweep");
  // fast: the default form without the regional form's parallel first stage (a small tree:
  // hybrid stays itself and has no such stage).
  EXPECT_EQ(nlohmann::json::parse(out)["insertion_form"], "hybrid");
  EXPECT_EQ(nlohmann::json::parse(out)["starts"][0]["insertion_form"], "hybrid");
  EXPECT_EQ(nlohmann::json::parse(out)["insertion_parallel_start"], false);
  ASSERT_EQ(run("bake 'builtin:atrium?triangles=4000' --builder sbvh --budget 1.1 --json -o " + a.string(), &out, &err),
            0)
      << err;
  j = nlohmann::json::parse(out);
  EXPECT_EQ(j["builder"], "sbvh");
  EXPECT_LE(j["references"].get<double>(), 1.1 * j["triangles"].get<double>());
  EXPECT_NE(run("bake 'builtin:atrium?triangles=4000' --budget 0.5 -o " + a.string()), 0);

  // An explicit budget replaces the quality's and is reported in seconds.
  ASSERT_EQ(run("bake 'builtin:atrium?triangles=4000' --time-budget 0 --json -o " + a.string(), &out, &err), 0) << err;
  EXPECT_EQ(nlohmann::json::parse(out)["time_budget_seconds"], 0.0);
  EXPECT_NE(run("bake 'builtin:atrium?triangles=4000' --quality perfect -o " + a.string()), 0);
}

TEST_F(OptimizeCli, BadInputsAreErrorsNamingTheInput) {
  std::string err;
  const fs::path missing = dir_ / "missing.bvh";
  EXPECT_EQ(run("optimize " + missing.string() + " -o " + (dir_ / "x.bvh").string(), nullptr, &err), 1);
  EXPECT_NE(err.find("missing.bvh"), std::string::npos) << err;
  const fs::path junk = dir_ / "junk.bvh";
  std::ofstream(junk) << "not a bvh file";
  EXPECT_EQ(run("optimize " + junk.string() + " -o " + (dir_ / "x.bvh").string(), nullptr, &err), 1);
  EXPECT_NE(err.find("junk.bvh"), std::string::npos) << err;
  EXPECT_NE(run("optimize 'builtin:atrium?triangles=4000' --method nonsense -o " + (dir_ / "x.bvh").string()), 0);
}

}  // namespace
}  // namespace bvhopt
