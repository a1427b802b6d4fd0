// What `bvhopt trace` and `bvhopt render` share: a BVH file checked against its scene and
// made ready to trace.
#pragma once

#include <CLI/CLI.hpp>

#include <chrono>
#include <memory>
#include <optional>
#include <sstream>
#include <string>

#include "bvhopt/bvh_file.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/mesh.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/any_tracer.h"
#include "bvhopt/tracer.h"
#include "bvhopt/wide_tracer.h"
#include "cli_common.h"

namespace bvhopt::cli {

// --layout: the layout the tree is traced in. The file stores the binary tree; a wide
// layout is collapsed and laid out from it on load.
struct LayoutOption {
  std::string name = std::string(trace_layout_name(kDefaultTraceLayout));

  void add_to(CLI::App* cmd) {
    cmd->add_option("--layout", name, "Trace layout: bvh2 (binary nodes) | bvh4 | bvh8 (wide SIMD nodes, rebuilt on load)")
        ->check(CLI::IsMember({"bvh2", "bvh4", "bvh8"}))
        ->capture_default_str();
  }
  TraceLayout layout() const { return *parse_trace_layout(name); }
};

// --wide-block: the wide collapse's cost of a leaf block (c_blk, with c_node = 1), for a
// layout made under another cost model than the default, calibrated on one CPU
// (docs/wide-bvh.md): 0.5, say, for the layout of before December 2026.
struct WideCostOption {
  double block = WideCostModel{}.block;

  void add_to(CLI::App* cmd) {
    cmd->add_option("--wide-block", block,
                    "bvh4 / bvh8: the collapse's cost of a 4-triangle leaf block per wide node visited (c_blk; "
                    "docs/wide-bvh.md)")
        ->check(finite_number())
        ->check(positive_number())
        ->capture_default_str();
  }
  WideCostModel model() const { return {WideCostModel{}.node, block}; }
};

struct LoadedTree {
  BvhFileInfo info;
  double sah = 0.0;
  // The binary tracer: always there, since ray sets and the default camera are made with it.
  std::unique_ptr<Tracer> tracer;
  std::unique_ptr<WideTracer> wide;  // for --layout bvh4 / bvh8
  double layout_seconds = 0.0;       // making the wide layout (collapse + layout)

  // What traces the rays in the chosen layout.
  AnyTracer traced(ChildOrder order) const { return wide ? AnyTracer(*wide) : AnyTracer(*tracer, order); }
};

// Reads the BVH file and refuses a scene other than the one the tree was built over
// (check_tree_matches_scene: triangle count, geometry fingerprint).
inline BvhFile read_tree_for_scene(const std::string& file, const Mesh& mesh) {
  BvhFile f = read_bvh_file(file);
  check_tree_matches_scene(file, f.info, mesh);
  return f;
}

inline LoadedTree load_tree_for_scene(const std::string& file, const Mesh& mesh,
                                      TraceLayout layout = TraceLayout::bvh2, const WideCostModel& cost = {},
                                      AnyHitOrder any_hit_order = AnyHitOrder::adaptive,
                                      ClosestHitOrder closest_hit_order = ClosestHitOrder::adaptive) {
  BvhFile f = read_tree_for_scene(file, mesh);
  LoadedTree t;
  t.info = f.info;
  const FlatBvh flat = finalize(f.bvh, f.refs);
  t.tracer = std::make_unique<Tracer>(flat, mesh);
  if (layout != TraceLayout::bvh2) {
    const auto start = std::chrono::steady_clock::now();
    t.wide = make_wide_tracer(flat, mesh, layout, cost, any_hit_order, closest_hit_order);
    t.layout_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return t;
}

// A scene and the BVH file built over it, loaded behind a progress line.
struct SceneAndTree {
  Mesh mesh;
  LoadedTree tree;
};
inline SceneAndTree load_scene_and_tree(const SceneOption& scene, const std::string& bvh_file,
                                        ProgressLine& progress, TraceLayout layout = TraceLayout::bvh2,
                                        const WideCostModel& cost = {},
                                        AnyHitOrder any_hit_order = AnyHitOrder::adaptive,
                                        ClosestHitOrder closest_hit_order = ClosestHitOrder::adaptive) {
  progress.update("loading " + scene.spec + " and " + bvh_file, true);
  SceneAndTree out;
  out.mesh = scene.load();
  out.tree = load_tree_for_scene(bvh_file, out.mesh, layout, cost, any_hit_order, closest_hit_order);
  return out;
}

// The value of --order.
inline ChildOrder parse_child_order(const std::string& order) {
  return order == "distance" ? ChildOrder::distance : ChildOrder::split_axis;
}

// --camera-position, --camera-target, --up-axis, --fov: the default camera (see
// default_camera) unless a position is given.
struct CameraOptions {
  std::string position, target;
  std::string up = "y";
  float fov = 60.0f;
  bool fov_given = false;

  void add_to(CLI::App* cmd) {
    cmd->add_option("--camera-position", position, "Camera position (default: the scene file's camera, else placed from where the geometry is)")->type_name("X,Y,Z");
    cmd->add_option("--camera-target", target, "Point the camera looks at (needs --camera-position)")->type_name("X,Y,Z");
    cmd->add_option("--up-axis", up, "The scene's up axis")->check(CLI::IsMember({"x", "y", "z"}))->capture_default_str();
    cmd->add_option("--fov", fov, "Vertical field of view, degrees (default: the scene file's camera's, else 60)")
        ->check(CLI::Range(1.0f, 179.0f))
        ->capture_default_str()
        ->each([this](const std::string&) { fov_given = true; });
  }
  int up_axis() const { return up == "x" ? 0 : (up == "z" ? 2 : 1); }

  static Vec3 parse(const std::string& text, const std::string& option) {
    std::stringstream ss(text);
    float v[3];
    char comma1 = 0, comma2 = 0;
    if (!(ss >> v[0] >> comma1 >> v[1] >> comma2 >> v[2]) || comma1 != ',' || comma2 != ',' || !ss.eof())
      throw Error(option + ": '" + text + "' is not X,Y,Z");
    return {v[0], v[1], v[2]};
  }

  // The camera to use, or nullopt for the default one.
  std::optional<Camera> camera(uint32_t width, uint32_t height) const {
    if (position.empty()) {
      if (!target.empty()) throw Error("--camera-target needs --camera-position");
      return std::nullopt;
    }
    if (target.empty()) throw Error("--camera-position needs --camera-target");
    Camera c;
    c.position = parse(position, "--camera-position");
    c.target = parse(target, "--camera-target");
    c.up = Vec3(0.0f);
    c.up[up_axis()] = 1.0f;
    c.fov_degrees = fov;
    c.width = width;
    c.height = height;
    return c;
  }

  Camera resolve(const Mesh& mesh, const Tracer& tracer, uint32_t width, uint32_t height) const {
    if (auto c = camera(width, height)) return *c;
    Camera c = default_camera(mesh, tracer, width, height, up_axis());
    if (fov_given) c.fov_degrees = fov;  // keep the default position; only widen or narrow the view
    return c;
  }
};

}  // namespace bvhopt::cli
