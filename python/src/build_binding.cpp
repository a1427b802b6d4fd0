// bvhopt.build and bvhopt.load: where a Bvh comes from.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <optional>
#include <string>

#include "bindings.h"
#include "bvhopt/build.h"
#include "bvhopt/edge_volume_subdivision.h"
#include "bvhopt/bvh_file.h"
#include "bvhopt/error.h"
#include "bvhopt/leaf_dedup.h"

namespace bvhopt::python {
namespace {

std::string known_builders() {
  std::string s;
  for (BuilderKind k : all_mesh_builders()) s += (s.empty() ? "" : ", ") + std::string(builder_name(k));
  return s;
}

// evh=None or False: one reference per triangle; True: the paper's t = 14; a number: that t.
std::optional<EdgeVolumeConfig> evh_config(const py::object& evh) {
  if (evh.is_none() || (py::isinstance<py::bool_>(evh) && !evh.cast<bool>())) return std::nullopt;
  EdgeVolumeConfig config;
  if (!py::isinstance<py::bool_>(evh)) {
    if (!py::isinstance<py::int_>(evh)) throw Error("build: evh must be None, a bool or the threshold exponent t (an int)");
    config.t = evh.cast<int>();
    if (config.t < 0 || config.t > 62) throw Error("build: evh threshold exponent t must be in 0..62, got " + std::to_string(config.t));
  }
  return config;
}

Tree build(const Scene& scene, const std::string& builder, uint32_t leaf_size, double c_t, double c_i,
           std::optional<int> threads, const py::object& evh, std::optional<uint32_t> bins, double budget,
           double split_alpha, uint32_t spatial_bins, uint32_t spatial_from, double split_node_alpha,
           uint32_t spatial_max) {
  BuildOptions options;
  const auto kind = parse_builder(builder);
  if (!kind) throw Error("build: unknown builder '" + builder + "' (known: " + known_builders() + ")");
  options.kind = *kind;
  options.leaf.max_leaf_size = leaf_size;
  options.cost = {c_t, c_i};
  if (bins) {  // an explicit count holds at every node, as the command line's --bins
    options.binned.bin_count = *bins;
    options.binned.refs_per_bin = 0;
  }
  options.sbvh.budget = budget;
  options.sbvh.alpha = split_alpha;
  options.sbvh.spatial_bins = spatial_bins;
  options.sbvh.spatial_from = spatial_from;
  options.sbvh.node_alpha = split_node_alpha;
  options.sbvh.spatial_max = spatial_max;
  validate(options);
  const std::optional<EdgeVolumeConfig> subdivide = evh_config(evh);
  Tree tree;
  {
    py::gil_scoped_release unlocked;
    auto limit = limit_threads(threads, "build");
    BuiltTree built = build_tree(
        scene.mesh, subdivide ? subdivide_edge_volume(scene.mesh, *subdivide).refs : make_references(scene.mesh), options);
    tree.bvh = std::move(built.bvh);
    tree.refs = std::move(built.refs);
    tree.spatial_split = built.spatial_split;
    // Over subdivided references a leaf keeps one reference per triangle (as the command
    // line; the sbvh builder's leaves already do).
    if (subdivide && options.kind != BuilderKind::spatial_split) dedup_leaf_references(tree.bvh, tree.refs);
  }
  tree.info = scene_info(scene.mesh, options.cost, subdivide ? "evh+" + builder : builder);
  return tree;
}

Tree load(const py::object& path) {
  const std::string file = path_text(path);
  py::gil_scoped_release unlocked;
  BvhFile f = read_bvh_file(file);
  return Tree{std::move(f.bvh), std::move(f.refs), std::move(f.info), std::nullopt};
}

}  // namespace

void register_build(py::module_& m) {
  m.def("build", &build, py::arg("scene"), py::arg("builder") = "sweep", py::arg("leaf_size") = 1,
        py::arg("c_t") = 3.0, py::arg("c_i") = 2.0, py::arg("threads") = py::none(), py::arg("evh") = py::none(),
        py::arg("bins") = py::none(), py::arg("budget") = SpatialSplitParams{}.budget,
        py::arg("split_alpha") = SpatialSplitParams{}.alpha, py::arg("spatial_bins") = SpatialSplitParams{}.spatial_bins,
        py::arg("spatial_from") = SpatialSplitParams{}.spatial_from,
        py::arg("split_node_alpha") = SpatialSplitParams{}.node_alpha,
        py::arg("spatial_max") = SpatialSplitParams{}.spatial_max,
        "Builds a BVH top-down: builder 'sweep' | 'binned' | 'spatial-median' | 'object-median' | 'sbvh' "
        "(spatial splits, at most budget x triangles references; split_alpha, split_node_alpha, spatial_bins, "
        "spatial_from and spatial_max as the command line's --split-alpha, --split-node-alpha, --spatial-bins, "
        "--spatial-from and --spatial-max); evh=True (or the exponent t) "
        "subdivides fat triangles first. The tree does not depend on threads.");
  m.def("load", &load, py::arg("path"), "Reads a BVH file written by Bvh.save or the command line");
  m.def("builders", [] {
    py::list names;
    for (BuilderKind k : all_mesh_builders()) names.append(std::string(builder_name(k)));
    return names;
  });
}

}  // namespace bvhopt::python
