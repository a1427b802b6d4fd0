// Bvh.trace: hit distances, triangle ids and steps per ray, and rays per second.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <cstring>
#include <optional>
#include <sstream>
#include <string>
#include <type_traits>

#include "bindings.h"
#include "bvhopt/any_tracer.h"
#include "bvhopt/binned_sah_builder.h"
#include "bvhopt/bvh_file.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/ray_measure.h"
#include "numpy_arrays.h"
#include "trace_setup.h"

namespace bvhopt::python {

std::unique_ptr<Tracer> make_tracer(const Tree& tree, const Mesh& mesh, const std::string& where) {
  check_tree_matches_scene(where, tree.info, mesh);
  return std::make_unique<Tracer>(finalize(tree.bvh, tree.refs), mesh);
}

std::unique_ptr<Tracer> quick_tracer(const Mesh& mesh) {
  PrimitiveRefs refs = make_references(mesh);
  return std::make_unique<Tracer>(finalize(build_binned_sah(refs), refs), mesh);
}

namespace {

std::vector<std::string> known_layouts() {
  return {std::string(trace_layout_name(TraceLayout::bvh2)), std::string(trace_layout_name(TraceLayout::bvh4)),
          std::string(trace_layout_name(TraceLayout::bvh8))};
}

struct TraceResult {
  py::array_t<float> t;              // hit distance, inf for a miss
  py::array_t<uint32_t> triangle_id;  // 0xffffffff for a miss
  py::array_t<uint32_t> steps;        // inner nodes visited + leaves tested
  py::array_t<uint32_t> triangle_tests;
  double rays_per_second = 0.0;
  double seconds = 0.0;
  double hit_rate = 0.0;
  double mean_steps = 0.0;
  int threads = 0;
};

std::vector<Ray> rays_from(const py::array_t<float, py::array::c_style | py::array::forcecast>& array) {
  require_columns(array, 8, "trace: rays");
  std::vector<Ray> rays(static_cast<size_t>(array.shape(0)));
  // Eight floats a ray, in the array's column order (checked above and in ray.h).
  static_assert(std::is_trivially_copyable_v<Ray> && sizeof(Ray) == 8 * sizeof(float));
  if (!rays.empty()) std::memcpy(static_cast<void*>(rays.data()), array.data(), rays.size() * sizeof(Ray));
  return rays;
}

TraceResult trace(const Tree& tree, const Scene& scene, const py::array_t<float, py::array::c_style | py::array::forcecast>& array,
                  const std::string& layout, const std::string& query, const std::string& order,
                  std::optional<int> threads, int repeats, std::optional<double> wide_block, int rays_per_call,
                  const std::string& any_hit_order, const std::string& closest_hit_order) {
  const std::optional<TraceLayout> wide = parse_trace_layout(layout);
  if (!wide) throw Error("trace: unknown layout '" + layout + "' (known: bvh2, bvh4, bvh8)");
  if (query != "closest" && query != "any") throw Error("trace: query must be 'closest' or 'any', got '" + query + "'");
  if (order != "split-axis" && order != "distance") throw Error("trace: order must be 'split-axis' or 'distance', got '" + order + "'");
  const std::optional<AnyHitOrder> any_order = parse_any_hit_order(any_hit_order);
  if (!any_order) throw Error("trace: any_hit_order must be 'auto', 'far' or 'near', got '" + any_hit_order + "'");
  const std::optional<ClosestHitOrder> closest_order = parse_closest_hit_order(closest_hit_order);
  if (!closest_order)
    throw Error("trace: closest_hit_order must be 'auto' or 'near', got '" + closest_hit_order + "'");
  if (repeats < 1) throw Error("trace: repeats must be at least 1, got " + std::to_string(repeats));
  if (threads && *threads < 1) throw Error("trace: threads must be at least 1 (or None for all cores)");
  if (rays_per_call < 0 || size_t(rays_per_call) > kMaxRaysPerCall)
    throw Error("trace: rays_per_call must be 0 (blocks of 256 rays) to " + std::to_string(kMaxRaysPerCall) + ", got " +
                std::to_string(rays_per_call));
  if (wide_block && !(std::isfinite(*wide_block) && *wide_block > 0.0)) {
    std::ostringstream m;
    m << "trace: wide_block must be a finite number above 0 (or None for the default, " << WideCostModel{}.block
      << "), got " << *wide_block;
    throw Error(m.str());
  }
  const std::vector<Ray> rays = rays_from(array);
  const RayQuery q = query == "any" ? RayQuery::any : RayQuery::closest;
  MeasureOptions options;
  options.order = order == "distance" ? ChildOrder::distance : ChildOrder::split_axis;
  options.threads = threads.value_or(0);
  options.repeats = repeats;
  options.rays_per_call = size_t(rays_per_call);
  std::vector<Hit> hits;
  std::vector<TraceCounters> counters;
  RayMeasurement measured;
  {
    py::gil_scoped_release unlocked;
    std::unique_ptr<Tracer> binary = make_tracer(tree, scene.mesh, "trace");
    // bvh4 / bvh8: collapsed and laid out from the binary tree, as the command line's --layout.
    std::unique_ptr<WideTracer> wide_tracer;
    if (*wide != TraceLayout::bvh2) {
      WideCostModel cost;
      if (wide_block) cost.block = *wide_block;
      wide_tracer = make_wide_tracer(finalize(tree.bvh, tree.refs), scene.mesh, *wide, cost, *any_order, *closest_order);
    }
    const AnyTracer tracer = wide_tracer ? AnyTracer(*wide_tracer) : AnyTracer(*binary, options.order);
    trace_rays(tracer, rays, q, hits, &counters);
    measured = measure_rays(tracer, rays, q, options);
  }
  std::vector<float> t(hits.size());
  std::vector<uint32_t> ids(hits.size()), steps(hits.size()), tests(hits.size());
  for (size_t i = 0; i < hits.size(); ++i) {
    t[i] = hits[i].hit() ? hits[i].t : std::numeric_limits<float>::infinity();
    ids[i] = hits[i].triangle_id;
    steps[i] = counters[i].steps;
    tests[i] = counters[i].triangle_tests;
  }
  TraceResult r;
  r.t = take_array(std::move(t));
  r.triangle_id = take_array(std::move(ids));
  r.steps = take_array(std::move(steps));
  r.triangle_tests = take_array(std::move(tests));
  r.rays_per_second = measured.rays_per_second;
  r.seconds = measured.seconds;
  r.hit_rate = measured.hit_rate;
  r.mean_steps = measured.steps.mean;
  r.threads = measured.threads;
  return r;
}

}  // namespace

void register_trace(py::class_<Tree>& tree) {
  py::class_<TraceResult>(tree, "TraceResult", "Per-ray hits and work, and the speed of the timed passes")
      .def_readonly("t", &TraceResult::t, "Hit distance per ray (float32, inf for a miss)")
      .def_readonly("triangle_id", &TraceResult::triangle_id, "Hit triangle per ray (uint32, 0xffffffff for a miss)")
      .def_readonly("steps", &TraceResult::steps, "Traversal steps per ray: inner nodes visited + leaves tested")
      .def_readonly("triangle_tests", &TraceResult::triangle_tests)
      .def_readonly("rays_per_second", &TraceResult::rays_per_second, "Median over the timed passes")
      .def_readonly("seconds", &TraceResult::seconds)
      .def_readonly("hit_rate", &TraceResult::hit_rate)
      .def_readonly("mean_steps", &TraceResult::mean_steps)
      .def_readonly("threads", &TraceResult::threads)
      .def("__repr__", [](const TraceResult& r) {
        return "<TraceResult " + std::to_string(r.t.size()) + " rays, " + std::to_string(r.rays_per_second / 1e6) +
               " Mrays/s, mean steps " + std::to_string(r.mean_steps) + ">";
      });
  tree.def("trace", &trace, py::arg("scene"), py::arg("rays"), py::arg("layout") = "bvh8", py::arg("query") = "closest",
           py::arg("order") = "split-axis", py::arg("threads") = py::none(), py::arg("repeats") = 3,
           py::arg("wide_block") = py::none(), py::arg("rays_per_call") = 0, py::arg("any_hit_order") = "auto",
           py::arg("closest_hit_order") = "auto",
           "Traces an n x 8 float32 ray array (see bvhopt.rays) through the tree laid out as `layout`: 'bvh8' (the default, as the command line's), 'bvh4' (wide SIMD nodes, collapsed from the binary tree) or 'bvh2' (binary nodes). "
           "`wide_block`: the wide collapse's cost of a 4-triangle leaf block (c_blk, as the command line's --wide-block; None: the library's default). "
           "`rays_per_call`: the timed passes trace the rays in calls of this many (1: one ray a call, as a renderer tracing a ray at a time; 0: blocks of 256), as the command line's --rays-per-call. "
           "`any_hit_order`: bvh4 / bvh8 any-hit rays search from the ray's far end ('far'), or its near end ('near'), or from the far end but in slot order while the batch's rays mostly hit nothing ('auto', the default), as the command line's --any-hit-order. "
           "`closest_hit_order`: bvh4 / bvh8 closest-hit rays in batches enter children nearest first ('near'), or in slot order while the batch's rays mostly hit nothing ('auto', the default), as the command line's --closest-hit-order");
  tree.def_static("layouts", [] { return known_layouts(); });
}

}  // namespace bvhopt::python
