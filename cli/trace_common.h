// What `bvhopt trace` and `bvhopt render` share: a BVH file checked against its scene and
// made ready to trace.
#pragma once

#include <CLI/CLI.hpp>

#include <memory>
#include <optional>
#include <sstream>
#include <string>

#include "bvhopt/bvh_file.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/mesh.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/tracer.h"
#include "cli_common.h"

namespace bvhopt::cli {

struct LoadedTree {
  BvhFileInfo info;
  double sah = 0.0;
  std::unique_ptr<Tracer> tracer;
};

// Reads the BVH file and refuses a scene whose triangle count differs from the one the
// tree was built over (the ids would point at the wrong triangles, or past the end).
inline LoadedTree load_tree_for_scene(const std::string& file, const Mesh& mesh) {
  BvhFile f = read_bvh_file(file);
  if (f.info.scene_triangles != mesh.triangle_count())
    throw Error(file + ": built over scene '" + f.info.scene_name + "' with " +
                std::to_string(f.info.scene_triangles) + " triangles, but scene '" + mesh.name + "' has " +
                std::to_string(mesh.triangle_count()) + " (pass the scene the tree was built from)");
  LoadedTree t;
  t.info = f.info;
  t.tracer = std::make_unique<Tracer>(finalize(f.bvh, f.refs), mesh);
  return t;
}

// A scene and the BVH file built over it, loaded behind a progress line.
struct SceneAndTree {
  Mesh mesh;
  LoadedTree tree;
};
inline SceneAndTree load_scene_and_tree(const SceneOption& scene, const std::string& bvh_file,
                                        ProgressLine& progress) {
  progress.update("loading " + scene.spec + " and " + bvh_file, true);
  SceneAndTree out;
  out.mesh = scene.load();
  out.tree = load_tree_for_scene(bvh_file, out.mesh);
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

  void add_to(CLI::App* cmd) {
    cmd->add_option("--camera-position", position, "Camera position (default: from the scene box)")->type_name("X,Y,Z");
    cmd->add_option("--camera-target", target, "Point the camera looks at (needs --camera-position)")->type_name("X,Y,Z");
    cmd->add_option("--up-axis", up, "The scene's up axis")->check(CLI::IsMember({"x", "y", "z"}))->capture_default_str();
    cmd->add_option("--fov", fov, "Vertical field of view, degrees")->check(CLI::Range(1.0f, 179.0f))->capture_default_str();
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
    if (fov != c.fov_degrees) {
      c.fov_degrees = fov;  // keep the default position; only widen or narrow the view
    }
    return c;
  }
};

}  // namespace bvhopt::cli
