// bvhopt export against the standalone reader example (examples/wide_reader, built by ctest
// from its own CMake project): for every format and width, the reader traces the exported
// file and writes the very hit file `bvhopt trace --save-hits` writes for the same rays.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include <sys/wait.h>

#include "test_support.h"

namespace fs = std::filesystem;

namespace {

class WideExportCli : public bvhopt::testing::ProgramTest {
 protected:
  void SetUp() override {
    ProgramTest::SetUp();
    if (IsSkipped()) return;
    reader_ = fs::path(std::getenv("BVHOPT_BIN_DIR")) / "tests" / "wide_reader" / "wide_reader";
    ASSERT_TRUE(fs::exists(reader_)) << reader_ << " not built (ctest builds it in WideReaderExample.Builds)";
  }

  // Builds a tree over `scene` and saves, per ray set, the rays and bvhopt's hits in `layout`.
  void trace_sets(const std::string& scene, const std::string& build_args, const std::string& layout) {
    ASSERT_EQ(run("build '" + scene + "' " + build_args + " -o " + (dir_ / "s.bvh").string()).exit_code, 0);
    for (const char* rays : {"primary", "random", "ao", "shadow"}) {
      const Result r = run("trace " + (dir_ / "s.bvh").string() + " --scene '" + scene + "' --rays " + rays +
                           " --count 4000 --width 64 --height 48 --repeats 1 --check 0 --layout " + layout +
                           " --save-rays " + rays_file(rays).string() + " --save-hits " + hits_file(rays, "bvhopt").string());
      ASSERT_EQ(r.exit_code, 0) << rays << ": " << r.err;
    }
  }

  void expect_reader_agrees(const std::string& scene, const std::string& layout, const std::string& format) {
    const fs::path out = dir_ / (layout + "-" + format + ".wbvh");
    const Result e = run("export " + (dir_ / "s.bvh").string() + " --scene '" + scene + "' --layout " + layout +
                         " --format " + format + " -o " + out.string() + " --json");
    ASSERT_EQ(e.exit_code, 0) << e.err;
    const auto j = nlohmann::json::parse(e.out);
    EXPECT_EQ(j["bytes"].get<uint64_t>(), fs::file_size(out));
    bool some_miss = false;
    for (const char* rays : {"primary", "random", "ao", "shadow"}) {
      const fs::path mine = hits_file(rays, layout + format);
      const Result r = run_program(reader_, out.string() + " " + rays_file(rays).string() + " " + mine.string());
      ASSERT_EQ(r.exit_code, 0) << r.err;
      const std::string want = bvhopt::testing::read_text(hits_file(rays, "bvhopt"));
      const std::string got = bvhopt::testing::read_text(mine);
      ASSERT_FALSE(want.empty());
      // Rays of every set hit, and some miss, so the comparison means something.
      some_miss |= want.find("miss") != std::string::npos;
      EXPECT_NE(want.find(std::string(rays) == "shadow" ? "hit" : " 0x"), std::string::npos) << rays;
      EXPECT_TRUE(got == want) << layout << " " << format << " " << rays << ": the reader's hits differ";
    }
    EXPECT_TRUE(some_miss);
  }

  // Runs the reader, as ProgramTest::run runs bvhopt.
  Result run_program(const fs::path& program, const std::string& args) {
    const fs::path out = dir_ / "reader-out.txt", err = dir_ / "reader-err.txt";
    const std::string cmd = program.string() + " " + args + " >" + out.string() + " 2>" + err.string() + " </dev/null";
    const int status = std::system(cmd.c_str());
    return {WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status), bvhopt::testing::read_text(out),
            bvhopt::testing::read_text(err)};
  }

  fs::path rays_file(const std::string& kind) const { return dir_ / (kind + ".rays"); }
  fs::path hits_file(const std::string& kind, const std::string& who) const { return dir_ / (kind + "-" + who + ".hits"); }

  fs::path reader_;
};

constexpr const char* kScene = "builtin?triangles=4000";

TEST_F(WideExportCli, ReaderTracesFlatBvh8LikeBvhopt) {
  trace_sets(kScene, "--leaf-size 4", "bvh8");
  expect_reader_agrees(kScene, "bvh8", "flat");
}

TEST_F(WideExportCli, ReaderTracesFlatBvh4LikeBvhopt) {
  trace_sets(kScene, "--leaf-size 4", "bvh4");
  expect_reader_agrees(kScene, "bvh4", "flat");
}

TEST_F(WideExportCli, ReaderTracesCwbvhLikeBvhopt) {
  trace_sets(kScene, "--leaf-size 8", "bvh8");
  expect_reader_agrees(kScene, "bvh8", "cwbvh");
}

TEST_F(WideExportCli, EdgeVolumeSubdividedTreesExportToo) {
  trace_sets(kScene, "--evh --evh-t 16 --leaf-size 4", "bvh8");
  expect_reader_agrees(kScene, "bvh8", "flat");
  expect_reader_agrees(kScene, "bvh8", "cwbvh");
}

TEST_F(WideExportCli, BadInputGetsClearErrorsAndNoOutput) {
  const std::string bvh = (dir_ / "s.bvh").string();
  ASSERT_EQ(run("build '" + std::string(kScene) + "' -o " + bvh).exit_code, 0);
  const fs::path out = dir_ / "out.wbvh";
  Result r = run("export " + bvh + " --scene '" + kScene + "' --layout bvh4 --format cwbvh -o " + out.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("needs --layout bvh8"), std::string::npos) << r.err;
  r = run("export " + bvh + " --scene 'builtin?triangles=20000' -o " + out.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("pass the scene the tree was built from"), std::string::npos) << r.err;
  r = run("export " + (dir_ / "nothing.bvh").string() + " --scene '" + kScene + "' -o " + out.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("nothing.bvh"), std::string::npos) << r.err;
  r = run("export " + bvh + " --scene '" + kScene + "' --format bvh -o " + out.string());
  EXPECT_EQ(r.exit_code, 2) << r.err;
  r = run("export " + bvh + " --scene '" + kScene + "' -o " + (dir_ / "no-folder" / "x.wbvh").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_FALSE(fs::exists(out));
  EXPECT_FALSE(fs::exists(dir_ / "no-folder"));

  // The reader refuses a damaged file by its checksum, a truncated one by its sections.
  ASSERT_EQ(run("export " + bvh + " --scene '" + kScene + "' --format cwbvh -o " + out.string()).exit_code, 0);
  ASSERT_EQ(run("trace " + bvh + " --scene '" + kScene + "' --rays random --count 100 --repeats 1 --save-rays " +
                (dir_ / "r.rays").string()).exit_code, 0);
  std::string bytes = bvhopt::testing::read_text(out);
  bytes[bytes.size() / 2] ^= 1;
  std::ofstream(dir_ / "damaged.wbvh", std::ios::binary) << bytes;
  std::ofstream(dir_ / "short.wbvh", std::ios::binary) << bytes.substr(0, bytes.size() - 48);
  std::string tail = " ";  // built by appending: GCC 12 warns falsely (-Wrestrict) on " " + std::string
  tail += (dir_ / "r.rays").string() + " " + (dir_ / "h.txt").string();
  r = run_program(reader_, (dir_ / "damaged.wbvh").string() + tail);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("checksum mismatch"), std::string::npos) << r.err;
  r = run_program(reader_, (dir_ / "short.wbvh").string() + tail);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("outside the file"), std::string::npos) << r.err;
}

}  // namespace
