// bvhopt render: heat map of traversal steps per pixel, an eye-light image, and the
// difference heat map of two trees of one scene.
#include <iostream>

#include "bvhopt/atomic_file.h"
#include "bvhopt/images.h"
#include "bvhopt/png_file.h"
#include "bvhopt/ray_measure.h"
#include "bvhopt/ray_sets.h"
#include "cli_common.h"
#include "commands.h"
#include "trace_common.h"

namespace bvhopt::cli {

namespace {

// Everything `bvhopt render` takes; the defaults are the command's.
struct RenderOptions {
  std::string bvh_file;
  SceneOption scene;
  ThreadsOption threads;
  std::string heatmap, shaded, compare, compare_heatmap;
  uint32_t width = 1024, height = 768;
  float max_steps = 100.0f;
  float range = 50.0f;
  std::string order = "axis";
  bool json = false;
  CameraOptions camera;
  LayoutOption layout;
};

// Where the difference heat map goes: --compare-heatmap, or OUT.png with -diff.
std::string difference_path(const RenderOptions& opt) {
  if (!opt.compare_heatmap.empty()) return opt.compare_heatmap;
  const std::filesystem::path p(opt.heatmap);
  return (p.parent_path() / (p.stem().string() + "-diff" + p.extension().string())).string();
}

// Renders the heat map (and the shaded image, and the difference to --compare when given)
// of primary rays from the camera, and prints a summary. Every output is checked before the
// work and the images are written all or none.
void run_render(const RenderOptions& opt) {
  check_output_path(opt.heatmap, "--heatmap");
  if (!opt.shaded.empty()) check_output_path(opt.shaded, "--shaded");
  if (!opt.compare.empty()) check_output_path(difference_path(opt), "--compare-heatmap");
  auto threads = opt.threads.apply();
  ProgressLine progress;
  const SceneAndTree loaded = load_scene_and_tree(opt.scene, opt.bvh_file, progress, opt.layout.layout());
  const Mesh& mesh = loaded.mesh;
  const LoadedTree& tree = loaded.tree;
  progress.finish();
  const ChildOrder order = parse_child_order(opt.order);
  const Camera cam = opt.camera.resolve(mesh, *tree.tracer, opt.width, opt.height);
  const std::vector<Ray> rays = camera_rays(cam);

  std::vector<Hit> hits;
  std::vector<TraceCounters> counters;
  trace_rays(tree.traced(order), rays, RayQuery::closest, hits, &counters);
  OutputGroup outputs;
  outputs.add(opt.heatmap, [&](const std::filesystem::path& tmp) {
    write_png(tmp, heatmap_image(counters, cam.width, cam.height, opt.max_steps));
  });
  if (!opt.shaded.empty())
    outputs.add(opt.shaded, [&](const std::filesystem::path& tmp) {
      write_png(tmp, shaded_image(mesh, rays, hits, cam.width, cam.height));
    });

  double mean_a = 0, mean_b = 0;
  for (const TraceCounters& c : counters) mean_a += c.steps;
  mean_a /= double(counters.size());
  std::string diff_path;
  if (!opt.compare.empty()) {
    const LoadedTree other = load_tree_for_scene(opt.compare, mesh, opt.layout.layout());
    std::vector<Hit> hits_b;
    std::vector<TraceCounters> counters_b;
    trace_rays(other.traced(order), rays, RayQuery::closest, hits_b, &counters_b);
    for (const TraceCounters& c : counters_b) mean_b += c.steps;
    mean_b /= double(counters_b.size());
    diff_path = difference_path(opt);
    outputs.add(diff_path, [&](const std::filesystem::path& tmp) {
      write_png(tmp, difference_image(counters, counters_b, cam.width, cam.height, opt.range));
    });
  }
  outputs.commit();
  if (opt.json) {
    nlohmann::json j = {{"bvh", opt.bvh_file}, {"scene", mesh.name}, {"width", cam.width},
                        {"height", cam.height}, {"heatmap", opt.heatmap}, {"mean_steps", mean_a},
                        {"layout", opt.layout.name}};
    if (!opt.shaded.empty()) j["shaded"] = opt.shaded;
    if (!opt.compare.empty()) {
      j["compare"] = opt.compare;
      j["compare_mean_steps"] = mean_b;
      j["difference_heatmap"] = diff_path;
    }
    print_json(j);
    return;
  }
  std::cout << "image      " << cam.width << "x" << cam.height << ", camera at (" << cam.position.x << ", "
            << cam.position.y << ", " << cam.position.z << ")\n"
            << "heat map   " << opt.heatmap << " (mean " << format_double(mean_a, 1) << " steps/pixel, scale 0.."
            << opt.max_steps << ")\n";
  if (!opt.shaded.empty()) std::cout << "shaded     " << opt.shaded << "\n";
  if (!opt.compare.empty())
    std::cout << "compare    " << opt.compare << ": mean " << format_double(mean_b, 1) << " steps/pixel; difference "
              << diff_path << " (red: more steps than " << opt.bvh_file << ")\n";
}

}  // namespace

void register_render_command(CLI::App& app) {
  auto opt = std::make_shared<RenderOptions>();
  CLI::App* cmd = app.add_subcommand("render", "Heat map of traversal steps per pixel (primary rays), shaded image, "
                                               "and the difference of two trees");
  cmd->add_option("bvh", opt->bvh_file, "BVH file")->required()->type_name("FILE.bvh");
  opt->scene.add_to(cmd, "--scene", true);
  cmd->add_option("--heatmap", opt->heatmap, "PNG: steps per pixel, fixed scale 0 (blue) to --max-steps (red)")
      ->required()
      ->type_name("OUT.png");
  cmd->add_option("--shaded", opt->shaded, "PNG: eye-light shading")->type_name("OUT.png");
  cmd->add_option("--compare", opt->compare, "A second BVH file of the same scene")->type_name("OTHER.bvh");
  cmd->add_option("--compare-heatmap", opt->compare_heatmap,
                  "PNG: steps of the --compare tree minus this tree's (default: OUT.png with -diff)")
      ->type_name("OUT.png");
  cmd->add_option("--width", opt->width, "Image width")->check(CLI::Range(1u, 16384u))->capture_default_str();
  cmd->add_option("--height", opt->height, "Image height")->check(CLI::Range(1u, 16384u))->capture_default_str();
  cmd->add_option("--max-steps", opt->max_steps, "Steps shown as full red (positive)")
      ->check(finite_number())
      ->check(positive_number())
      ->capture_default_str();
  cmd->add_option("--range", opt->range, "Step difference shown as full red/blue (positive)")
      ->check(finite_number())
      ->check(positive_number())
      ->capture_default_str();
  cmd->add_option("--order", opt->order, "axis | distance")->check(CLI::IsMember({"axis", "distance"}))->capture_default_str();
  opt->camera.add_to(cmd);
  opt->layout.add_to(cmd);
  opt->threads.add_to(cmd);
  cmd->add_flag("--json", opt->json, "Print a summary as JSON");
  cmd->callback([opt] { run_render(*opt); });
}

}  // namespace bvhopt::cli
