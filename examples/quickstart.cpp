// Build a BVH over the built-in scene, optimize nothing yet, and print its SAH cost.
// Needs bvhopt::core only (no file formats).
#include <bvhopt/core.h>

#include <cstdio>

int main() {
  bvhopt::Mesh mesh = bvhopt::load_builtin_scene("builtin:atrium?triangles=20000");
  bvhopt::PrimitiveRefs refs = bvhopt::make_references(mesh);

  bvhopt::SweepSahConfig config;   // c_T = 3, c_I = 2, one reference per leaf
  bvhopt::Bvh bvh = bvhopt::build_sweep_sah(refs, config);

  bvhopt::ValidationReport report = bvhopt::validate(bvh, refs);
  if (!report.ok()) {
    std::fprintf(stderr, "invalid tree: %s\n", report.summary().c_str());
    return 1;
  }
  std::printf("%zu triangles, SAH cost %.2f, ocost %.2f\n", mesh.triangle_count(),
              bvhopt::sah_cost(bvh, config.cost), bvhopt::optimal_collapse_cost(bvh, config.cost));
  return 0;
}
