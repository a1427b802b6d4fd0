#include <gtest/gtest.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <thread>

#include <filesystem>
#include <fstream>

#include "bvhopt/atomic_file.h"
#include "bvhopt/error.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace bvhopt {
namespace {

class AtomicFile : public ::testing::Test {
 protected:
  void SetUp() override {
    // ctest runs each test in its own process, two at a time: the process id
    // and the test's name keep two tests from emptying each other's folder.
    const ::testing::TestInfo* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("bvhopt_atomic_" + std::to_string(::getpid()) + "_" + info->name());
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
  EXPECT_EQ(testing::read_text(p), "first");
  write_text_atomically(p, "second, longer");
  EXPECT_EQ(testing::read_text(p), "second, longer");
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
  EXPECT_EQ(testing::read_text(p), "old contents");
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

// A device node stands for something that is not ours: it is written to, never replaced.
// The nodes are made in the test's folder (root only) so the test cannot damage /dev.
TEST_F(AtomicFile, DeviceIsWrittenThroughNeverReplaced) {
  fs::path null_node = dir_ / "null";
  if (::mknod(null_node.c_str(), S_IFCHR | 0666, makedev(1, 3)) != 0) GTEST_SKIP() << "mknod needs root";
  write_text_atomically(null_node, "into the void");
  EXPECT_TRUE(fs::is_character_file(null_node)) << "the device node was replaced";
  EXPECT_EQ(entries(), 1u);
}

TEST_F(AtomicFile, FullDeviceFailsClearlyAndStaysADevice) {
  fs::path full_node = dir_ / "full";
  if (::mknod(full_node.c_str(), S_IFCHR | 0666, makedev(1, 7)) != 0) GTEST_SKIP() << "mknod needs root";
  try {
    write_text_atomically(full_node, "x");
    FAIL() << "writing to a full device must fail";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("full"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(fs::is_character_file(full_node));
  EXPECT_EQ(entries(), 1u);
}

TEST_F(AtomicFile, FifoWithAReaderIsWrittenThrough) {
  fs::path fifo = dir_ / "pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  std::string got;
  int fd = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK);  // the reader is there before the writer
  ASSERT_GE(fd, 0);
  write_text_atomically(fifo, "through the pipe");
  char buf[64];
  ssize_t n = ::read(fd, buf, sizeof buf);
  ::close(fd);
  ASSERT_GT(n, 0);
  EXPECT_EQ(std::string(buf, size_t(n)), "through the pipe");
  EXPECT_TRUE(fs::is_fifo(fifo));
}

// Without a reader, opening a FIFO for writing would block forever: it is an error at once.
TEST_F(AtomicFile, FifoWithoutAReaderIsAnErrorNotAHang) {
  fs::path fifo = dir_ / "pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  try {
    write_text_atomically(fifo, "x");
    FAIL() << "expected an Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("reader"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(fs::is_fifo(fifo));
  EXPECT_EQ(entries(), 1u);
}

// A symlink is written through: its target gets the new contents, the link stays a link.
TEST_F(AtomicFile, SymlinkIsWrittenThrough) {
  fs::create_directories(dir_ / "real");
  fs::path target = dir_ / "real" / "out.txt";
  write_text_atomically(target, "old");
  fs::path link = dir_ / "link.txt";
  fs::create_symlink(fs::path("real") / "out.txt", link);
  write_text_atomically(link, "new");
  EXPECT_TRUE(fs::is_symlink(link));
  EXPECT_EQ(testing::read_text(target), "new");
  EXPECT_EQ(entries(), 2u);
}

// A dangling symlink creates its target, the link stays.
TEST_F(AtomicFile, DanglingSymlinkCreatesItsTarget) {
  fs::path link = dir_ / "link.txt";
  fs::create_symlink("made_through_link.txt", link);
  write_text_atomically(link, "new");
  EXPECT_TRUE(fs::is_symlink(link));
  EXPECT_EQ(testing::read_text(dir_ / "made_through_link.txt"), "new");
}

}  // namespace
}  // namespace bvhopt
