// Every triangle of the mesh in id order: the oracle the tests and the measurements check
// traversal against.
#pragma once

#include "bvhopt/mesh.h"
#include "bvhopt/ray.h"
#include "bvhopt/triangle.h"

namespace bvhopt {

// Ties in t keep the lowest triangle id.
Hit brute_force_closest(const Mesh& mesh, const Ray& ray);
bool brute_force_any(const Mesh& mesh, const Ray& ray);

// The same with the Moller-Trumbore test as the wide leaf blocks run it (edges v1 - v0 and
// v2 - v0 in float, no fused operations, division deferred; wide_kernel.h): the oracle of
// the wide tracer's default triangle test.
Hit brute_force_closest_mt(const Mesh& mesh, const Ray& ray);
// Its test on one triangle: fills t, u, v of `hit` (not the id) for t in [tmin, tmax] and
// t < hit.t.
bool intersect_triangle_mt(const Ray& ray, const Triangle& tri, Hit& hit);

}  // namespace bvhopt
