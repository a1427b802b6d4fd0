// Helpers shared by the tests: random scenes, the scenes folder, tree invariants.
#pragma once

#include <cstdint>
#include <filesystem>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "bvhopt/bvh.h"
#include "bvhopt/mesh.h"
#include "bvhopt/references.h"

namespace bvhopt::testing {

// The shared scenes folder: $BVHOPT_SCENES if set, else ../shared/scenes beside the repository.
std::filesystem::path scenes_dir();

// One scene of the shared folder's MANIFEST.tsv.
struct ManifestRow {
  std::string file;
  uint64_t triangles = 0;
  std::string kind;  // architectural (interiors), scanned, other
};

// MANIFEST.tsv: a header naming the columns, then one scene a line; the columns are
// found by name so that adding one does not break the tests. Problems are test failures.
std::vector<ManifestRow> read_manifest(const std::filesystem::path& path);

// BVHOPT_SKIP_LARGE=1 (the sanitizer run): tests leave out scenes above 100k triangles.
bool skip_large_scenes();

// A soup of `triangles` random triangles in [0, extent]^3, sizes varying over two orders of
// magnitude, with some degenerate ones when `with_degenerate` is set. Deterministic in seed.
Mesh random_mesh(uint32_t triangles, uint64_t seed, bool with_degenerate = false);

// `count` random boxes, for builder and optimizer tests that need no triangles.
PrimitiveRefs random_refs(uint32_t count, uint64_t seed);

// The exact minimum SAH cost (c_T, c_I) over all binary trees with one reference per leaf,
// by dynamic programming over subsets; count <= 12. Not normalized by the root area.
double optimal_tree_cost(const PrimitiveRefs& refs, double c_t, double c_i);

// A tree in which each node's children appear in the same order, as a string such as
// "((0,1),2)" of triangle ids: two trees are the same tree exactly when the strings match.
std::string tree_signature(const Bvh& bvh, const PrimitiveRefs& refs);

// Success when two trees have the same root and nodes (boxes, links and parents, bit for
// bit) and the same leaf slots; else the first difference.
::testing::AssertionResult same_nodes(const Bvh& got, const Bvh& want);

// |a - b| relative to |b|: how far a tracked cost is from the cost recomputed from scratch.
double relative_gap(double a, double b);

// The object-median tree of `refs`: a poor start that leaves the optimizers much to do.
Bvh median_tree(const PrimitiveRefs& refs);

// The whole contents of a file ("" when it cannot be read).
std::string read_text(const std::filesystem::path& path);

// A test that runs the bvhopt program (ctest passes its folder in BVHOPT_BIN_DIR) inside a
// fresh temporary folder `dir_`, removed afterwards. Skipped when the program is not there.
class ProgramTest : public ::testing::Test {
 public:
  struct Result {
    int exit_code = 0;
    std::string out, err;
  };

 protected:
  void SetUp() override;
  void TearDown() override;
  // Runs `bvhopt ARGS` through the shell (ARGS may quote), with no standard input.
  Result run(const std::string& args);

  std::filesystem::path exe_, dir_;
};

}  // namespace bvhopt::testing
