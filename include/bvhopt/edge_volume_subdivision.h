// Edge volume heuristic (Dammertz and Keller 2008): subdivide triangles whose edges have
// fat axis-aligned boxes, and hand the builders one reference per piece.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "bvhopt/box.h"
#include "bvhopt/mesh.h"
#include "bvhopt/references.h"
#include "bvhopt/triangle.h"

namespace bvhopt {

struct EdgeVolumeConfig {
  // The threshold exponent: a triangle is split while the volume of its largest edge box
  // exceeds eps_v = V / 2^t, V the volume of the scene box (section 2.2). 14 is the
  // paper's default; each step of t up roughly doubles the volume an edge may have less.
  int t = 14;
  // Guard against pathological input (a single thin diagonal triangle, or huge t): no
  // triangle is split more than max_depth times along one path, so it makes at most
  // 2^max_depth pieces. A piece at this depth stays as it is even if its edges are still
  // fat; EdgeVolumeStats::depth_limited counts them. At most 30 (larger is an Error).
  uint32_t max_depth = 24;
  // Guard on memory: at most max_reference_ratio * triangles references in all. When the
  // count pass finds more, t is lowered by one and counted again until it fits; the t that
  // was used is EdgeVolumeStats::effective_t and budget_hit says it happened. 0 = no limit;
  // otherwise at least 1 (since t <= 0 never splits, the loop always ends).
  double max_reference_ratio = 8.0;
  // The box whose volume is V. Empty (the default): the mesh's own bounds. An animation
  // passes one box for all frames when it wants one threshold for all of them.
  Box scene_box;
};

struct EdgeVolumeStats {
  size_t triangles = 0;
  size_t references = 0;
  double ratio = 1.0;                  // references / triangles
  size_t subdivided_triangles = 0;     // triangles split at least once
  uint32_t deepest = 0;                // most splits along one path in any triangle
  size_t depth_limited = 0;            // pieces left unsplit only because of max_depth
  bool depth_limit_hit = false;        // depth_limited > 0
  bool budget_hit = false;             // t was lowered to fit max_reference_ratio
  int effective_t = 14;                // the t that produced the output
  double scene_volume = 0.0;           // V
  double threshold = 0.0;              // eps_v for effective_t
};

struct EdgeVolumeResult {
  // One reference per piece, grouped by triangle in triangle order; a triangle's pieces in
  // the depth-first order of its subdivision. Box: the bounds of the piece's exact
  // vertices; centroid: the box centre; id: the original triangle.
  PrimitiveRefs refs;
  EdgeVolumeStats stats;
};

// A count pass sizes the output exactly, a prefix sum gives each triangle its offset, and a
// fill pass writes the references; both passes run in parallel with oneTBB and the result
// does not depend on the thread count. Split points depend only on an edge's two end
// points (ordered lexicographically, then the midpoint), so triangles sharing an edge split
// it at the same points and a watertight mesh stays watertight (section 2.1). Zero-volume
// edges (axis-aligned in some dimension) are never split, so degenerate triangles whose
// box is flat pass untouched. Throws Error for a bad config.
EdgeVolumeResult subdivide_edge_volume(const Mesh& mesh, const EdgeVolumeConfig& config = {});

// The count pass alone (with the budget loop): the statistics subdivide_edge_volume would
// report, without allocating the references. For `bvhopt info --evh-t N`.
EdgeVolumeStats count_edge_volume(const Mesh& mesh, const EdgeVolumeConfig& config = {});

// The pieces themselves, as triangles, in the order of subdivide_edge_volume's references
// (reference i is the bounds of triangles[i]). For tests and for looking at the result;
// builders only need the references.
struct SubdividedTriangles {
  std::vector<Triangle> triangles;
  std::vector<uint32_t> triangle_ids;
  EdgeVolumeStats stats;
};
SubdividedTriangles subdivide_edge_volume_triangles(const Mesh& mesh, const EdgeVolumeConfig& config = {});

// Table 1 of the paper: for every split, each of the two new pieces' box area divided by
// the area of the box of the piece it was split from. Both boxes are bounds of exact
// vertices and the midpoint halves the split edge, so every factor lies in [0.25, 1] (up
// to the rounding of the float midpoint, a relative 1e-6 or so):
// 0.25 when the piece's box halves in all three dimensions (a needle along a diagonal),
// 1 when the split changes no extreme. best = smallest factor, worst = largest.
struct AreaReduction {
  size_t splits = 0;      // factors counted = 2 * splits
  double best = 0.0;
  double average = 0.0;
  double worst = 0.0;
  EdgeVolumeStats stats;  // of the subdivision measured (same config rules, budget loop too)
};
// Deterministic (a fixed reduction order), on any thread count.
AreaReduction area_reduction_factors(const Mesh& mesh, const EdgeVolumeConfig& config = {});

}  // namespace bvhopt
