// Every triangle of the mesh in id order: the oracle the tests and the measurements check
// traversal against.
#pragma once

#include "bvhopt/mesh.h"
#include "bvhopt/ray.h"

namespace bvhopt {

// Ties in t keep the lowest triangle id.
Hit brute_force_closest(const Mesh& mesh, const Ray& ray);
bool brute_force_any(const Mesh& mesh, const Ray& ray);

}  // namespace bvhopt
