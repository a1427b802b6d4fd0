// bvhopt info SCENE: what a scene holds, and how long it took to load.
#include <iostream>

#include "bvhopt/mesh.h"
#include "cli_common.h"
#include "commands.h"

namespace bvhopt::cli {

namespace {

std::string format_vec(const Vec3& v) {
  return "(" + format_double(v.x, 4) + ", " + format_double(v.y, 4) + ", " + format_double(v.z, 4) + ")";
}

}  // namespace

void register_info_command(CLI::App& app) {
  auto* cmd = app.add_subcommand("info", "Load a scene and print its triangles, vertices, bounds and degenerate triangles");
  struct Options {
    SceneOption scene;
    bool json = false;
  };
  auto opts = std::make_shared<Options>();
  opts->scene.add_to(cmd);
  cmd->add_flag("--json", opts->json, "Print JSON instead of text");
  cmd->callback([opts] {
    ProgressLine progress;
    progress.update("loading " + opts->scene.spec + " ...", true);
    Stopwatch watch;
    Mesh mesh = opts->scene.load();
    const double load_seconds = watch.seconds();
    progress.finish();
    const MeshInfo info = describe(mesh);
    if (opts->json) {
      nlohmann::json j;
      j["scene"] = mesh.name;
      j["triangles"] = info.triangles;
      j["vertices"] = info.vertices;
      j["degenerate_triangles"] = info.degenerate_triangles;
      j["coincident_triangles"] = info.coincident_triangles;
      j["bounds"] = {{"min", {info.bounds.min.x, info.bounds.min.y, info.bounds.min.z}},
                     {"max", {info.bounds.max.x, info.bounds.max.y, info.bounds.max.z}}};
      j["load_seconds"] = load_seconds;
      if (!opts->scene.rotate.empty()) j["rotate"] = opts->scene.rotate;
      print_json(j);
      return;
    }
    std::cout << "scene:                " << mesh.name << "\n"
              << "triangles:            " << info.triangles << "\n"
              << "vertices:             " << info.vertices << "\n"
              << "degenerate triangles: " << info.degenerate_triangles << " (zero area; " << info.coincident_triangles
              << " with coincident corners)\n"
              << "bounds:               " << format_vec(info.bounds.min) << " to " << format_vec(info.bounds.max) << "\n"
              << "extent:               " << format_vec(info.bounds.extent()) << "\n";
    if (!opts->scene.rotate.empty()) std::cout << "rotated:              " << opts->scene.rotate << " degrees\n";
    std::cout << "load time:            " << format_double(load_seconds, 3) << " s\n";
  });
}

}  // namespace bvhopt::cli
