// bvhopt.rays: the library's deterministic ray sets as n x 8 float32 arrays
// (origin xyz, tmin, direction xyz, tmax: the layout of bvhopt::Ray and of ray files).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <array>
#include <optional>
#include <string>

#include "bindings.h"
#include "bvhopt/error.h"
#include "bvhopt/ray_sets.h"
#include "numpy_arrays.h"
#include "trace_setup.h"

namespace bvhopt::python {
namespace {

std::string known_kinds() {
  std::string s;
  for (RayKind k : all_ray_kinds()) s += (s.empty() ? "" : ", ") + std::string(ray_kind_name(k));
  return s;
}

py::array_t<float> rays(const Scene& scene, const std::string& kind, uint64_t count, uint64_t seed,
                        const Tree* bvh, uint32_t width, uint32_t height, int up_axis,
                        const std::optional<std::array<float, 3>>& light) {
  const auto k = parse_ray_kind(kind);
  if (!k) throw Error("rays: unknown kind '" + kind + "' (known: " + known_kinds() + ")");
  if (width == 0 || height == 0) throw Error("rays: width and height must be positive");
  if (up_axis < 0 || up_axis > 2) throw Error("rays: up_axis must be 0, 1 or 2 (x, y, z)");
  if (light && *k != RayKind::shadow)
    throw Error("rays: only shadow rays have a light; '" + kind + "' rays do not (kind='shadow')");
  RaySetConfig config;
  config.kind = *k;
  config.count = count;
  config.seed = seed;
  config.width = width;
  config.height = height;
  config.up_axis = up_axis;
  if (light) config.light = Vec3((*light)[0], (*light)[1], (*light)[2]);
  RaySet set;
  {
    py::gil_scoped_release unlocked;
    // The rays that start at hits need a tracer; any tree finds the same hits, the given
    // one (as the command line uses the traced tree) or a quick binned one.
    std::unique_ptr<Tracer> tracer = bvh ? make_tracer(*bvh, scene.mesh, "rays") : quick_tracer(scene.mesh);
    set = make_ray_set(scene.mesh, *tracer, config);
  }
  const auto n = static_cast<py::ssize_t>(set.rays.size());
  return take_array<Ray, float>(std::move(set.rays), {n, 8});
}

}  // namespace

void register_rays(py::module_& m) {
  m.def("rays", &rays, py::arg("scene"), py::arg("kind") = "primary", py::arg("count") = 0, py::arg("seed") = 1,
        py::arg("bvh") = nullptr, py::arg("width") = 1024, py::arg("height") = 768, py::arg("up_axis") = 1,
        py::arg("light") = py::none(),
        "A ray set as an n x 8 float32 array (origin, tmin, direction, tmax): kind 'primary' | 'random' | 'ao' | "
        "'path' | 'shadow' (shadow rays are any-hit queries); count 0: the default size. The same scene, kind, "
        "count and seed give the same rays as `bvhopt trace`. `light`: shadow rays' point light (x, y, z), as the command "
        "line's --light (None: above the centre of the scene's box by 0.4 of its height).");
  m.def("ray_kinds", [] {
    py::list names;
    for (RayKind k : all_ray_kinds()) names.append(std::string(ray_kind_name(k)));
    return names;
  });
}

}  // namespace bvhopt::python
