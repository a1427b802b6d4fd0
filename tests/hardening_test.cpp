// Issue 14's classes of silent failure, end to end: a tree traced against the wrong scene,
// readers handed devices and FIFOs, unbounded work from a bad camera or a large --evh-t,
// options outside their range, outputs checked before the work.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <functional>
#include <string>
#include <vector>

#include "bvhopt/bvh_file.h"
#include "bvhopt/error.h"
#include "bvhopt/geometry_fingerprint.h"
#include "bvhopt/ray_file.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/references.h"
#include "bvhopt/scene.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/sweep_sah_builder.h"
#include "bvhopt/finalize.h"
#include "bvhopt/testing/bvh_file_checksum.h"
#include "test_support.h"

namespace bvhopt {
namespace {

namespace fs = std::filesystem;
using Cli = testing::ProgramTest;
using CliRun = testing::ProgramTest::Result;

// Built by appending: GCC 12 warns falsely (-Wstringop-overflow) on "'" + p.string() + "'".
std::string q(const fs::path& p) {
  std::string quoted = "'";
  quoted += p.string();
  quoted += '\'';
  return quoted;
}

void write_file(const fs::path& p, const std::string& text) { std::ofstream(p, std::ios::binary) << text; }

// Two triangles, shifted by `dx`: the same size as any other call, other geometry.
std::string two_triangles_obj(float dx) {
  std::string s;
  for (int t = 0; t < 2; ++t) {
    const float x = dx + 2.0f * t;
    s += "v " + std::to_string(x) + " 0 0\nv " + std::to_string(x + 1) + " 0 0\nv " + std::to_string(x) + " 1 0\n";
  }
  return s + "f 1 2 3\nf 4 5 6\n";
}

// ---- Item 8: a tree meets only the scene it was built over --------------------------

TEST_F(Cli, TreeOfAnotherSceneWithTheSameTriangleCountIsRefused) {
  write_file(dir_ / "a.obj", two_triangles_obj(0.0f));
  write_file(dir_ / "b.obj", two_triangles_obj(0.5f));
  ASSERT_EQ(run("build " + q(dir_ / "a.obj") + " -o " + q(dir_ / "a.bvh")).exit_code, 0);
  CliRun r = run("trace " + q(dir_ / "a.bvh") + " --scene " + q(dir_ / "b.obj") + " --count 10");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.err.find("a.obj"), std::string::npos) << r.err;  // the stored scene name
  EXPECT_NE(r.err.find("b.obj"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("fingerprint"), std::string::npos) << r.err;
  EXPECT_EQ(run("trace " + q(dir_ / "a.bvh") + " --scene " + q(dir_ / "a.obj") + " --count 10").exit_code, 0);
}

TEST_F(Cli, RotationNotUsedAtBuildIsRefused) {
  const std::string scene = "'builtin?triangles=4000'";
  ASSERT_EQ(run("build " + scene + " -o " + q(dir_ / "t.bvh")).exit_code, 0);
  CliRun r = run("render " + q(dir_ / "t.bvh") + " --scene " + scene + " --rotate 0,90,0 --width 8 --height 8 --heatmap " +
                 q(dir_ / "h.png"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("--rotate"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "h.png"));
  ASSERT_EQ(run("build " + scene + " --rotate 0,90,0 -o " + q(dir_ / "r.bvh")).exit_code, 0);
  EXPECT_EQ(run("trace " + q(dir_ / "r.bvh") + " --scene " + scene + " --rotate 0,90,0 --count 100").exit_code, 0);
  EXPECT_EQ(run("trace " + q(dir_ / "r.bvh") + " --scene " + scene + " --count 100").exit_code, 1);
}

TEST_F(Cli, BuiltinSceneWithAnotherSeedIsRefused) {
  // Seeds 1 and 2 give the same triangle count: only the geometry tells them apart.
  const Mesh a = load_scene("builtin?triangles=4000&seed=1"), b = load_scene("builtin?triangles=4000&seed=2");
  ASSERT_EQ(a.triangle_count(), b.triangle_count());
  ASSERT_EQ(run("build 'builtin?triangles=4000&seed=1' -o " + q(dir_ / "t.bvh")).exit_code, 0);
  CliRun r = run("trace " + q(dir_ / "t.bvh") + " --scene 'builtin?triangles=4000&seed=2' --count 100");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("seed"), std::string::npos) << r.err;
}

// A version-1 file (no fingerprint) still reads, and still meets its scene by name and count.
TEST(BvhFileVersion, VersionOneFilesStillRead) {
  Mesh mesh = make_builtin_scene({.seed = 1, .target_triangles = 4000});
  mesh.name = "scene.obj";
  PrimitiveRefs refs = make_references(mesh);
  const Bvh bvh = build_sweep_sah(refs);
  const fs::path dir = fs::temp_directory_path() / ("bvhopt_v1_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path v2 = dir / "v2.bvh", v1 = dir / "v1.bvh";
  write_bvh_file(v2, bvh, refs, scene_info(mesh, CostModel{}, "sweep"));
  // Version 1 is version 2 without the 8 fingerprint bytes after the method string.
  std::string bytes = testing::read_text(v2);
  uint32_t header_size = 0;
  std::memcpy(&header_size, bytes.data() + 12, 4);
  bytes.erase(header_size - 8, 8);
  const uint32_t version = 1;
  header_size -= 8;
  std::memcpy(bytes.data() + 8, &version, 4);
  std::memcpy(bytes.data() + 12, &header_size, 4);
  const uint64_t sum = bvh_file_checksum(bytes.data(), bytes.size() - 8);
  std::memcpy(bytes.data() + bytes.size() - 8, &sum, 8);
  write_file(v1, bytes);

  const BvhFile f = read_bvh_file(v1);
  EXPECT_EQ(f.info.geometry_fingerprint, 0u);
  EXPECT_EQ(f.info.scene_name, "scene.obj");
  EXPECT_EQ(f.bvh.nodes.size(), bvh.depth_first_order().size());
  EXPECT_NO_THROW(check_tree_matches_scene("v1.bvh", f.info, mesh));
  Mesh renamed = mesh;
  renamed.name = "other.obj";
  EXPECT_THROW(check_tree_matches_scene("v1.bvh", f.info, renamed), Error);
  EXPECT_NE(read_bvh_file(v2).info.geometry_fingerprint, 0u);
  fs::remove_all(dir);
}

TEST(GeometryFingerprint, SeesEveryBitOfPositionsAndIndices) {
  Mesh m = make_builtin_scene({.seed = 3, .target_triangles = 4000});
  const uint64_t base = geometry_fingerprint(m);
  Mesh moved = m;
  const size_t some = moved.positions.size() / 2;  // inside the array, whatever the scene makes
  moved.positions.at(some) = std::nextafter(moved.positions.at(some), 1e9f);
  EXPECT_NE(geometry_fingerprint(moved), base);
  Mesh swapped = m;
  std::swap(swapped.indices[0], swapped.indices[1]);
  EXPECT_NE(geometry_fingerprint(swapped), base);
  Mesh renamed = m;
  renamed.name = "x";
  EXPECT_EQ(geometry_fingerprint(renamed), base);  // geometry only
}

// ---- Item 5: readers refuse what is not a regular file, before opening it -----------

TEST(Readers, RefuseDevicesAndFifosBeforeOpening) {
  const fs::path fifo = fs::temp_directory_path() / ("bvhopt_fifo_" + std::to_string(::getpid()) + ".obj");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  // With no writer, opening the FIFO for reading would block forever.
  for (const fs::path& p : {fs::path("/dev/zero"), fifo}) {
    SCOPED_TRACE(p.string());
    EXPECT_THROW(load_mesh_file(p), Error);
    EXPECT_THROW(read_bvh_file(p), Error);
    EXPECT_THROW(read_ray_file(p), Error);
    try {
      load_mesh_file(p);
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("not a regular file"), std::string::npos) << e.what();
    }
  }
  fs::remove(fifo);
}

TEST_F(Cli, ATreeFileGivenAsTheSceneIsNamedAsSuch) {
  ASSERT_EQ(run("build 'builtin?triangles=4000' -o " + q(dir_ / "t.bvh")).exit_code, 0);
  CliRun r = run("trace " + q(dir_ / "t.bvh") + " --scene " + q(dir_ / "t.bvh"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("a bvhopt BVH file (a tree), not a scene"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("HIERARCHY"), std::string::npos) << r.err;  // not read as motion capture
}

// The subdivision's cost is bounded by its reference budget: t = 62 (the top of the
// documented range) on 98 triangles took minutes. `timeout` turns a hang into exit 124.
TEST_F(Cli, LargestEvhThresholdFinishes) {
  write_file(dir_ / "s.obj", [] {
    std::string s;
    for (int t = 0; t < 98; ++t) {
      const std::string x = std::to_string(t), y = std::to_string(t % 7);
      s += "v " + x + " " + y + " 0\nv " + x + ".9 " + y + ".8 3\nv " + x + ".2 " + y + ".9 1\n";
    }
    for (int t = 0; t < 98; ++t)
      s += "f " + std::to_string(3 * t + 1) + " " + std::to_string(3 * t + 2) + " " + std::to_string(3 * t + 3) + "\n";
    return s;
  }());
  CliRun r = run("--version >/dev/null; timeout 120 " + q(exe_) + " build " + q(dir_ / "s.obj") +
                 " --evh --evh-t 62 --json -o " + q(dir_ / "s.bvh"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_LE(j["references"].get<double>(), 8.0 * 98);
}

// ---- Item 4: a camera that sees almost nothing --------------------------------------

TEST(RaySetBound, CameraThatSeesAlmostNothingIsAClearErrorNotUnboundedWork) {
  Mesh mesh = make_builtin_scene({.seed = 1, .target_triangles = 4000});
  PrimitiveRefs refs = make_references(mesh);
  const Tracer tracer(finalize(build_sweep_sah(refs), refs), mesh);
  Camera cam;
  // Far away, looking past the scene: a handful of pixels at most see it.
  cam.position = Vec3(0.0f, 0.0f, 1e5f);
  cam.target = Vec3(1e4f, 0.0f, 0.0f);
  for (RayKind kind : {RayKind::ao, RayKind::shadow, RayKind::path}) {
    SCOPED_TRACE(std::string(ray_kind_name(kind)));
    RaySetConfig cfg;
    cfg.kind = kind;
    cfg.count = 100'000;
    cfg.camera = cam;
    try {
      const RaySet set = make_ray_set(mesh, tracer, cfg);
      ADD_FAILURE() << "made " << set.rays.size() << " rays";
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(std::string(ray_kind_name(kind)) + " rays"), std::string::npos) << msg;
      EXPECT_NE(msg.find("of the 100000 wanted"), std::string::npos) << msg;
      EXPECT_NE(msg.find("aim the camera"), std::string::npos) << msg;
    }
  }
  // A count the view can give still comes out whole.
  RaySetConfig cfg;
  cfg.kind = RayKind::ao;
  cfg.count = 1000;
  EXPECT_EQ(make_ray_set(mesh, tracer, cfg).rays.size(), 1000u);
}

TEST(RaySetBound, CountsAndResolutionsAboveTheLimitAreErrors) {
  Mesh mesh = make_builtin_scene({.seed = 1, .target_triangles = 4000});
  PrimitiveRefs refs = make_references(mesh);
  const Tracer tracer(finalize(build_sweep_sah(refs), refs), mesh);
  RaySetConfig cfg;
  cfg.kind = RayKind::random;
  cfg.count = kMaxRayCount + 1;
  EXPECT_THROW(make_ray_set(mesh, tracer, cfg), Error);
  Camera cam;
  cam.width = 100000;
  cam.height = 100000;
  EXPECT_THROW(camera_rays(cam), Error);
}

// ---- Item 6: every option inside its range does what it says, outside it is refused --

TEST_F(Cli, RayCountsOutsideTheirRangeAreRefusedByName) {
  ASSERT_EQ(run("build 'builtin?triangles=4000' -o " + q(dir_ / "t.bvh")).exit_code, 0);
  const std::string trace = "trace " + q(dir_ / "t.bvh") + " --scene 'builtin?triangles=4000' --repeats 1 ";
  for (const char* bad : {"--count 0", "--count -1", "--count 99999999999999", "--count 1e3", "--check -1"}) {
    CliRun r = run(trace + bad);
    EXPECT_EQ(r.exit_code, 2) << bad << "\n" << r.err;
    EXPECT_NE(r.err.find(std::string(bad).substr(0, 7)), std::string::npos) << bad << "\n" << r.err;
    EXPECT_EQ(r.err.find("unexpected"), std::string::npos) << r.err;
  }
  CliRun ok = run(trace + "--count 1000 --rays random --json");
  ASSERT_EQ(ok.exit_code, 0) << ok.err;
  EXPECT_EQ(nlohmann::json::parse(ok.out)["count"].get<int>(), 1000);
}

TEST_F(Cli, RangeBoundsAreWordsNotThreeHundredDigits) {
  ASSERT_EQ(run("build 'builtin?triangles=4000' -o " + q(dir_ / "t.bvh")).exit_code, 0);
  for (const std::string opt : {"--max-steps 0", "--range nan", "--range -1"}) {
    CliRun r = run("render " + q(dir_ / "t.bvh") + " --scene 'builtin?triangles=4000' " + opt + " --heatmap " +
                   q(dir_ / "h.png"));
    EXPECT_EQ(r.exit_code, 2) << opt;
    EXPECT_NE(r.err.find(opt.substr(0, opt.find(' '))), std::string::npos) << r.err;
    EXPECT_LT(r.err.size(), 300u) << r.err;
  }
}

TEST(BuiltinSpec, TriangleTargetBelowTheSmallestSceneIsRefused) {
  try {
    load_scene("builtin?triangles=1");
    ADD_FAILURE() << "builtin?triangles=1 loaded";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("triangles"), std::string::npos) << msg;
    EXPECT_NE(msg.find(std::to_string(min_builtin_scene_triangles(1))), std::string::npos) << msg;
  }
  const uint64_t fewest = min_builtin_scene_triangles(1);
  EXPECT_EQ(load_scene("builtin?triangles=" + std::to_string(fewest)).triangle_count(), fewest);
}

// ---- optimize --method insertion: each option has an effect ------------------------

TEST_F(Cli, EveryInsertionOptionChangesTheRun) {
  const std::string base = "optimize 'builtin?triangles=4000' --method insertion --passes 40 --json -o ";
  auto run_with = [&](const std::string& options) {
    const fs::path out = dir_ / "o.bvh";
    CliRun r = run(base + q(out) + " " + options);
    EXPECT_EQ(r.exit_code, 0) << options << "\n" << r.err;
    if (r.exit_code != 0) return std::string();
    const auto j = nlohmann::json::parse(r.out);
    // What a run did: its result and its path there.
    return std::to_string(j["cost_after"].get<double>()) + " " + std::to_string(j["passes"].get<int>()) + " " +
           std::to_string(j["moves"].get<int>()) + " tree " + std::to_string(std::hash<std::string>{}(testing::read_text(out)));
  };
  const std::string reference = run_with("");
  ASSERT_FALSE(reference.empty());
  // (The default form, hybrid, starts as the sequential one: with a 40-pass cap they agree.)
  for (const char* option : {"--batch 0.05", "--measure sum", "--form parallel", "--random-after 1", "--stop-after 1"}) {
    const std::string other = run_with(option);
    EXPECT_NE(other, reference) << option << " changed nothing";
  }
  // --stop-after 1 ends at the first pass without improvement: fewer passes than p_T = 10.
  CliRun early = run(base + q(dir_ / "e.bvh") + " --form sequential --stop-after 1");
  CliRun late = run(base + q(dir_ / "l.bvh") + " --form sequential --stop-after 10");
  ASSERT_EQ(early.exit_code, 0);
  ASSERT_EQ(late.exit_code, 0);
  EXPECT_LT(nlohmann::json::parse(early.out)["passes"].get<int>(), nlohmann::json::parse(late.out)["passes"].get<int>());
}

// ---- Item 9: every output checked before the work; all or none written ------------

TEST_F(Cli, OutputPathsAreCheckedBeforeTheWork) {
  const std::string nowhere = q(dir_ / "no_such_folder" / "x");
  // The input is missing too: the output's error comes first, before any loading.
  const std::string in = q(dir_ / "missing.obj");
  struct Case {
    std::string command, option, problem;
  };
  const Case cases[] = {
      {"optimize " + in + " -o " + nowhere, "-o", "no_such_folder"},
      {"optimize " + in + " -o " + q(dir_ / "ok.bvh") + " --cost-trace " + nowhere, "--cost-trace",
       "no_such_folder"},
      {"build " + in + " -o " + nowhere, "-o", "no_such_folder"},
      {"build " + in + " -o " + q(dir_), "-o", "is a folder"},
      {"bake " + in + " -o " + nowhere, "-o", "no_such_folder"},
  };
  for (const Case& c : cases) {
    CliRun r = run(c.command + " --json");
    EXPECT_EQ(r.exit_code, 1) << c.command;
    EXPECT_NE(r.err.find(c.option + " "), std::string::npos) << c.command << "\n" << r.err;
    EXPECT_NE(r.err.find(c.problem), std::string::npos) << c.command << "\n" << r.err;
    EXPECT_TRUE(r.out.empty()) << "work was done before the check: " << r.out;
  }
  EXPECT_FALSE(fs::exists(dir_ / "ok.bvh"));  // nothing written when one output is bad
}

TEST_F(Cli, RenderWritesAllImagesOrNone) {
  ASSERT_EQ(run("build 'builtin?triangles=4000' -o " + q(dir_ / "t.bvh")).exit_code, 0);
  const std::string render = "render " + q(dir_ / "t.bvh") + " --scene 'builtin?triangles=4000' --width 16 --height 16 ";
  CliRun r = run(render + "--heatmap " + q(dir_ / "h.png") + " --shaded " + q(dir_ / "no_such_folder" / "s.png"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("--shaded"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "h.png"));
  // A --compare tree of another scene fails after the images are made: none is written.
  ASSERT_EQ(run("build 'builtin?triangles=5000' -o " + q(dir_ / "other.bvh")).exit_code, 0);
  r = run(render + "--heatmap " + q(dir_ / "h.png") + " --shaded " + q(dir_ / "s.png") + " --compare " +
          q(dir_ / "other.bvh"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_FALSE(fs::exists(dir_ / "h.png"));
  EXPECT_FALSE(fs::exists(dir_ / "s.png"));
  for (const auto& entry : fs::directory_iterator(dir_))
    EXPECT_EQ(entry.path().string().find(".tmp-"), std::string::npos) << entry.path();
  r = run(render + "--heatmap " + q(dir_ / "h.png") + " --shaded " + q(dir_ / "s.png"));
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir_ / "h.png") && fs::exists(dir_ / "s.png"));
}

}  // namespace
}  // namespace bvhopt
