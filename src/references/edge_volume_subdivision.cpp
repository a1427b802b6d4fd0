// Edge volume heuristic: see include/bvhopt/edge_volume_subdivision.h.
#include "bvhopt/edge_volume_subdivision.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/partitioner.h>

#include <algorithm>
#include <cmath>
#include <atomic>
#include <cstdint>
#include <limits>
#include <string>

#include "bvhopt/error.h"

namespace bvhopt {
namespace {

constexpr uint32_t kMaxDepthLimit = 30;  // 2^30 pieces still count in uint32_t
// Triangles per task: big enough that the per-task overhead vanishes against three edge
// volumes per triangle, small enough that a few heavily split triangles do not serialize.
constexpr size_t kGrain = 2048;

struct Params {
  double eps = 0.0;
  uint32_t max_depth = 0;
  // A count pass stops a triangle after this many pieces: one triangle alone above the
  // reference budget already misses it, and counting its 2^max_depth pieces would take
  // minutes at a large t.
  uint64_t piece_cap = UINT64_MAX;
};

// Volume of the box of edge p-q. |p - q| equals |q - p| exactly in IEEE arithmetic, so both
// triangles that share the edge see the same volume. Double so that tiny scenes do not
// underflow. A NaN volume never compares greater than eps: such edges are not split.
inline double edge_volume(const Vec3& p, const Vec3& q) {
  return static_cast<double>(std::fabs(p.x - q.x)) * static_cast<double>(std::fabs(p.y - q.y)) *
         static_cast<double>(std::fabs(p.z - q.z));
}

inline bool lex_less(const Vec3& a, const Vec3& b) {
  if (a.x != b.x) return a.x < b.x;
  if (a.y != b.y) return a.y < b.y;
  return a.z < b.z;
}

// The split point of an edge, a function of the unordered pair of end points: ordering them
// first makes the result independent of which triangle (and which winding) asks. The
// rounded sum lies between 2*min and 2*max per coordinate and halving is exact, so the
// midpoint never leaves the edge's box and a piece's box never leaves its parent's.
inline Vec3 edge_midpoint(const Vec3& p, const Vec3& q) {
  const Vec3& lo = lex_less(q, p) ? q : p;
  const Vec3& hi = lex_less(q, p) ? p : q;
  return {(lo.x + hi.x) * 0.5f, (lo.y + hi.y) * 0.5f, (lo.z + hi.z) * 0.5f};
}

inline Box bounds_of(const Vec3& a, const Vec3& b, const Vec3& c) {
  return Box(min(min(a, b), c), max(max(a, b), c));
}

struct PieceStats {
  uint32_t pieces = 0;
  uint32_t deepest = 0;
  uint32_t depth_limited = 0;
};

// Subdivides one triangle depth-first (first piece first), calling leaf(a, b, c) for each
// final piece and split(parent corners, first piece's, second piece's) for each split.
// Explicit stack: the second piece waits while the first is finished, so at most
// max_depth wait.
template <class Leaf, class Split>
inline PieceStats subdivide_one(const Vec3& v0, const Vec3& v1, const Vec3& v2, const Params& params,
                                Leaf&& leaf, Split&& split) {
  struct Item {
    Vec3 v[3];
    uint32_t depth;
  };
  // Pieces waiting for their turn. Raw storage: Vec3 zero-initializes, and clearing 1 KB per
  // triangle cost more than the whole test of an unsplit triangle.
  struct Pending {
    float v[9];
    uint32_t depth;
  };
  Pending stack[kMaxDepthLimit + 1];
  auto push = [&](const Vec3& a, const Vec3& b, const Vec3& c, uint32_t depth, uint32_t at) {
    stack[at] = Pending{{a.x, a.y, a.z, b.x, b.y, b.z, c.x, c.y, c.z}, depth};
  };
  auto pop = [&](uint32_t at) {
    const float* f = stack[at].v;
    return Item{{Vec3(f[0], f[1], f[2]), Vec3(f[3], f[4], f[5]), Vec3(f[6], f[7], f[8])}, stack[at].depth};
  };
  uint32_t top = 0;
  PieceStats stats;
  Item cur{{v0, v1, v2}, 0};
  for (;;) {
    const double vol[3] = {edge_volume(cur.v[0], cur.v[1]), edge_volume(cur.v[1], cur.v[2]),
                           edge_volume(cur.v[2], cur.v[0])};
    // Most triangles are not split: test the largest volume without data-dependent branches
    // first (the branch on the result is predictable); choose the edge only when splitting.
    const double largest = std::max(std::max(vol[0], vol[1]), vol[2]);
    int e = 0;
    if (largest > params.eps) {
      if (vol[1] > vol[e]) e = 1;
      if (vol[2] > vol[e]) e = 2;
    }
    if (largest > params.eps && vol[e] > params.eps) {
      if (cur.depth < params.max_depth) {
        // Edge e runs from p to q; r is the opposite corner. Both pieces keep the winding.
        const Vec3 p = cur.v[e], q = cur.v[(e + 1) % 3], r = cur.v[(e + 2) % 3];
        const Vec3 m = edge_midpoint(p, q);
        const uint32_t d = cur.depth + 1;
        split(cur.v[0], cur.v[1], cur.v[2], p, m, r, m, q, r);
        push(m, q, r, d, top++);
        cur = Item{{p, m, r}, d};
        continue;
      }
      ++stats.depth_limited;
    }
    leaf(cur.v[0], cur.v[1], cur.v[2]);
    ++stats.pieces;
    stats.deepest = std::max(stats.deepest, cur.depth);
    if (top == 0 || stats.pieces > params.piece_cap) break;
    cur = pop(--top);
  }
  return stats;
}

struct NoLeaf {
  void operator()(const Vec3&, const Vec3&, const Vec3&) const {}
};
struct NoSplit {
  void operator()(const Vec3&, const Vec3&, const Vec3&, const Vec3&, const Vec3&, const Vec3&, const Vec3&,
                  const Vec3&, const Vec3&) const {}
};

// Reads triangle t's corners straight from the mesh arrays.
struct Corners {
  const float* pos;
  const uint32_t* idx;
  Vec3 get(size_t t, int k) const {
    const float* p = pos + 3 * static_cast<size_t>(idx[3 * t + k]);
    return {p[0], p[1], p[2]};
  }
};

void check_input(const Mesh& mesh, const EdgeVolumeConfig& config) {
  const std::string name = mesh.name.empty() ? std::string("mesh") : mesh.name;
  if (config.max_depth > kMaxDepthLimit)
    throw Error(name + ": edge volume subdivision: max_depth " + std::to_string(config.max_depth) +
                " exceeds " + std::to_string(kMaxDepthLimit));
  if (!(config.max_reference_ratio == 0.0 || config.max_reference_ratio >= 1.0))
    throw Error(name + ": edge volume subdivision: max_reference_ratio " +
                std::to_string(config.max_reference_ratio) + " must be 0 (no limit) or at least 1");
  if (config.t < -1000 || config.t > 1000)
    throw Error(name + ": edge volume subdivision: t " + std::to_string(config.t) + " out of range");
  if (mesh.positions.size() % 3 != 0)
    throw Error(name + ": position array holds " + std::to_string(mesh.positions.size()) +
                " floats, not a multiple of 3");
  if (mesh.indices.size() % 3 != 0)
    throw Error(name + ": index array holds " + std::to_string(mesh.indices.size()) +
                " indices, not a multiple of 3");
}

// The volume of the scene box: config.scene_box, or the bounds of the mesh's vertices (one
// contiguous parallel read; min and max do not depend on how the blocks combine).
double scene_volume(const Mesh& mesh, const EdgeVolumeConfig& config) {
  Box box = config.scene_box;
  if (box.is_empty()) {
    const float* pos = mesh.positions.data();
    box = tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, mesh.vertex_count(), 4 * kGrain), Box{},
        [&](const tbb::blocked_range<size_t>& r, Box acc) {
          for (size_t v = r.begin(); v != r.end(); ++v) acc.extend(Vec3(pos[3 * v], pos[3 * v + 1], pos[3 * v + 2]));
          return acc;
        },
        [](Box x, const Box& y) {
          x.extend(y);
          return x;
        });
  }
  if (box.is_empty()) return 0.0;
  const Vec3 e = box.extent();
  return static_cast<double>(e.x) * static_cast<double>(e.y) * static_cast<double>(e.z);
}

struct CountTotals {
  size_t first_bad = SIZE_MAX;  // first triangle with a vertex index out of range
  uint64_t references = 0;
  size_t subdivided = 0;
  uint32_t deepest = 0;
  size_t depth_limited = 0;
};

// The count pass: pieces per triangle into counts, totals returned. Integer sums and
// maxima, so the reduction order does not matter. The pass gives up once the pieces
// counted so far exceed `budget` (the totals are then a partial count above it): its cost
// is bounded by the budget, not by 2^max_depth pieces per triangle.
CountTotals count_pass(const Mesh& mesh, const Params& params, double budget, std::vector<uint32_t>* counts) {
  const Corners c{mesh.positions.data(), mesh.indices.data()};
  const size_t n = mesh.triangle_count();
  const size_t nv = mesh.vertex_count();
  std::atomic<uint64_t> counted{0};
  auto over_budget = [&] { return static_cast<double>(counted.load(std::memory_order_relaxed)) > budget; };
  return tbb::parallel_reduce(
      tbb::blocked_range<size_t>(0, n, kGrain), CountTotals{},
      [&](const tbb::blocked_range<size_t>& r, CountTotals acc) {
        uint64_t block_pieces = 0;
        for (size_t t = r.begin(); t != r.end(); ++t) {
          if (block_pieces > 4096) {
            counted.fetch_add(block_pieces, std::memory_order_relaxed);
            block_pieces = 0;
          }
          if (over_budget()) {
            acc.references = std::max<uint64_t>(acc.references, counted.load(std::memory_order_relaxed));
            return acc;
          }
          // The index check rides on the count pass, which reads the indices anyway.
          if (c.idx[3 * t] >= nv || c.idx[3 * t + 1] >= nv || c.idx[3 * t + 2] >= nv) {
            acc.first_bad = std::min(acc.first_bad, t);
            ++acc.references;
            continue;
          }
          const PieceStats s = subdivide_one(c.get(t, 0), c.get(t, 1), c.get(t, 2), params, NoLeaf{}, NoSplit{});
          if (counts) (*counts)[t] = s.pieces;
          acc.references += s.pieces;
          block_pieces += s.pieces;
          acc.subdivided += s.pieces > 1;
          acc.deepest = std::max(acc.deepest, s.deepest);
          acc.depth_limited += s.depth_limited;
        }
        counted.fetch_add(block_pieces, std::memory_order_relaxed);
        return acc;
      },
      [](CountTotals a, const CountTotals& b) {
        a.first_bad = std::min(a.first_bad, b.first_bad);
        a.references += b.references;
        a.subdivided += b.subdivided;
        a.deepest = std::max(a.deepest, b.deepest);
        a.depth_limited += b.depth_limited;
        return a;
      });
}

Params params_for(double volume, int t, const EdgeVolumeConfig& config, double budget) {
  const uint64_t cap = budget >= 0x1p63 ? UINT64_MAX : static_cast<uint64_t>(budget);
  return Params{std::ldexp(volume, -t), config.max_depth, cap};
}

// Counts, lowering t until the budget holds. Fills counts (when given) for the t chosen.
EdgeVolumeStats count_with_budget(const Mesh& mesh, const EdgeVolumeConfig& config, std::vector<uint32_t>* counts,
                                  Params& params_out) {
  check_input(mesh, config);
  EdgeVolumeStats stats;
  stats.triangles = mesh.triangle_count();
  stats.scene_volume = scene_volume(mesh, config);
  const double budget = config.max_reference_ratio == 0.0
                            ? std::numeric_limits<double>::infinity()
                            : config.max_reference_ratio * static_cast<double>(stats.triangles);
  if (counts) counts->assign(stats.triangles, 1);
  int t = config.t;
  for (;;) {
    const Params params = params_for(stats.scene_volume, t, config, budget);
    const CountTotals totals = count_pass(mesh, params, budget, counts);
    if (totals.first_bad != SIZE_MAX) {
      const std::string name = mesh.name.empty() ? std::string("mesh") : mesh.name;
      const size_t nv = mesh.vertex_count();
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = mesh.indices[3 * totals.first_bad + k];
        if (v >= nv)
          throw Error(name + ": triangle " + std::to_string(totals.first_bad) + ": vertex index " +
                      std::to_string(v) + " out of range (mesh has " + std::to_string(nv) + " vertices)");
      }
    }
    // t <= 0 gives eps >= V, and no edge box inside the scene box exceeds V, so the loop
    // ends there at the latest (a scene_box smaller than the mesh needs lower t; the
    // floor below stops that too, with the budget then reported as missed by the ratio).
    if (static_cast<double>(totals.references) <= budget || t <= -64) {
      stats.references = totals.references;
      stats.subdivided_triangles = totals.subdivided;
      stats.deepest = totals.deepest;
      stats.depth_limited = totals.depth_limited;
      stats.depth_limit_hit = totals.depth_limited > 0;
      stats.effective_t = t;
      stats.threshold = params.eps;
      params_out = params;
      break;
    }
    stats.budget_hit = true;
    --t;
  }
  stats.ratio = stats.triangles ? static_cast<double>(stats.references) / static_cast<double>(stats.triangles) : 1.0;
  return stats;
}

std::vector<size_t> prefix_offsets(const std::vector<uint32_t>& counts) {
  std::vector<size_t> offsets(counts.size() + 1);
  size_t sum = 0;
  for (size_t i = 0; i < counts.size(); ++i) {
    offsets[i] = sum;
    sum += counts[i];
  }
  offsets[counts.size()] = sum;
  return offsets;
}

}  // namespace

EdgeVolumeStats count_edge_volume(const Mesh& mesh, const EdgeVolumeConfig& config) {
  Params params;
  return count_with_budget(mesh, config, nullptr, params);
}

EdgeVolumeResult subdivide_edge_volume(const Mesh& mesh, const EdgeVolumeConfig& config) {
  EdgeVolumeResult result;
  std::vector<uint32_t> counts;
  Params params;
  result.stats = count_with_budget(mesh, config, &counts, params);
  const std::vector<size_t> offsets = prefix_offsets(counts);
  PrimitiveRefs& refs = result.refs;
  refs.resize(offsets.back());
  Box* boxes = refs.boxes.data();
  Vec3* centroids = refs.centroids.data();
  uint32_t* ids = refs.triangle_ids.data();
  const Corners c{mesh.positions.data(), mesh.indices.data()};
  tbb::parallel_for(tbb::blocked_range<size_t>(0, counts.size(), kGrain), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t t = r.begin(); t != r.end(); ++t) {
      size_t out = offsets[t];
      const Vec3 a = c.get(t, 0), b = c.get(t, 1), d = c.get(t, 2);
      if (counts[t] == 1) {
        const Box box = bounds_of(a, b, d);
        boxes[out] = box;
        centroids[out] = box.center();
        ids[out] = static_cast<uint32_t>(t);
        continue;
      }
      subdivide_one(
          a, b, d, params,
          [&](const Vec3& p, const Vec3& q, const Vec3& s) {
            const Box box = bounds_of(p, q, s);
            boxes[out] = box;
            centroids[out] = box.center();
            ids[out] = static_cast<uint32_t>(t);
            ++out;
          },
          NoSplit{});
    }
  });
  return result;
}

SubdividedTriangles subdivide_edge_volume_triangles(const Mesh& mesh, const EdgeVolumeConfig& config) {
  SubdividedTriangles result;
  std::vector<uint32_t> counts;
  Params params;
  result.stats = count_with_budget(mesh, config, &counts, params);
  const std::vector<size_t> offsets = prefix_offsets(counts);
  result.triangles.resize(offsets.back());
  result.triangle_ids.resize(offsets.back());
  const Corners c{mesh.positions.data(), mesh.indices.data()};
  tbb::parallel_for(tbb::blocked_range<size_t>(0, counts.size(), kGrain), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t t = r.begin(); t != r.end(); ++t) {
      size_t out = offsets[t];
      subdivide_one(
          c.get(t, 0), c.get(t, 1), c.get(t, 2), params,
          [&](const Vec3& p, const Vec3& q, const Vec3& s) {
            result.triangles[out] = Triangle{p, q, s};
            result.triangle_ids[out] = static_cast<uint32_t>(t);
            ++out;
          },
          NoSplit{});
    }
  });
  return result;
}

AreaReduction area_reduction_factors(const Mesh& mesh, const EdgeVolumeConfig& config) {
  Params params;
  AreaReduction out;
  out.stats = count_with_budget(mesh, config, nullptr, params);
  struct Acc {
    size_t splits = 0;
    double sum = 0.0;
    double best = std::numeric_limits<double>::infinity();
    double worst = -std::numeric_limits<double>::infinity();
  };
  const Corners c{mesh.positions.data(), mesh.indices.data()};
  // Deterministic reduce with a simple partitioner: the blocks and the order in which
  // their double sums are added depend only on the triangle count.
  const Acc acc = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<size_t>(0, mesh.triangle_count(), kGrain), Acc{},
      [&](const tbb::blocked_range<size_t>& r, Acc a) {
        for (size_t t = r.begin(); t != r.end(); ++t) {
          subdivide_one(c.get(t, 0), c.get(t, 1), c.get(t, 2), params, NoLeaf{},
                        [&](const Vec3& p0, const Vec3& p1, const Vec3& p2, const Vec3& a0, const Vec3& b0,
                            const Vec3& c0, const Vec3& a1, const Vec3& b1, const Vec3& c1) {
                          const double parent = bounds_of(p0, p1, p2).area();
                          const double f0 = bounds_of(a0, b0, c0).area() / parent;
                          const double f1 = bounds_of(a1, b1, c1).area() / parent;
                          ++a.splits;
                          a.sum += f0 + f1;
                          a.best = std::min({a.best, f0, f1});
                          a.worst = std::max({a.worst, f0, f1});
                        });
        }
        return a;
      },
      [](Acc a, const Acc& b) {
        a.splits += b.splits;
        a.sum += b.sum;
        a.best = std::min(a.best, b.best);
        a.worst = std::max(a.worst, b.worst);
        return a;
      },
      tbb::simple_partitioner());
  out.splits = acc.splits;
  if (acc.splits > 0) {
    out.best = acc.best;
    out.worst = acc.worst;
    out.average = acc.sum / (2.0 * static_cast<double>(acc.splits));
  }
  return out;
}

}  // namespace bvhopt
