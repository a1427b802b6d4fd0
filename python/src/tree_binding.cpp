// bvhopt.Bvh: costs, statistics, validation, the nodes as numpy, compaction, saving.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <string>

#include "bindings.h"
#include "bvhopt/collapse_leaves.h"
#include "bvhopt/triangle_cost.h"
#include "bvhopt/cost.h"
#include "bvhopt/error.h"
#include "bvhopt/stats.h"
#include "bvhopt/validate.h"
#include "numpy_arrays.h"

namespace bvhopt::python {

// One node as users read it: children for inner nodes, a range of Bvh.references for leaves,
// kInvalidNode (0xffffffff) where a field does not apply.
struct NodeRecord {
  float min[3];
  float max[3];
  float area;
  uint32_t parent;
  uint32_t left;
  uint32_t right;
  uint32_t first;
  uint32_t count;  // 0 for inner nodes
};

namespace {

py::array_t<NodeRecord> node_records(const Bvh& bvh) {
  py::array_t<NodeRecord> out(static_cast<py::ssize_t>(bvh.nodes.size()));
  NodeRecord* r = out.mutable_data();
  for (const BvhNode& n : bvh.nodes) {
    NodeRecord rec{};
    for (int a = 0; a < 3; ++a) {
      rec.min[a] = n.box.min[a];
      rec.max[a] = n.box.max[a];
    }
    rec.area = static_cast<float>(n.area());
    rec.parent = n.parent;
    rec.left = n.is_leaf() ? kInvalidNode : n.left();
    rec.right = n.is_leaf() ? kInvalidNode : n.right();
    rec.first = n.is_leaf() ? n.first_ref() : kInvalidNode;
    rec.count = n.is_leaf() ? n.ref_count() : 0;
    *r++ = rec;
  }
  return out;
}

// Per leaf slot, the triangle (index into the scene's triangles) it holds.
py::array_t<uint32_t> leaf_triangles(const Tree& t) {
  std::vector<uint32_t> ids(t.bvh.ref_indices.size());
  for (size_t i = 0; i < ids.size(); ++i) ids[i] = t.refs.triangle_ids[t.bvh.ref_indices[i]];
  return take_array(std::move(ids));
}

py::dict stats_of(const Tree& t) {
  TreeStats st = compute_stats(t.bvh, t.refs, t.info.cost);  // each triangle once per leaf
  py::dict d;
  d["cost"] = st.cost;
  d["ocost"] = st.ocost;
  d["nodes"] = st.nodes;
  d["inner_nodes"] = st.inner_nodes;
  d["leaves"] = st.leaves;
  d["references"] = st.references;
  d["max_depth"] = st.max_depth;
  d["mean_leaf_depth"] = st.mean_leaf_depth;
  d["min_refs_per_leaf"] = st.min_refs_per_leaf;
  d["max_refs_per_leaf"] = st.max_refs_per_leaf;
  d["mean_refs_per_leaf"] = st.mean_refs_per_leaf;
  d["root_area"] = st.root_area;
  d["inner_area_sum"] = st.inner_area_sum;
  d["leaf_area_sum"] = st.leaf_area_sum;
  d["inner_area_by_depth"] = take_array(std::move(st.inner_area_by_depth));
  d["leaf_area_by_depth"] = take_array(std::move(st.leaf_area_by_depth));
  return d;
}

void check(const Tree& t) {
  ValidationOptions options;
  // Over subdivided references a leaf keeps one reference per triangle.
  options.allow_dropped_duplicates = t.refs.size() > t.info.scene_triangles;
  const ValidationReport report = validate(t.bvh, t.refs, options);
  if (!report.ok()) throw Error("invalid tree: " + report.summary());
}

py::dict collapse(Tree& t, uint32_t max_leaf_size) {
  CollapseConfig config;
  config.cost = t.info.cost;
  config.max_leaf_size = max_leaf_size;
  CollapseResult r;
  {
    py::gil_scoped_release unlocked;
    r = collapse_leaves(t.bvh, t.refs, config);  // keeps each triangle once per leaf
  }
  t.info.method = (t.info.method.empty() ? std::string("unknown") : t.info.method) + "+compact";
  py::dict d;
  d["cost_before"] = r.cost_before;
  d["cost_after"] = r.cost_after;
  d["leaves_before"] = r.leaves_before;
  d["leaves_after"] = r.leaves_after;
  d["nodes_before"] = r.nodes_before;
  d["nodes_after"] = r.nodes_after;
  return d;
}

}  // namespace

void register_tree(py::module_& m) {
  PYBIND11_NUMPY_DTYPE(NodeRecord, min, max, area, parent, left, right, first, count);
  py::class_<Tree> tree(m, "Bvh", "A binary BVH over a scene's triangles (from bvhopt.build or bvhopt.load)");
  tree.def_property_readonly("cost", [](const Tree& t) { return sah_cost(t.bvh, t.refs, t.info.cost); },
                             "SAH cost, normalized by the root's area (each triangle once per leaf)")
      .def_property_readonly("ocost", [](const Tree& t) { return optimal_collapse_cost(t.bvh, t.refs, t.info.cost); },
                             "SAH cost after the best collapse of subtrees into leaves")
      .def_property_readonly(
          "spatial_split",
          [](const Tree& t) -> py::object {
            if (!t.spatial_split) return py::none();
            const SpatialSplitStats& s = *t.spatial_split;
            py::dict d;
            d["budget_references"] = s.budget;
            d["spatial_splits"] = s.spatial_splits;
            d["object_splits"] = s.object_splits;
            d["split_references"] = s.split_references;
            d["unsplit_references"] = s.unsplit_references;
            return d;
          },
          "What the sbvh build did (as `bvhopt build --json`'s spatial_split): the reference budget, spatial "
          "and object splits, references cut and sent whole; None for other builders and loaded files")
      .def_property_readonly("method", [](const Tree& t) { return t.info.method; })
      .def_property_readonly("scene_name", [](const Tree& t) { return t.info.scene_name; })
      .def_property_readonly("scene_triangles", [](const Tree& t) { return t.info.scene_triangles; })
      .def_property_readonly("c_t", [](const Tree& t) { return t.info.cost.traversal; })
      .def_property_readonly("c_i", [](const Tree& t) { return t.info.cost.intersection; })
      .def_property_readonly("root", [](const Tree& t) { return t.bvh.root; })
      .def_property_readonly("nodes", [](const Tree& t) { return node_records(t.bvh); },
                             "Structured array, one row per node: min, max (3 float32 each), area, parent, "
                             "left, right (inner nodes), first, count (leaves: a range of references); "
                             "0xffffffff where a field does not apply")
      .def_property_readonly("references", &leaf_triangles,
                             "Per leaf slot the triangle it holds: a leaf's triangles are "
                             "references[first:first + count]")
      .def("stats", &stats_of, "Counts, depths, costs and the per-depth area sums (arrays)")
      .def("validate", &check, "Raises bvhopt.Error naming every broken invariant")
      .def("collapse_leaves", &collapse, py::arg("max_leaf_size") = 0,
           "Collapses every subtree into a leaf where that costs no more (0: no leaf size limit)")
      .def(
          "save",
          [](const Tree& t, const py::object& path) {
            const std::string file = path_text(path);
            py::gil_scoped_release unlocked;
            write_bvh_file(file, t.bvh, t.refs, t.info);
          },
          py::arg("path"), "Writes the tree as a BVH file (docs/file-format.md)")
      .def("copy", [](const Tree& t) { return Tree(t); })
      .def("__repr__", [](const Tree& t) {
        return "<bvhopt.Bvh " + t.info.method + " over '" + t.info.scene_name + "': " +
               std::to_string(t.bvh.nodes.size()) + " nodes, cost " + std::to_string(sah_cost(t.bvh, t.info.cost)) + ">";
      });
  register_optimize(tree);
  register_trace(tree);
}

}  // namespace bvhopt::python
