#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "bvhopt/atomic_file.h"
#include "bvhopt/error.h"

namespace fs = std::filesystem;

namespace bvhopt {
namespace {

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

class AtomicFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("bvhopt_atomic_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  size_t entries() const { return std::distance(fs::directory_iterator(dir_), fs::directory_iterator()); }
  fs::path dir_;
};

TEST_F(AtomicFile, WritesAndReplaces) {
  fs::path p = dir_ / "out.txt";
  write_text_atomically(p, "first");
  EXPECT_EQ(slurp(p), "first");
  write_text_atomically(p, "second, longer");
  EXPECT_EQ(slurp(p), "second, longer");
  EXPECT_EQ(entries(), 1u) << "no temporary left behind";
}

// A writer that fails half way leaves the old file as it was and no temporary.
TEST_F(AtomicFile, FailedWriteLeavesTheOldFileAndNoTemporary) {
  fs::path p = dir_ / "out.txt";
  write_text_atomically(p, "old contents");
  EXPECT_THROW(write_atomically(p,
                                [](const fs::path& tmp) {
                                  std::ofstream(tmp) << "half of the new";
                                  throw Error("disk full");
                                }),
               Error);
  EXPECT_EQ(slurp(p), "old contents");
  EXPECT_EQ(entries(), 1u);
}

TEST_F(AtomicFile, MissingFolderIsAnErrorNamingTheFile) {
  fs::path p = dir_ / "no_such_folder" / "out.csv";
  try {
    write_text_atomically(p, "x");
    FAIL() << "expected an Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("out.csv"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(dir_ / "no_such_folder"));
}

// The target is a folder: the rename fails, the temporary is removed, the folder stays.
TEST_F(AtomicFile, RenameFailureRemovesTheTemporary) {
  fs::path p = dir_ / "a_folder";
  fs::create_directories(p / "inside");
  EXPECT_THROW(write_text_atomically(p, "x"), Error);
  EXPECT_TRUE(fs::is_directory(p / "inside"));
  EXPECT_EQ(entries(), 1u);
}

}  // namespace
}  // namespace bvhopt
