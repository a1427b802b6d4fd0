// bvhopt.Scene and bvhopt.load_scene.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <cstring>

#include "bindings.h"
#include "bvhopt/error.h"
#include "bvhopt/scene_file.h"
#include "numpy_arrays.h"

namespace bvhopt::python {
namespace {

using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;
using IndexArray = py::array_t<int64_t, py::array::c_style | py::array::forcecast>;

// A scene from user arrays: copied, since the library owns its mesh as vectors. Indices go
// through int64 so that a negative one is reported, not wrapped round.
Scene scene_from_arrays(const FloatArray& vertices, const IndexArray& indices, const std::string& name) {
  require_columns(vertices, 3, name + ": vertices");
  require_columns(indices, 3, name + ": indices");
  Scene s;
  s.mesh.name = name;
  s.mesh.positions.resize(static_cast<size_t>(vertices.size()));
  if (!s.mesh.positions.empty()) std::memcpy(s.mesh.positions.data(), vertices.data(), s.mesh.positions.size() * sizeof(float));
  const int64_t* idx = indices.data();
  s.mesh.indices.resize(static_cast<size_t>(indices.size()));
  for (size_t i = 0; i < s.mesh.indices.size(); ++i) {
    if (idx[i] < 0 || idx[i] > int64_t{UINT32_MAX})
      throw Error(name + ": triangle " + std::to_string(i / 3) + ", vertex index " + std::to_string(idx[i]) +
                  " is not a 32-bit unsigned index");
    s.mesh.indices[i] = static_cast<uint32_t>(idx[i]);
  }
  check_mesh(s.mesh);
  return s;
}

Scene load(const py::object& spec) {
  const std::string text = path_text(spec);
  Scene s;
  {
    py::gil_scoped_release unlocked;
    s.mesh = load_scene(text);
    check_mesh(s.mesh);
  }
  return s;
}

}  // namespace

void register_scene(py::module_& m) {
  py::class_<Scene>(m, "Scene", "A triangle mesh: vertices (n x 3 float32) and indices (m x 3 uint32)")
      .def(py::init(&scene_from_arrays), py::arg("vertices"), py::arg("indices"), py::arg("name") = "arrays",
           "A scene from arrays (copied); raises bvhopt.Error for an unusable mesh")
      .def_property_readonly(
          "vertices",
          [](py::object self) {
            const Mesh& mesh = self.cast<const Scene&>().mesh;
            return read_only_view(mesh.positions.data(), {static_cast<py::ssize_t>(mesh.vertex_count()), 3}, self);
          },
          "Vertex positions, n x 3 float32 (a read-only view of the scene)")
      .def_property_readonly(
          "indices",
          [](py::object self) {
            const Mesh& mesh = self.cast<const Scene&>().mesh;
            return read_only_view(mesh.indices.data(), {static_cast<py::ssize_t>(mesh.triangle_count()), 3}, self);
          },
          "Three vertex indices per triangle, m x 3 uint32 (a read-only view of the scene)")
      .def_property_readonly("name", [](const Scene& s) { return s.mesh.name; })
      .def_property_readonly("triangle_count", [](const Scene& s) { return s.mesh.triangle_count(); })
      .def_property_readonly("vertex_count", [](const Scene& s) { return s.mesh.vertex_count(); })
      .def_property_readonly("bounds",
                             [](const Scene& s) {
                               const Box b = describe(s.mesh).bounds;
                               return py::make_tuple(py::make_tuple(b.min.x, b.min.y, b.min.z),
                                                     py::make_tuple(b.max.x, b.max.y, b.max.z));
                             })
      .def("__repr__", [](const Scene& s) {
        return "<bvhopt.Scene '" + s.mesh.name + "': " + std::to_string(s.mesh.triangle_count()) + " triangles, " +
               std::to_string(s.mesh.vertex_count()) + " vertices>";
      });
  m.def("load_scene", &load, py::arg("path_or_builtin"),
        "A scene file (any format assimp reads) or the built-in scene ('builtin', "
        "'builtin:atrium?triangles=N&seed=S'); raises bvhopt.Error naming the file and the problem");
}

}  // namespace bvhopt::python
