// A tree made ready to trace against a scene, for Bvh.trace and bvhopt.rays.
#pragma once

#include <memory>
#include <string>

#include "bindings.h"
#include "bvhopt/tracer.h"

namespace bvhopt::python {

// Refuses a scene whose triangle count differs from the tree's (its ids would point at the
// wrong triangles), as the command line does.
std::unique_ptr<Tracer> make_tracer(const Tree& tree, const Mesh& mesh, const std::string& where);

// A tracer over a binned SAH tree of the mesh: for finding hits when no tree is given.
std::unique_ptr<Tracer> quick_tracer(const Mesh& mesh);

}  // namespace bvhopt::python
