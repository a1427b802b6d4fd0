// The benchmarks' scene lists: a scene file that is not there is an error before any run
// starts. A bench loads its scenes one after the other, and scale_bench's built-in scenes
// take minutes before Conference is read: a wrong path found only then wasted them.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

#include "../bench/bench_support.h"
#include "bvhopt/error.h"

namespace bvhopt::bench {
namespace {

namespace fs = std::filesystem;

class BenchScenes : public ::testing::Test {
 protected:
  void SetUp() override {
    // Named after the test and the process, as ProgramTest's folders are: two suites run at
    // once (Release and a sanitizer build) never share one.
    dir_ = fs::temp_directory_path() /
           ("bvhopt_bench_scenes_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) +
            "_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    std::ofstream(dir_ / "one.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

// The message of what `f` throws, or "" if it throws nothing.
template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST_F(BenchScenes, AMissingFileIsNamedAndBuiltinScenesNeedNone) {
  const std::string here = (dir_ / "one.obj").string(), missing = (dir_ / "missing.obj").string();
  EXPECT_EQ(error_of([&] { require_scene_files({"builtin", "builtin:atrium?triangles=1000", here}); }), "");
  const std::string e = error_of([&] { require_scene_files({"builtin", here, missing, "also-missing.obj"}); });
  // The first missing file, and where scenes come from.
  EXPECT_EQ(e.rfind(missing + ": scene file not found", 0), 0u) << e;
  EXPECT_NE(e.find("BVHOPT_SCENES"), std::string::npos) << e;
  // A folder is not a scene file.
  EXPECT_NE(error_of([&] { require_scene_files({dir_.string()}); }), "");
}

TEST_F(BenchScenes, PicksAreCheckedBeforeTheFolderIsListed) {
  SceneOptions s;
  s.dir = dir_;
  EXPECT_EQ(scene_specs(s), (std::vector<std::string>{(dir_ / "one.obj").string(), "builtin"}));
  s.files = {(dir_ / "one.obj").string(), (dir_ / "gone.obj").string()};
  // Even where a missing folder would only be a warning (warn_as), a missing pick is an error.
  const std::string e = error_of([&] { scene_specs(s, "insertion_bench"); });
  EXPECT_EQ(e.rfind((dir_ / "gone.obj").string() + ": scene file not found", 0), 0u) << e;
}

}  // namespace
}  // namespace bvhopt::bench
