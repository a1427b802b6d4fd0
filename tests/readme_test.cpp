#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <string>

namespace {

std::string read_file(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// The example a reader copies from the README is the one CTest compiles and runs.
TEST(Readme, ShowsTheExampleThatTheTestsRun) {
  std::string readme = read_file(std::string(BVHOPT_SOURCE_DIR) + "/README.md");
  std::string example = read_file(std::string(BVHOPT_SOURCE_DIR) + "/examples/quickstart.cpp");
  ASSERT_FALSE(example.empty());
  EXPECT_NE(readme.find(example), std::string::npos) << "README.md must contain examples/quickstart.cpp verbatim";
}

// The README opens with the two set-up commands, and CI runs the second.
TEST(Readme, OpensWithTheDemoAndTestCommands) {
  std::string readme = read_file(std::string(BVHOPT_SOURCE_DIR) + "/README.md");
  size_t demo = readme.find("bash scripts/run-demo.sh");
  size_t tests = readme.find("bash scripts/run-tests.sh");
  ASSERT_NE(demo, std::string::npos);
  ASSERT_NE(tests, std::string::npos);
  EXPECT_LT(demo, 2000u);
  EXPECT_LT(tests, 2000u);
  std::string ci = read_file(std::string(BVHOPT_SOURCE_DIR) + "/.ci/run");
  EXPECT_NE(ci.find("bash scripts/run-tests.sh"), std::string::npos);
}

}  // namespace
