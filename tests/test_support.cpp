#include "test_support.h"

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <limits>
#include <vector>

#include "bvhopt/median_builder.h"

namespace bvhopt::testing {

std::filesystem::path scenes_dir() {
  if (const char* env = std::getenv("BVHOPT_SCENES"); env && *env) return env;
  return BVHOPT_DEFAULT_SCENES_DIR;
}

Mesh random_mesh(uint32_t triangles, uint64_t seed, bool with_degenerate) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> pos(0.0f, 100.0f);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  std::uniform_real_distribution<float> logsize(-1.0f, 1.0f);
  Mesh mesh;
  mesh.name = "random(" + std::to_string(seed) + ")";
  for (uint32_t t = 0; t < triangles; ++t) {
    Vec3 c(pos(rng), pos(rng), pos(rng));
    float s = std::pow(10.0f, logsize(rng));
    uint32_t base = static_cast<uint32_t>(mesh.vertex_count());
    Vec3 a = c + Vec3(unit(rng), unit(rng), unit(rng)) * s;
    Vec3 b = c + Vec3(unit(rng), unit(rng), unit(rng)) * s;
    Vec3 d = c + Vec3(unit(rng), unit(rng), unit(rng)) * s;
    if (with_degenerate && t % 7 == 3) d = a;  // coincident vertices: zero area
    mesh.add_vertex(a);
    mesh.add_vertex(b);
    mesh.add_vertex(d);
    mesh.add_triangle(base, base + 1, base + 2);
  }
  return mesh;
}

PrimitiveRefs random_refs(uint32_t count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> pos(0.0f, 10.0f);
  std::uniform_real_distribution<float> size(0.01f, 2.0f);
  std::vector<Box> boxes(count);
  for (auto& b : boxes) {
    Vec3 lo(pos(rng), pos(rng), pos(rng));
    b = Box(lo, lo + Vec3(size(rng), size(rng), size(rng)));
  }
  return make_references(boxes);
}

double optimal_tree_cost(const PrimitiveRefs& refs, double c_t, double c_i) {
  const uint32_t n = static_cast<uint32_t>(refs.size());
  const uint32_t full = (1u << n) - 1;
  std::vector<double> area(full + 1, 0.0), best(full + 1, std::numeric_limits<double>::infinity());
  for (uint32_t s = 1; s <= full; ++s) {
    Box b;
    for (uint32_t i = 0; i < n; ++i)
      if (s & (1u << i)) b.extend(refs.boxes[i]);
    area[s] = b.area();
  }
  for (uint32_t s = 1; s <= full; ++s) {
    if ((s & (s - 1)) == 0) {  // one reference: a leaf
      best[s] = c_i * area[s];
      continue;
    }
    // Each unordered split once: the part holding the lowest set bit is the left one.
    uint32_t low = s & (~s + 1);
    for (uint32_t l = (s - 1) & s; l > 0; l = (l - 1) & s) {
      if (!(l & low)) continue;
      double c = best[l] + best[s ^ l];
      if (c < best[s]) best[s] = c;
    }
    best[s] += c_t * area[s];
  }
  return best[full];
}

std::string tree_signature(const Bvh& bvh, const PrimitiveRefs& refs) {
  if (bvh.empty()) return "";
  auto rec = [&](auto&& self, uint32_t n) -> std::string {
    const BvhNode& nd = bvh[n];
    if (nd.is_leaf()) {
      std::string s = "[";
      for (uint32_t i = 0; i < nd.ref_count(); ++i) {
        if (i) s += ' ';
        s += std::to_string(refs.triangle_ids[bvh.ref_indices[nd.first_ref() + i]]);
      }
      return s + "]";
    }
    std::string s = "(";
    s += self(self, nd.left());
    s += ',';
    s += self(self, nd.right());
    s += ')';
    return s;
  };
  return rec(rec, bvh.root);
}

::testing::AssertionResult same_nodes(const Bvh& got, const Bvh& want) {
  if (got.root != want.root) return ::testing::AssertionFailure() << "root " << got.root << ", want " << want.root;
  if (got.nodes.size() != want.nodes.size())
    return ::testing::AssertionFailure() << got.nodes.size() << " nodes, want " << want.nodes.size();
  for (size_t i = 0; i < want.nodes.size(); ++i) {
    const BvhNode &a = got.nodes[i], &w = want.nodes[i];
    if (!(a.box == w.box) || a.parent != w.parent || a.left_or_first != w.left_or_first ||
        a.right_or_count != w.right_or_count)
      return ::testing::AssertionFailure() << "node " << i << " differs";
  }
  if (got.ref_indices != want.ref_indices) return ::testing::AssertionFailure() << "leaf slots differ";
  return ::testing::AssertionSuccess();
}

double relative_gap(double a, double b) { return std::abs(a - b) / std::max(std::abs(b), 1e-300); }

Bvh median_tree(const PrimitiveRefs& refs) { return build_object_median(refs, MedianConfig{}); }

std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void ProgramTest::SetUp() {
  const char* bin = std::getenv("BVHOPT_BIN_DIR");
  if (!bin) GTEST_SKIP() << "BVHOPT_BIN_DIR not set (run through ctest)";
  exe_ = std::filesystem::path(bin) / "bvhopt";
  if (!std::filesystem::exists(exe_)) GTEST_SKIP() << "bvhopt program not built";
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  dir_ = std::filesystem::temp_directory_path() /
         ("bvhopt_" + std::string(info->test_suite_name()) + "_" + info->name() + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir_);
  std::filesystem::create_directories(dir_);
}

void ProgramTest::TearDown() {
  if (!dir_.empty()) std::filesystem::remove_all(dir_);
}

ProgramTest::Result ProgramTest::run(const std::string& args) {
  const std::filesystem::path out = dir_ / "stdout.txt", err = dir_ / "stderr.txt";
  const std::string cmd = exe_.string() + " " + args + " >" + out.string() + " 2>" + err.string() + " </dev/null";
  const int status = std::system(cmd.c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status), read_text(out), read_text(err)};
}

std::vector<ManifestRow> read_manifest(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) ADD_FAILURE() << "cannot open " << path;
  auto split = [](const std::string& line) {
    std::vector<std::string> cells;
    std::stringstream s(line);
    for (std::string cell; std::getline(s, cell, '\t');) cells.push_back(cell);
    return cells;
  };
  std::string line;
  std::getline(in, line);
  const auto header = split(line);
  int file_col = -1, tri_col = -1, kind_col = -1;
  for (size_t i = 0; i < header.size(); ++i) {
    if (header[i] == "file") file_col = static_cast<int>(i);
    if (header[i] == "triangles") tri_col = static_cast<int>(i);
    if (header[i] == "kind") kind_col = static_cast<int>(i);
  }
  if (file_col < 0 || tri_col < 0) {
    ADD_FAILURE() << path << ": header lacks 'file' or 'triangles': " << line;
    return {};
  }
  std::vector<ManifestRow> rows;
  for (int n = 2; std::getline(in, line); ++n) {
    if (line.empty()) continue;
    const auto cells = split(line);
    if (cells.size() <= static_cast<size_t>(std::max({file_col, tri_col, kind_col}))) {
      ADD_FAILURE() << path << ": line " << n << " has too few columns";
      continue;
    }
    rows.push_back({cells[file_col], std::stoull(cells[tri_col]), kind_col >= 0 ? cells[kind_col] : std::string()});
  }
  return rows;
}

bool skip_large_scenes() {
  const char* env = std::getenv("BVHOPT_SKIP_LARGE");
  return env && std::string(env) == "1";
}

}  // namespace bvhopt::testing
