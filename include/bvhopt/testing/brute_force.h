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

// The independent oracle: every triangle through a test of its own, in double precision
// (Moller-Trumbore on the float inputs widened to double; no code shared with the tracers'
// float tests), so a fault in those tests, such as a float overflow at large coordinates,
// cannot hide behind an oracle that shares it. It can differ from the tracers only for rays
// within rounding of a triangle's edge or plane; tests compare it with a small tolerance.
// Ties in t keep the lowest triangle id; t is rounded to float in the result.
Hit brute_force_closest_double(const Mesh& mesh, const Ray& ray);

}  // namespace bvhopt
