// The experiment runner: a small run of every protocol on the built-in scene, sharded and
// whole runs agreeing, merge refusing incomplete or mismatched parts, the plot script.
#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "bvhopt/build.h"
#include "bvhopt/cost.h"
#include "bvhopt/error.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/references.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/tree_rotations.h"
#include "bvhopt/wide_bvh.h"
#include "experiment/experiment.h"
#include "test_support.h"

namespace bvhopt {
namespace {

namespace fs = std::filesystem;

bool skip_large() {
  const char* v = std::getenv("BVHOPT_SKIP_LARGE");
  return v && std::string(v) == "1";
}

fs::path source_dir() { return fs::path(BVHOPT_SOURCE_DIR); }
fs::path plot_script() { return source_dir() / "scripts" / "plot_experiment.py"; }

// A fresh folder per test, under the system temporary folder.
fs::path temp_dir(const std::string& name) {
  fs::path p = fs::temp_directory_path() / ("bvhopt_experiment_test_" + std::to_string(::getpid())) / name;
  fs::remove_all(p);
  fs::create_directories(p);
  return p;
}

ExperimentConfig small_config() {
  ExperimentConfig c;
  // The smallest built-in scenes (3,512 triangles is the architecture alone).
  c.scenes = {"builtin?triangles=4000", "builtin?triangles=3600&seed=5"};
  c.rotation_scene = "seed=5";  // Figure 5 on the second scene
  c = quick_experiment_config(c);
  if (skip_large()) {
    c.rays = 4000;
    c.evh_rays = 4000;
    c.rotation_frames = 2;
  }
  c.plot_script.clear();  // plots are tested on their own below
  return c;
}

using Csv = std::vector<std::map<std::string, std::string>>;

Csv read_csv(const fs::path& path) {
  std::ifstream in(path);
  EXPECT_TRUE(in) << path;
  std::string line;
  std::vector<std::string> header;
  Csv rows;
  auto split = [](const std::string& s) {
    std::vector<std::string> out;
    std::stringstream ss(s);
    std::string cell;
    while (std::getline(ss, cell, ',')) out.push_back(cell);
    return out;
  };
  if (std::getline(in, line)) header = split(line);
  while (std::getline(in, line)) {
    auto cells = split(line);
    EXPECT_EQ(cells.size(), header.size()) << path << ": " << line;
    std::map<std::string, std::string> row;
    for (size_t i = 0; i < header.size() && i < cells.size(); ++i) row[header[i]] = cells[i];
    rows.push_back(row);
  }
  return rows;
}

double value(const std::map<std::string, std::string>& row, const std::string& key) {
  auto it = row.find(key);
  EXPECT_NE(it, row.end()) << "no column " << key;
  return it == row.end() ? NAN : std::stod(it->second);
}

using testing::read_text;

// The whole run, shared by the tests that read it (it is the slow part).
class ExperimentRun : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    whole_ = new fs::path(temp_dir("whole"));
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    run_experiment(small_config(), *whole_);
  }
  static void TearDownTestSuite() {
    fs::remove_all(whole_->parent_path());
    delete whole_;
  }
  static fs::path* whole_;
};
fs::path* ExperimentRun::whole_ = nullptr;

TEST_F(ExperimentRun, WritesEveryOutput) {
  for (const char* f : {"report.md", "results.json", "kensler_table1.csv", "kensler_passes.csv", "bittner_table1.csv",
                        "bittner_depth_areas.csv", "dk_t_sweep.csv", "dk_area_reduction.csv", "dk_rotation.csv",
                        "papers_comparison.csv", "anneal_budget.csv", "heat_builtin_sah.png", "heat_builtin_best.png",
                        "heat_builtin_2_sah.png"})
    EXPECT_TRUE(fs::exists(*whole_ / f)) << f;
  const std::string report = read_text(*whole_ / "report.md");
  for (const char* heading : {"## Kensler 2008, Table 1", "## Bittner et al. 2013, Table 1", "### Figure 4",
                              "### Figure 5", "### Table 1: area reduction", "## Heat maps", "## The papers beside us",
                              "## Time budget", "Machine:", "## Plots"})
    EXPECT_NE(report.find(heading), std::string::npos) << heading;
  // No plot script given: the report must say there are no plots.
  EXPECT_NE(report.find("No plots"), std::string::npos);
  nlohmann::json r = nlohmann::json::parse(read_text(*whole_ / "results.json"));
  EXPECT_EQ(r["tasks"].size(), 5u);  // 2 scenes x (optimizers, evh) + rotation
  EXPECT_GT(r["machine"]["cores"].get<int>(), 0);
  EXPECT_EQ(r["settings"]["layout"], "bvh8");  // the default: the fastest layout
  EXPECT_NE(report.find("in the bvh8 layout"), std::string::npos);
}

TEST_F(ExperimentRun, KenslerTableInRange) {
  Csv rows = read_csv(*whole_ / "kensler_table1.csv");
  ASSERT_EQ(rows.size(), 6u);  // 2 scenes x (none, hill, anneal)
  for (const auto& row : rows) {
    EXPECT_GT(value(row, "sah_cost"), 0.0);
    EXPECT_GT(value(row, "cost_ratio"), 0.0);
    EXPECT_LE(value(row, "cost_ratio"), 1.0);  // the optimizers never end above their start
    EXPECT_GT(value(row, "primary_seconds"), 0.0);
    EXPECT_GT(value(row, "path_seconds"), 0.0);
    EXPECT_GT(value(row, "primary_ratio"), 0.0);
    if (row.at("method") != "none") {
      EXPECT_GT(value(row, "optimize_seconds"), 0.0);
    }
  }
  Csv passes = read_csv(*whole_ / "kensler_passes.csv");
  size_t hill = 0, anneal = 0;
  for (const auto& row : passes) {
    EXPECT_GT(value(row, "cost"), 0.0);
    hill += row.at("method") == "hill";
    anneal += row.at("method") == "anneal";
  }
  EXPECT_GT(hill, 0u);
  EXPECT_GT(anneal, hill);
}

TEST_F(ExperimentRun, BittnerTableInRange) {
  Csv rows = read_csv(*whole_ / "bittner_table1.csv");
  ASSERT_EQ(rows.size(), 14u);  // 2 scenes x 7 trees
  for (const auto& row : rows) {
    EXPECT_GT(value(row, "cost"), 0.0);
    EXPECT_GT(value(row, "rel_cost"), 0.0);
    EXPECT_LT(value(row, "rel_cost"), 2.0);
    EXPECT_GT(value(row, "ocost"), 0.0);
    EXPECT_LE(value(row, "ocost"), value(row, "cost") * (1 + 1e-9));
    EXPECT_GT(value(row, "total_seconds"), 0.0);
    for (const char* k : {"primary_seconds", "random_seconds", "ao_seconds", "primary_steps"})
      EXPECT_GT(value(row, k), 0.0) << k;
    if (row.at("tree").find("insertion") != std::string::npos) {
      EXPECT_LT(value(row, "rel_cost"), 1.0);
    }
  }
  Csv depth = read_csv(*whole_ / "bittner_depth_areas.csv");
  ASSERT_FALSE(depth.empty());
  for (const auto& row : depth) {
    EXPECT_GE(value(row, "inner_area"), 0.0);
    EXPECT_GE(value(row, "leaf_area"), 0.0);
    // Depth 0 holds the root alone: its area relative to itself is 1.
    if (row.at("depth") == "0") {
      EXPECT_NEAR(value(row, "inner_area"), 1.0, 1e-6);
    }
  }
}

// The tables are the library's own numbers: every optimizer lowers the cost of its start
// tree on the test scene, and hill climbing and both insertion forms, run here through the
// library with the same seed, give exactly the costs the tables print (an optimizer that
// did nothing, or a table fed from the wrong tree, fails here; "in range" checks do not).
TEST_F(ExperimentRun, TablesHoldTheLibrarysCosts) {
  const ExperimentConfig c = small_config();
  const Mesh mesh = load_scene(c.scenes[0]);
  const PrimitiveRefs refs = make_references(mesh);
  const Bvh sah = build_bvh(refs, BuildOptions{});
  const double c0 = sah_cost(sah, CostModel{});
  auto optimized = [&](auto&& optimize) {
    Bvh tree = sah;
    optimize(tree);
    return sah_cost(tree, CostModel{});
  };
  const double hill = optimized([&](Bvh& t) { hill_climb(t, HillClimbConfig{}); });
  const double paper = optimized([&](Bvh& t) { optimize_insertion(t, bittner_paper_insertion_config(c.seed)); });
  const double hybrid = optimized([&](Bvh& t) { optimize_insertion(t, hybrid_insertion_config(c.seed)); });
  for (double cost : {hill, paper, hybrid}) EXPECT_LT(cost, c0);

  const Csv rows = read_csv(*whole_ / "bittner_table1.csv");
  ASSERT_FALSE(rows.empty());
  std::map<std::string, double> table;  // the first scene's rows
  for (const auto& row : rows)
    if (row.at("scene") == rows.front().at("scene")) table[row.at("tree")] = value(row, "cost");
  ASSERT_EQ(table.size(), 7u);
  EXPECT_NEAR(table.at("SAH (sweep) without optimization"), c0, 1e-4);
  EXPECT_NEAR(table.at("SAH + hill climbing (Kensler)"), hill, 1e-4);
  EXPECT_NEAR(table.at("SAH + insertion (Bittner as published)"), paper, 1e-4);
  EXPECT_NEAR(table.at("SAH + insertion (our hybrid form)"), hybrid, 1e-4);
  for (const auto& [tree, cost] : table)
    if (tree.find("without") == std::string::npos) {
      const double start = tree.find("median") != std::string::npos
                               ? table.at("spatial median without optimization") : c0;
      EXPECT_LT(cost, start) << tree;
    }
  for (const auto& row : read_csv(*whole_ / "kensler_table1.csv"))
    if (row.at("method") != "none") {
      EXPECT_LT(value(row, "cost_ratio"), 1.0) << row.at("method");
    }
}

// The rows beside the paper's figures run the paper's algorithm as published.
TEST(Experiment, BittnerRowsRunThePublishedAlgorithm) {
  const InsertionConfig ic = bittner_paper_insertion_config(7);
  EXPECT_EQ(ic.form, InsertionForm::sequential);
  EXPECT_EQ(ic.batch, 0.01);
  EXPECT_EQ(ic.measure, InsertionMeasure::area);
  EXPECT_EQ(ic.random_after, 5u);
  EXPECT_EQ(ic.stop_after, 10u);
  EXPECT_EQ(ic.min_improvement, 0.0);
  EXPECT_EQ(ic.limits.max_passes, 0u);
  EXPECT_EQ(ic.seed, 7u);
  EXPECT_EQ(hybrid_insertion_config(7).form, InsertionForm::hybrid);
}

TEST_F(ExperimentRun, DammertzKellerInRange) {
  Csv sweep = read_csv(*whole_ / "dk_t_sweep.csv");
  ASSERT_EQ(sweep.size(), 2u * (1 + small_config().evh_t_values.size()));
  for (const auto& row : sweep) {
    EXPECT_GE(value(row, "ref_ratio"), 1.0);
    EXPECT_GT(value(row, "seconds"), 0.0);
    EXPECT_GT(value(row, "time_ratio"), 0.0);
    EXPECT_GT(value(row, "steps"), 0.0);
  }
  Csv area = read_csv(*whole_ / "dk_area_reduction.csv");
  ASSERT_EQ(area.size(), 4u);
  for (const auto& row : area) {
    if (value(row, "splits") == 0) continue;
    EXPECT_GE(value(row, "best"), 0.25 - 1e-4);
    EXPECT_LE(value(row, "best"), value(row, "average"));
    EXPECT_LE(value(row, "average"), value(row, "worst"));
    EXPECT_LE(value(row, "worst"), 1.0 + 1e-4);
  }
  Csv rotation = read_csv(*whole_ / "dk_rotation.csv");
  ASSERT_EQ(rotation.size(), small_config().rotation_frames);
  for (const auto& row : rotation) {
    EXPECT_EQ(row.at("scene"), "builtin_2");
    EXPECT_GE(value(row, "evh_references"), value(row, "base_references"));
    EXPECT_GT(value(row, "base_seconds"), 0.0);
    EXPECT_GT(value(row, "evh_seconds"), 0.0);
  }
  // The last frame is the paper's end pose.
  EXPECT_NEAR(value(rotation.back(), "angle_x"), -180.0, 1e-3);
  EXPECT_NEAR(value(rotation.back(), "angle_z"), 90.0, 1e-3);
}

TEST_F(ExperimentRun, ShardedRunsMergeToTheWholeRun) {
  const fs::path base = whole_->parent_path();
  std::vector<fs::path> parts;
  for (uint32_t i = 0; i < 2; ++i) {
    ExperimentConfig c = small_config();
    c.shard_index = i;
    c.shard_count = 2;
    parts.push_back(base / ("shard" + std::to_string(i)));
    fs::remove_all(parts.back());
    run_experiment(c, parts.back());
    // A part holds only its own tasks.
    nlohmann::json r = nlohmann::json::parse(read_text(parts.back() / "results.json"));
    EXPECT_EQ(r["tasks"].size(), i == 0 ? 3u : 2u);
  }
  const fs::path merged = base / "merged";
  merge_experiments(parts, merged);
  EXPECT_EQ(deterministic_results(merged / "results.json"), deterministic_results(*whole_ / "results.json"));
  EXPECT_TRUE(fs::exists(merged / "heat_builtin_2_best.png"));
  // Merging in the other order gives the same.
  const fs::path reversed = base / "reversed";
  merge_experiments({parts[1], parts[0]}, reversed);
  EXPECT_EQ(deterministic_results(reversed / "results.json"), deterministic_results(*whole_ / "results.json"));

  // A missing shard, a repeated shard and a part of another run are refused.
  EXPECT_THROW(merge_experiments({parts[0]}, base / "bad1"), Error);
  EXPECT_THROW(merge_experiments({parts[0], parts[0]}, base / "bad2"), Error);
  ExperimentConfig other = small_config();
  other.seed = 2;
  other.shard_index = 1;
  other.shard_count = 2;
  other.evh_t_values = {10};
  other.rotation_frames = 1;
  run_experiment(other, base / "other");
  EXPECT_THROW(merge_experiments({parts[0], base / "other"}, base / "bad3"), Error);
  EXPECT_THROW(merge_experiments({base / "nothing_here"}, base / "bad4"), Error);
}

TEST(Experiment, RejectsBadInput) {
  const fs::path out = temp_dir("bad");
  ExperimentConfig c = small_config();
  c.shard_index = 2;
  c.shard_count = 2;
  EXPECT_THROW(run_experiment(c, out), Error);
  c = small_config();
  c.scenes = {};
  EXPECT_THROW(run_experiment(c, out), Error);
  c = small_config();
  c.scenes = {(out / "no_such_scene.obj").string()};
  try {
    run_experiment(c, out);
    FAIL() << "a missing scene must throw";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_scene.obj"), std::string::npos) << e.what();
  }
  fs::remove_all(out.parent_path());
}

// The Python that has matplotlib, as the runner looks for it; empty when none.
std::string python_with_matplotlib() {
  std::vector<std::string> candidates;
  if (const char* env = std::getenv("BVHOPT_PYTHON"); env && *env) candidates.push_back(env);
  candidates.push_back("python3");
  candidates.push_back("/usr/bin/python3");
  for (const std::string& py : candidates)
    if (std::system(("'" + py + "' -c 'import matplotlib' >/dev/null 2>&1").c_str()) == 0) return py;
  return {};
}

bool is_png(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  char magic[8] = {};
  in.read(magic, 8);
  return in && std::string(magic + 1, 3) == "PNG";
}

TEST(Experiment, PlotScriptDrawsTheFixtures) {
  const std::string py = python_with_matplotlib();
  if (py.empty()) GTEST_SKIP() << "python3 with matplotlib is not installed";
  const fs::path out = temp_dir("plots");
  const fs::path fixtures = source_dir() / "tests" / "fixtures" / "experiment";
  const std::string cmd = "'" + py + "' '" + plot_script().string() + "' --dir '" + fixtures.string() + "' --out '" +
                          out.string() + "' > '" + (out / "log.txt").string() + "' 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << read_text(out / "log.txt");
  for (const char* f : {"fig_kensler_passes.png", "fig_bittner_depth_builtin.png", "fig_dk_t_sweep.png",
                        "fig_dk_rotation.png"})
    EXPECT_TRUE(is_png(out / f)) << f;
  // A malformed CSV is an error with a message, not a traceback.
  const fs::path bad = temp_dir("plots_bad");
  std::ofstream(bad / "dk_rotation.csv") << "scene,frame,base_seconds\nx,one,2\n";
  const std::string bad_cmd = "'" + py + "' '" + plot_script().string() + "' --dir '" + bad.string() + "' > '" +
                              (bad / "log.txt").string() + "' 2>&1";
  EXPECT_NE(std::system(bad_cmd.c_str()), 0);
  EXPECT_NE(read_text(bad / "log.txt").find("dk_rotation.csv"), std::string::npos);
  fs::remove_all(out.parent_path());
}

// One run of the real program, when it is built beside the tests.
TEST(Experiment, CommandLineRuns) {
  const char* bin = std::getenv("BVHOPT_BIN_DIR");
  if (!bin || !fs::exists(fs::path(bin) / "bvhopt")) GTEST_SKIP() << "bvhopt program not built";
  const fs::path out = temp_dir("cli");
  const std::string exe = (fs::path(bin) / "bvhopt").string();
  const std::string cmd = "'" + exe + "' experiment --scene 'builtin?triangles=4000' --quick --rays 2000 --threads 2 --out '" +
                          (out / "run").string() + "' > '" + (out / "log.txt").string() + "' 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << read_text(out / "log.txt");
  EXPECT_TRUE(fs::exists(out / "run" / "report.md"));
  // --layout and --wide-block: recorded in the settings and the report, and the rays really
  // go through them (a 4-wide tree takes fewer traversal steps than the binary one on the same
  // rays; a dearer leaf block, c_blk, collapses into smaller leaves: fewer triangle tests).
  // The SAH tree's primary-ray figures.
  auto sah_primary = [&](const std::string& layout, const std::string& block) {
    const fs::path dir = out / (layout + block);
    const std::string run = "'" + exe + "' experiment --scene 'builtin?triangles=4000' --quick --rays 2000 --out '" +
                            dir.string() + "' --layout " + layout + (block.empty() ? "" : " --wide-block " + block) +
                            " > '" + (out / "log.txt").string() + "' 2>&1";
    EXPECT_EQ(std::system(run.c_str()), 0) << read_text(out / "log.txt");
    const nlohmann::json r = nlohmann::json::parse(read_text(dir / "results.json"));
    EXPECT_EQ(r["settings"]["layout"], layout);
    EXPECT_EQ(r["settings"]["wide_block_cost"].get<double>(), block.empty() ? WideCostModel{}.block : std::stod(block));
    const std::string report = read_text(dir / "report.md");
    EXPECT_NE(report.find("in the " + layout + " layout"), std::string::npos);
    if (layout != "bvh2") {
      EXPECT_NE(report.find("c_blk = " + r["settings"]["wide_block_cost"].dump()), std::string::npos) << report;
    }
    for (const auto& task : r["tasks"])
      if (task.contains("det") && task["det"].contains("trees")) {
        const nlohmann::json& sah = task["det"]["trees"]["sah"];
        return std::pair(sah["steps"]["primary"].get<double>(), sah["triangle_tests"]["primary"].get<double>());
      }
    ADD_FAILURE() << "no traced trees in " << dir;
    return std::pair(0.0, 0.0);
  };
  const auto bvh4 = sah_primary("bvh4", "");
  EXPECT_LT(bvh4.first, 0.8 * sah_primary("bvh2", "").first);
  EXPECT_LT(sah_primary("bvh4", "4").second, bvh4.second);
  const std::string bad = "'" + exe + "' experiment --scene 'builtin?triangles=4000' --shard 3/2 --out '" +
                          (out / "bad").string() + "' > '" + (out / "bad.txt").string() + "' 2>&1";
  EXPECT_NE(std::system(bad.c_str()), 0);
  EXPECT_NE(read_text(out / "bad.txt").find("--shard '3/2'"), std::string::npos) << read_text(out / "bad.txt");
  fs::remove_all(out.parent_path());
}

}  // namespace
}  // namespace bvhopt
