// The Python module's objects and the functions that register them, one file per object.
#pragma once

#include <pybind11/pybind11.h>

#include <memory>
#include <optional>
#include <string>

#include <tbb/global_control.h>

#include "bvhopt/bvh.h"
#include "bvhopt/bvh_file.h"
#include "bvhopt/mesh.h"
#include "bvhopt/references.h"
#include "bvhopt/spatial_split_builder.h"

namespace bvhopt::python {

namespace py = pybind11;

// bvhopt.Scene: a mesh; its arrays are views of it.
struct Scene {
  Mesh mesh;
};

// bvhopt.Bvh: a tree with the references it was built over and what a BVH file says of it.
struct Tree {
  Bvh bvh;
  PrimitiveRefs refs;
  BvhFileInfo info;
  std::optional<SpatialSplitStats> spatial_split;  // what an sbvh build did (not kept in files)
};

// Limits oneTBB to `threads` for the scope (none: all cores); throws Error for threads < 1.
std::unique_ptr<tbb::global_control> limit_threads(const std::optional<int>& threads, const std::string& where);

// A path (str or os.PathLike) as text.
std::string path_text(const py::handle& path);

void register_scene(py::module_& m);
void register_build(py::module_& m);
void register_tree(py::module_& m);
void register_optimize(py::class_<Tree>& tree);
void register_rays(py::module_& m);
void register_trace(py::class_<Tree>& tree);

}  // namespace bvhopt::python
