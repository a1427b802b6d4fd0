// numpy arrays over the library's vectors: views that keep their owner alive, and arrays
// that take a vector over without copying it.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <string>
#include <utility>
#include <vector>

#include "bvhopt/error.h"

namespace bvhopt::python {

namespace py = pybind11;

// A read-only view of `data` with `shape`, alive as long as `owner` (the Python object that
// holds the vector) is: the scene's arrays cost nothing to read, and cannot be changed
// under a tree built over them.
template <class T>
py::array_t<T> read_only_view(const T* data, std::vector<py::ssize_t> shape, py::handle owner) {
  py::array_t<T> a(std::move(shape), data, owner);
  a.attr("setflags")(py::arg("write") = false);
  return a;
}

// Moves `values` into an array of `shape` (their count must match) that owns them.
template <class T, class Element = T>
py::array_t<Element> take_array(std::vector<T>&& values, std::vector<py::ssize_t> shape) {
  auto* owned = new std::vector<T>(std::move(values));
  py::capsule free_when_done(owned, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array_t<Element>(std::move(shape), reinterpret_cast<const Element*>(owned->data()), free_when_done);
}

template <class T>
py::array_t<T> take_array(std::vector<T>&& values) {
  const auto n = static_cast<py::ssize_t>(values.size());
  return take_array<T, T>(std::move(values), {n});
}

// "(n, 3)"-style text for messages.
inline std::string shape_text(const py::array& a) {
  std::string s = "(";
  for (py::ssize_t d = 0; d < a.ndim(); ++d) s += (d ? ", " : "") + std::to_string(a.shape(d));
  return s + (a.ndim() == 1 ? ",)" : ")");
}

// Throws Error unless `a` is a 2-d array with `columns` columns.
inline void require_columns(const py::array& a, py::ssize_t columns, const std::string& what) {
  if (a.ndim() != 2 || a.shape(1) != columns)
    throw Error(what + ": expected an array of shape (n, " + std::to_string(columns) + "), got shape " +
                shape_text(a));
}

}  // namespace bvhopt::python
