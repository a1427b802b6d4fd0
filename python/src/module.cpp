// The module `bvhopt._bvhopt`, re-exported by the package `bvhopt`.
#include <pybind11/pybind11.h>

#include "bindings.h"
#include "bvhopt/error.h"

namespace bvhopt::python {

std::unique_ptr<tbb::global_control> limit_threads(const std::optional<int>& threads, const std::string& where) {
  if (!threads) return nullptr;
  if (*threads < 1) throw Error(where + ": threads must be at least 1 (or None for all cores), got " + std::to_string(*threads));
  return std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                               static_cast<size_t>(*threads));
}

std::string path_text(const py::handle& path) {
  return py::str(py::module_::import("os").attr("fspath")(path)).cast<std::string>();
}

}  // namespace bvhopt::python

PYBIND11_MODULE(_bvhopt, m) {
  namespace bp = bvhopt::python;
  m.doc() = "bvhopt: building and optimizing bounding volume hierarchies for ray tracing";
  // The library's one exception: its message names the file or input, the place and the problem.
  pybind11::register_exception<bvhopt::Error>(m, "Error", PyExc_RuntimeError);
  bp::register_scene(m);
  bp::register_tree(m);
  bp::register_build(m);
  bp::register_rays(m);
}
