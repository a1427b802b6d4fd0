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

// A bench's numbers: the whole text is the number, or the error names the option and the
// text (std::stoi read "3x" as 3, std::atoi "abc" as 0).
TEST(BenchArgs, NumbersAreWholeAndBadOnesAreNamed) {
  EXPECT_EQ(parse_double("0.25", "--wide-block"), 0.25);
  EXPECT_EQ(parse_double("-1e3", "--x"), -1000.0);
  EXPECT_EQ(parse_int("-7", "--t"), -7);
  EXPECT_EQ(parse_integer("4000000000", "--rays", 0, INT64_MAX), 4000000000);
  for (const char* bad : {"", "abc", "3x", "1.5.2", " 2", "nan", "inf", "1e999"}) {
    const std::string e = error_of([&] { parse_double(bad, "--wide-block"); });
    EXPECT_EQ(e, "option --wide-block: '" + std::string(bad) + "' is not a finite number") << bad;
  }
  for (const char* bad : {"", "abc", "3x", "2.5", "99999999999999999999"}) {
    const std::string e = error_of([&] { parse_int(bad, "--runs"); });
    EXPECT_EQ(e, "option --runs: '" + std::string(bad) + "' is not a whole number") << bad;
  }
  EXPECT_EQ(error_of([&] { parse_integer("-1", "--count", 0, 10); }), "option --count: -1 is out of range (0 to 10)");
  EXPECT_EQ(error_of([&] { parse_int("3000000000", "--runs"); }).rfind("option --runs: 3000000000 is out of range", 0), 0u);
  EXPECT_EQ(parse_positive_list("0.25,0.5", "--wide-block"), (std::vector<double>{0.25, 0.5}));
  EXPECT_EQ(error_of([&] { parse_positive_list("0.25,0", "--wide-block"); }),
            "option --wide-block takes costs above 0, got '0'");
  EXPECT_EQ(error_of([&] { parse_positive_list(",", "--wide-block"); }), "option --wide-block needs at least one cost");
  // Through Args, as the benches read them: the option is the one being read.
  const char* argv[] = {"x_bench", "--repeats", "5", "--count", "-3", "--c-t", "three"};
  Args args(7, const_cast<char**>(argv), "x_bench");
  ASSERT_TRUE(args.next());
  EXPECT_EQ(args.int_value(), 5);
  ASSERT_TRUE(args.next());
  EXPECT_EQ(error_of([&] { args.u64_value(); }).rfind("option --count: -3 is out of range", 0), 0u);
  ASSERT_TRUE(args.next());
  EXPECT_EQ(error_of([&] { args.double_value(); }), "option --c-t: 'three' is not a finite number");
}

}  // namespace
}  // namespace bvhopt::bench
