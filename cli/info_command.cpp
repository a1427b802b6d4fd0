// bvhopt info SCENE: what a scene holds, and how long it took to load.
#include <iomanip>
#include <iostream>

#include "bvhopt/mesh.h"
#include "bvhopt/edge_volume_subdivision.h"
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
    std::vector<int> evh_t;
    bool json = false;
  };
  auto opts = std::make_shared<Options>();
  opts->scene.add_to(cmd);
  cmd->add_option("--evh-t", opts->evh_t,
                  "Also count the references edge volume subdivision would make with this t (repeatable)")
      ->check(CLI::Range(0, 62));
  cmd->add_flag("--json", opts->json, "Print JSON instead of text");
  cmd->callback([opts] {
    ProgressLine progress;
    progress.update("loading " + opts->scene.spec + " ...", true);
    Stopwatch watch;
    Mesh mesh = opts->scene.load();
    const double load_seconds = watch.seconds();
    progress.finish();
    const MeshInfo info = describe(mesh);
    std::vector<EdgeVolumeStats> evh;
    for (int t : opts->evh_t) {
      EdgeVolumeConfig config;
      config.t = t;
      config.max_reference_ratio = 0.0;  // the count as the paper defines it, no budget
      evh.push_back(count_edge_volume(mesh, config));
    }
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
      for (const EdgeVolumeStats& st : evh)
        j["evh"].push_back({{"t", st.effective_t},
                            {"references", st.references},
                            {"ratio", st.ratio},
                            {"subdivided_triangles", st.subdivided_triangles}});
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
    for (const EdgeVolumeStats& st : evh)
      std::cout << "evh t=" << std::setw(2) << std::left << st.effective_t << std::right << "           " << st.references
                << " references (x" << format_double(st.ratio, 4) << "), " << st.subdivided_triangles
                << " triangles subdivided\n";
  });
}

}  // namespace bvhopt::cli
