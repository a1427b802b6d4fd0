// End-to-end tests of the bvhopt program: exit codes, outputs, error messages.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <set>

#include <string>

#include "bvhopt/build.h"
#include "bvhopt/bvh_file.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/triangle_cost.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace {

using CliRun = bvhopt::testing::ProgramTest::Result;
using Cli = bvhopt::testing::ProgramTest;

TEST_F(Cli, HelpListsTheSubcommands) {
  CliRun r = run("--help");
  EXPECT_EQ(r.exit_code, 0);
  for (const char* sub : {"info", "build", "stats", "demo"}) EXPECT_NE(r.out.find(sub), std::string::npos) << sub;
}

TEST_F(Cli, NoSubcommandIsAnError) {
  CliRun r = run("");
  EXPECT_NE(r.exit_code, 0);
}

TEST_F(Cli, BuildThenStatsAgreeOnTheCost) {
  fs::path bvh = dir_ / "scene.bvh";
  CliRun b = run("build 'builtin?triangles=4000' --builder binned --json -o " + bvh.string());
  ASSERT_EQ(b.exit_code, 0) << b.err;
  ASSERT_TRUE(fs::exists(bvh));
  auto built = nlohmann::json::parse(b.out);
  CliRun s = run("stats --json " + bvh.string());
  ASSERT_EQ(s.exit_code, 0) << s.err;
  auto stats = nlohmann::json::parse(s.out);
  EXPECT_GT(built["cost"].get<double>(), 0.0);
  EXPECT_DOUBLE_EQ(built["cost"].get<double>(), stats["cost"].get<double>());
  EXPECT_EQ(stats["method"], "binned");
  EXPECT_EQ(stats["references"].get<size_t>(), built["triangles"].get<size_t>());
}

// The default build (sweep, leaves of one) builds over the mesh and takes its statistics
// before the references exist: the file must hold the tree and references of the build over
// references, and the printed cost and ocost must be theirs to the last bit.
TEST_F(Cli, DefaultBuildWritesTheTreeOverReferences) {
  const std::string scene = "builtin:atrium?triangles=5000";
  const fs::path bvh = dir_ / "scene.bvh";
  CliRun b = run("build '" + scene + "' --json -o " + bvh.string());
  ASSERT_EQ(b.exit_code, 0) << b.err;
  const auto printed = nlohmann::json::parse(b.out);
  const bvhopt::Mesh mesh = bvhopt::load_scene(scene);
  const bvhopt::BuiltTree want = bvhopt::build_tree(mesh, bvhopt::make_references(mesh), bvhopt::BuildOptions{});
  const bvhopt::BvhFile got = bvhopt::read_bvh_file(bvh);
  EXPECT_TRUE(bvhopt::testing::same_nodes(got.bvh, want.bvh));
  EXPECT_EQ(got.refs.triangle_ids, want.refs.triangle_ids);
  EXPECT_EQ(got.refs.boxes, want.refs.boxes);
  const bvhopt::TreeStats st = bvhopt::compute_stats(want.bvh, want.refs, bvhopt::CostModel{});
  EXPECT_EQ(printed["cost"].get<double>(), st.cost);
  EXPECT_EQ(printed["ocost"].get<double>(), st.ocost);
  EXPECT_EQ(printed["nodes"].get<size_t>(), st.nodes);
}

TEST_F(Cli, MissingSceneNamesTheFile) {
  CliRun r = run("info " + (dir_ / "no_such_scene.obj").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("no_such_scene.obj"), std::string::npos) << r.err;
}

// An explicit --bins holds at every node: --bins 32 differs from the adaptive default
// (which gives large nodes more bins), and the range is the library's (2 to 128).
TEST_F(Cli, ExplicitBinCountIsHonoured) {
  auto cost_with = [&](const std::string& bins) {
    CliRun r = run("build 'builtin?triangles=20000' --builder binned " + bins + " --json -o " + (dir_ / "b.bvh").string());
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return r.exit_code == 0 ? nlohmann::json::parse(r.out)["cost"].get<double>() : -1.0;
  };
  const double adaptive = cost_with(""), b32 = cost_with("--bins 32"), b128 = cost_with("--bins 128");
  EXPECT_NE(adaptive, b32);
  EXPECT_NE(b32, b128);
  CliRun r = run("build builtin --builder binned --bins 129 -o " + (dir_ / "x.bvh").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("--bins"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "x.bvh"));
}

// The sbvh builder's settings reach it: spatial splits everywhere (--spatial-from 0), none
// (--split-alpha 1: no overlap is that large), the root's test alone (--split-node-alpha 0)
// and a few bins each give another tree than the defaults; values outside their ranges are
// refused by name.
TEST_F(Cli, SbvhSettingsAreHonoured) {
  auto build_with = [&](const std::string& options) {
    CliRun r = run("build 'builtin?triangles=4000' --builder sbvh " + options + " --json -o " + (dir_ / "s.bvh").string());
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return r.exit_code == 0 ? nlohmann::json::parse(r.out) : nlohmann::json{{"cost", -1.0}, {"references", 0}};
  };
  const nlohmann::json defaults = build_with(""), everywhere = build_with("--spatial-from 0"),
                       none = build_with("--split-alpha 1"), few_bins = build_with("--spatial-bins 2"),
                       root_test_only = build_with("--split-node-alpha 0");
  const size_t triangles = defaults["triangles"].get<size_t>();
  EXPECT_GT(defaults["references"].get<size_t>(), triangles);  // the default does split
  EXPECT_EQ(none["references"].get<size_t>(), triangles);      // alpha 1 never does
  EXPECT_NE(everywhere["cost"].get<double>(), defaults["cost"].get<double>());
  EXPECT_NE(few_bins["cost"].get<double>(), defaults["cost"].get<double>());
  EXPECT_NE(root_test_only["cost"].get<double>(), defaults["cost"].get<double>());
  for (const std::string bad : {"--spatial-bins 1", "--spatial-bins 129", "--split-alpha nan", "--split-alpha -1",
                                "--split-node-alpha -1", "--split-node-alpha nan", "--spatial-from -1"}) {
    CliRun r = run("build builtin --builder sbvh " + bad + " -o " + (dir_ / "x.bvh").string());
    EXPECT_EQ(r.exit_code, 2) << bad;
    EXPECT_NE(r.err.find(bad.substr(0, bad.find(' '))), std::string::npos) << r.err;
  }
}

// What the sbvh builder did is reported: its splits are one per inner node, its references
// within the budget and per triangle as counted; a build that splits nothing says so; other
// builders have no such report.
TEST_F(Cli, BuildReportsTheSpatialSplitCounts) {
  auto build_with = [&](const std::string& options) {
    CliRun r = run("build 'builtin?triangles=4000' " + options + " --json -o " + (dir_ / "s.bvh").string());
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return r.exit_code == 0 ? nlohmann::json::parse(r.out) : nlohmann::json::object();
  };
  const nlohmann::json sbvh = build_with("--builder sbvh"), none = build_with("--builder sbvh --split-alpha 1"),
                       sweep = build_with("--builder sweep");
  ASSERT_TRUE(sbvh.contains("spatial_split")) << sbvh.dump();
  const nlohmann::json& s = sbvh["spatial_split"];
  const size_t refs = sbvh["references"].get<size_t>(), triangles = sbvh["triangles"].get<size_t>();
  EXPECT_GT(s["spatial_splits"].get<size_t>(), 0u);
  EXPECT_GT(s["split_references"].get<size_t>(), 0u);
  EXPECT_EQ(s["spatial_splits"].get<size_t>() + s["object_splits"].get<size_t>(),
            sbvh["nodes"].get<size_t>() - sbvh["leaves"].get<size_t>());
  EXPECT_LE(refs, s["budget_references"].get<size_t>());
  EXPECT_GE(s["budget_references"].get<size_t>(), triangles + triangles / 4);  // 1.3x by default
  EXPECT_DOUBLE_EQ(sbvh["references_per_triangle"].get<double>(), double(refs) / double(triangles));
  ASSERT_TRUE(none.contains("spatial_split"));
  EXPECT_EQ(none["spatial_split"]["spatial_splits"].get<size_t>(), 0u);
  EXPECT_EQ(none["spatial_split"]["split_references"].get<size_t>(), 0u);
  EXPECT_FALSE(sweep.contains("spatial_split"));
  EXPECT_DOUBLE_EQ(sweep["references_per_triangle"].get<double>(), 1.0);
  // The text names the same counts.
  CliRun text = run("build 'builtin?triangles=4000' --builder sbvh -o " + (dir_ / "s.bvh").string());
  EXPECT_NE(text.out.find(std::to_string(s["spatial_splits"].get<size_t>()) + " spatial and "), std::string::npos)
      << text.out;
}

TEST_F(Cli, UnknownBuilderIsRejected) {
  CliRun r = run("build builtin --builder fastest -o " + (dir_ / "x.bvh").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_FALSE(fs::exists(dir_ / "x.bvh"));
}

TEST_F(Cli, CorruptBvhFileIsRejectedWithItsName) {
  fs::path bad = dir_ / "corrupt.bvh";
  std::ofstream(bad) << "this is not a bvh file at all";
  CliRun r = run("stats " + bad.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("corrupt.bvh"), std::string::npos) << r.err;
}

TEST_F(Cli, FailedWriteLeavesNothingBehind) {
  fs::path target = dir_ / "missing_dir" / "out.bvh";
  CliRun r = run("build 'builtin?triangles=4000' -o " + target.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_FALSE(fs::exists(dir_ / "missing_dir"));
  EXPECT_NE(r.err.find("out.bvh"), std::string::npos) << r.err;
}

TEST_F(Cli, DemoPrintsARowPerMethodAndWritesHeatMaps) {
  CliRun r = run("demo --triangles 5000 --quick --rays 20000 --json --images " + (dir_ / "images").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto j = nlohmann::json::parse(r.out);
  std::set<std::string> methods;
  for (const auto& row : j["rows"]) {
    methods.insert(row["method"].get<std::string>());
    EXPECT_GT(row["cost"].get<double>(), 0.0);
    EXPECT_LE(row["ocost"].get<double>(), row["cost"].get<double>() + 1e-9);
  }
  for (const char* m : {"sweep", "binned", "spatial-median", "object-median", "sweep+hill-climb", "sweep+anneal",
                        "sweep+insertion", "sweep+insertion+compact"})
    EXPECT_TRUE(methods.count(m)) << m;
  for (const auto& row : j["rows"]) EXPECT_GT(row["primary_mrays_per_s"].get<double>(), 0.0);
  EXPECT_TRUE(fs::exists(dir_ / "images" / "heatmap-sweep.png"));
  EXPECT_TRUE(fs::exists(dir_ / "images" / "heatmap-best.png"));
}

}  // namespace

namespace {

// Edge volume subdivision through the command line: more references than triangles, every
// triangle still in the tree, and the count `info` predicts is the one `build` makes.
TEST_F(Cli, EvhBuildMakesTheReferencesInfoPredicts) {
  const std::string scene = "'builtin?triangles=4000' --rotate 30,30,0";
  CliRun info = run("info " + scene + " --evh-t 14 --json");
  ASSERT_EQ(info.exit_code, 0) << info.err;
  auto predicted = nlohmann::json::parse(info.out)["evh"][0]["references"].get<size_t>();
  fs::path bvh = dir_ / "evh.bvh";
  CliRun b = run("build " + scene + " --evh --evh-t 14 --evh-max-ratio 0 --json -o " + bvh.string());
  ASSERT_EQ(b.exit_code, 0) << b.err;
  auto built = nlohmann::json::parse(b.out);
  EXPECT_EQ(built["references"].get<size_t>(), predicted);
  EXPECT_GT(predicted, 4000u);
  CliRun s = run("stats --json " + bvh.string());
  ASSERT_EQ(s.exit_code, 0) << s.err;
  auto stats = nlohmann::json::parse(s.out);
  EXPECT_EQ(stats["triangles"].get<size_t>(), 4000u);
  EXPECT_EQ(stats["references"].get<size_t>(), predicted);  // leaf size 1: nothing to dedup
  EXPECT_EQ(stats["method"], "evh+sweep");
}

TEST_F(Cli, EvhOnABvhFileIsRefused) {
  fs::path bvh = dir_ / "a.bvh";
  ASSERT_EQ(run("build 'builtin?triangles=4000' -o " + bvh.string()).exit_code, 0);
  CliRun r = run("optimize " + bvh.string() + " --evh --method hill-climb -o " + (dir_ / "b.bvh").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("--evh"), std::string::npos) << r.err;
}

// The exit codes of docs/errors.md: 1 bad input or a failed run, 2 bad usage.
TEST_F(Cli, UnknownSubcommandIsAUsageErrorNamingIt) {
  CliRun r = run("frobnicate");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("unknown subcommand 'frobnicate'"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("stats"), std::string::npos) << r.err;
}

TEST_F(Cli, BadOptionValuesAreUsageErrorsNamingTheOption) {
  EXPECT_EQ(run("build builtin --no-such-option").exit_code, 2);
  EXPECT_EQ(run("build builtin --leaf-size 0 -o " + (dir_ / "x.bvh").string()).exit_code, 2);
}

TEST_F(Cli, MissingBvhFileIsBadInputNotUsage) {
  CliRun r = run("stats " + (dir_ / "no_such.bvh").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.err.rfind("bvhopt: error: ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find("no_such.bvh"), std::string::npos) << r.err;
}

// NaN passes every range check (all its comparisons are false); each of these options must
// refuse it, and infinity, by name.
TEST_F(Cli, NonFiniteNumbersAreRefusedByName) {
  fs::path bvh = dir_ / "t.bvh";
  ASSERT_EQ(run("build 'builtin?triangles=4000' -o " + bvh.string()).exit_code, 0);
  const std::string out = " -o " + (dir_ / "o.bvh").string();
  const std::pair<std::string, std::string> cases[] = {
      {"build builtin --ct nan" + out, "--ct"},
      {"build builtin --ci inf" + out, "--ci"},
      {"optimize " + bvh.string() + " --h nan" + out, "--h"},
      {"optimize " + bvh.string() + " --method insertion --batch nan" + out, "--batch"},
      {"optimize " + bvh.string() + " --time-limit nan" + out, "--time-limit"},
      {"build builtin --evh --evh-max-ratio nan" + out, "--evh-max-ratio"},
      {"render " + bvh.string() + " --scene 'builtin?triangles=4000' --max-steps nan --heatmap " +
           (dir_ / "h.png").string(), "--max-steps"},
      {"render " + bvh.string() + " --scene 'builtin?triangles=4000' --max-steps 0 --heatmap " +
           (dir_ / "h.png").string(), "--max-steps"},
      {"render " + bvh.string() + " --scene 'builtin?triangles=4000' --max-steps -5 --heatmap " +
           (dir_ / "h.png").string(), "--max-steps"},
  };
  for (const auto& [command, option] : cases) {
    CliRun r = run(command);
    EXPECT_EQ(r.exit_code, 2) << command << "\n" << r.err;
    EXPECT_NE(r.err.find(option), std::string::npos) << command << "\n" << r.err;
  }
}

// oneTBB never runs more threads than there are cores, so that is what is reported.
TEST_F(Cli, ThreadsAboveTheCoreCountAreReportedAsRun) {
  CliRun r = run("build 'builtin?triangles=4000' --threads 4096 -o " + (dir_ / "t.bvh").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.find("4096 threads"), std::string::npos) << r.out;
}

}  // namespace
