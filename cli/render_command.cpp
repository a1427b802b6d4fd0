// bvhopt render: heat map of traversal steps per pixel, an eye-light image, and the
// difference heat map of two trees of one scene.
#include <filesystem>
#include <iostream>
#include <optional>

#include "bvhopt/font.h"
#include "bvhopt/image_legend.h"
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
  std::string heatmap, shaded, compare, compare_heatmap, other_heatmap;
  std::string name, compare_name;
  uint32_t width = 1024, height = 768;
  float max_steps = 100.0f;
  float range = 50.0f;
  std::string scale = "auto";
  bool range_given = false;
  bool no_legend = false;
  std::string order = "axis";
  bool json = false;
  CameraOptions camera;
  LayoutOption layout;
  WideCostOption wide_cost;
};

// One tree's primary-ray picture.
struct TracedView {
  std::vector<Hit> hits;
  std::vector<TraceCounters> counters;
};

TracedView trace_view(const LoadedTree& tree, ChildOrder order, const std::vector<Ray>& rays) {
  TracedView v;
  trace_rays(tree.traced(order), rays, RayQuery::closest, v.hits, &v.counters);
  return v;
}

// OUT.png with `suffix` before the extension.
std::string beside(const std::string& path, const std::string& suffix) {
  const std::filesystem::path p(path);
  return (p.parent_path() / (p.stem().string() + suffix + p.extension().string())).string();
}

// Writes a picture with its legend, or the bare picture with --no-legend.
void write_picture(const std::string& path, const LegendImage& picture, bool legend) {
  if (!legend) {
    Image bare{picture.picture.width, picture.picture.height, {}};
    for (uint32_t y = 0; y < bare.height; ++y)
      bare.rgb.insert(bare.rgb.end(), picture.image.rgb.begin() + 3 * size_t(y) * picture.image.width,
                      picture.image.rgb.begin() + 3 * (size_t(y) * picture.image.width + bare.width));
    write_png(path, bare);
    return;
  }
  write_png(path, picture.image);
}

// Where the difference heat map goes: --compare-heatmap, or OUT.png with -diff.
std::string difference_path(const RenderOptions& opt) {
  return opt.compare_heatmap.empty() ? beside(opt.heatmap, "-diff") : opt.compare_heatmap;
}

// Where the --compare tree's heat map goes: --other-heatmap, or OUT.png with -other.
std::string other_path(const RenderOptions& opt) {
  return opt.other_heatmap.empty() ? beside(opt.heatmap, "-other") : opt.other_heatmap;
}

// Renders the heat map (and the shaded image, and with --compare the other tree's heat map
// on the same scale and the difference) of primary rays from the camera, and prints a
// summary. Every output is checked before the work and the images are written all or none.
void run_render(const RenderOptions& opt) {
  check_output_path(opt.heatmap, "--heatmap");
  if (!opt.shaded.empty()) check_output_path(opt.shaded, "--shaded");
  if (!opt.compare.empty()) {
    check_output_path(difference_path(opt), "--compare-heatmap");
    check_output_path(other_path(opt), "--other-heatmap");
  }
  auto threads = opt.threads.apply();
  ProgressLine progress;
  const SceneAndTree loaded =
      load_scene_and_tree(opt.scene, opt.bvh_file, progress, opt.layout.layout(), opt.wide_cost.model());
  const Mesh& mesh = loaded.mesh;
  const LoadedTree& tree = loaded.tree;
  progress.finish();
  const ChildOrder order = parse_child_order(opt.order);
  const Camera cam = opt.camera.resolve(mesh, *tree.tracer, opt.width, opt.height);
  const std::vector<Ray> rays = camera_rays(cam);

  const TracedView a = trace_view(tree, order, rays);
  std::optional<TracedView> b;
  if (!opt.compare.empty())
    b = trace_view(load_tree_for_scene(opt.compare, mesh, opt.layout.layout(), opt.wide_cost.model()), order, rays);

  // One scale for both heat maps, so that equal colours are equal steps.
  std::vector<const std::vector<TraceCounters>*> maps{&a.counters};
  if (b) maps.push_back(&b->counters);
  const bool fixed = opt.scale == "fixed";
  const float max_steps = fixed ? opt.max_steps : shared_heat_scale(maps);
  std::string font_problem;
  const std::optional<Font> font = opt.no_legend ? std::nullopt : Font::load_default(font_problem);
  if (!opt.no_legend && !font) std::cerr << "warning: " << font_problem << ": pictures without captions\n";
  const Font* text = font ? &*font : nullptr;
  const auto title = [&](const std::string& name, const std::string& file) {
    return (name.empty() ? std::filesystem::path(file).filename().string() : name) + "  \u00b7  " + mesh.name +
           "  \u00b7  " + opt.layout.name + " layout";
  };
  OutputGroup outputs;
  outputs.add(opt.heatmap, [&](const std::filesystem::path& tmp) {
    write_picture(tmp.string(),
                  heatmap_with_legend(a.counters, cam.width, cam.height, max_steps, title(opt.name, opt.bvh_file), text),
                  !opt.no_legend);
  });
  if (!opt.shaded.empty())
    outputs.add(opt.shaded, [&](const std::filesystem::path& tmp) {
      write_png(tmp, shaded_image(mesh, rays, a.hits, cam.width, cam.height));
    });

  size_t hits = 0;
  for (const Hit& h : a.hits) hits += h.hit();
  const double hit_fraction = double(hits) / double(std::max<size_t>(a.hits.size(), 1));
  const double mean_a = mean_steps(a.counters);
  double mean_b = 0.0;
  float range = opt.range;
  std::string diff_path, other_file;
  const auto name_of = [](const std::string& name, const std::string& file) {
    return name.empty() ? std::filesystem::path(file).filename().string() : name;
  };
  if (b) {
    mean_b = mean_steps(b->counters);
    other_file = other_path(opt);
    outputs.add(other_file, [&](const std::filesystem::path& tmp) {
      write_picture(tmp.string(),
                    heatmap_with_legend(b->counters, cam.width, cam.height, max_steps,
                                        title(opt.compare_name, opt.compare), text),
                    !opt.no_legend);
    });
    if (!opt.range_given && !fixed) range = difference_scale(a.counters, b->counters);
    diff_path = difference_path(opt);
    outputs.add(diff_path, [&, range](const std::filesystem::path& tmp) {
      write_picture(tmp.string(),
                    difference_with_legend(a.counters, b->counters, cam.width, cam.height, range,
                                           "steps of " + name_of(opt.compare_name, opt.compare) + " minus " +
                                               name_of(opt.name, opt.bvh_file) + "  \u00b7  " + mesh.name,
                                           text),
                    !opt.no_legend);
    });
  }
  outputs.commit();
  if (opt.json) {
    nlohmann::json j = {{"bvh", opt.bvh_file},   {"scene", mesh.name},         {"width", cam.width},
                        {"height", cam.height},  {"heatmap", opt.heatmap},     {"mean_steps", mean_a},
                        {"layout", opt.layout.name}, {"max_steps", max_steps}, {"scale", opt.scale},
                        {"legend", !opt.no_legend && text != nullptr}, {"hit_fraction", hit_fraction},
                        {"wide_block_cost", opt.wide_cost.block}};
    if (!opt.shaded.empty()) j["shaded"] = opt.shaded;
    if (b) {
      j["compare"] = opt.compare;
      j["compare_mean_steps"] = mean_b;
      j["difference_heatmap"] = diff_path;
      j["difference_range"] = range;
      j["other_heatmap"] = other_file;
    }
    print_json(j);
    return;
  }
  std::cout << "image      " << cam.width << "x" << cam.height << ", camera at (" << cam.position.x << ", "
            << cam.position.y << ", " << cam.position.z << "), " << format_double(100.0 * hit_fraction, 1)
            << "% of the rays hit\n"
            << "heat map   " << opt.heatmap << " (mean " << format_double(mean_a, 1) << " steps/pixel, scale 0.."
            << max_steps << (fixed ? ", fixed" : ", the 99th percentile rounded up") << ")\n";
  if (!opt.shaded.empty()) std::cout << "shaded     " << opt.shaded << "\n";
  if (b)
    std::cout << "compare    " << opt.compare << ": mean " << format_double(mean_b, 1) << " steps/pixel, heat map "
              << other_file << " (same scale); difference " << diff_path << " (red: more steps than " << opt.bvh_file
              << ", full at +-" << range << ")\n";
}

}  // namespace

void register_render_command(CLI::App& app) {
  auto opt = std::make_shared<RenderOptions>();
  CLI::App* cmd = app.add_subcommand("render", "Heat map of traversal steps per pixel (primary rays), shaded image, "
                                               "and the difference of two trees");
  cmd->add_option("bvh", opt->bvh_file, "BVH file")->required()->type_name("FILE.bvh");
  opt->scene.add_to(cmd, "--scene", true);
  cmd->add_option("--heatmap", opt->heatmap,
                  "PNG: steps per pixel, 0 (blue) to the scale's top (red), with colour bar and caption")
      ->required()
      ->type_name("OUT.png");
  cmd->add_option("--shaded", opt->shaded, "PNG: eye-light shading")->type_name("OUT.png");
  cmd->add_option("--compare", opt->compare, "A second BVH file of the same scene")->type_name("OTHER.bvh");
  cmd->add_option("--compare-heatmap", opt->compare_heatmap,
                  "PNG: steps of the --compare tree minus this tree's (default: OUT.png with -diff)")
      ->type_name("OUT.png");
  cmd->add_option("--other-heatmap", opt->other_heatmap,
                  "PNG: the --compare tree's heat map on the same scale (default: OUT.png with -other)")
      ->type_name("OUT.png");
  cmd->add_option("--name", opt->name, "This tree's name in the captions (default: the file name)");
  cmd->add_option("--compare-name", opt->compare_name, "The --compare tree's name in the captions");
  cmd->add_option("--width", opt->width, "Image width")->check(CLI::Range(1u, 16384u))->capture_default_str();
  cmd->add_option("--height", opt->height, "Image height")->check(CLI::Range(1u, 16384u))->capture_default_str();
  cmd->add_option("--scale", opt->scale,
                  "auto: the heat maps' top is the 99th percentile of both trees' steps, rounded up (so a --compare "
                  "pair shares it); fixed: --max-steps (Bittner's 0-100)")
      ->check(CLI::IsMember({"auto", "fixed"}))
      ->capture_default_str();
  cmd->add_option("--max-steps", opt->max_steps, "Steps shown as full red with --scale fixed (giving it implies fixed)")
      ->check(finite_number())
      ->check(positive_number())
      ->capture_default_str()
      ->each([opt](const std::string&) { opt->scale = "fixed"; });
  cmd->add_option("--range", opt->range,
                  "Step difference shown as full red/blue (default: the 99th percentile of |difference|, rounded up; "
                  "50 with --scale fixed)")
      ->check(finite_number())
      ->check(positive_number())
      ->each([opt](const std::string&) { opt->range_given = true; })
      ->capture_default_str();
  cmd->add_flag("--no-legend", opt->no_legend, "Pictures without colour bar and caption (one pixel per ray only)");
  cmd->add_option("--order", opt->order, "axis | distance")->check(CLI::IsMember({"axis", "distance"}))->capture_default_str();
  opt->camera.add_to(cmd);
  opt->layout.add_to(cmd);
  opt->wide_cost.add_to(cmd);
  opt->threads.add_to(cmd);
  cmd->add_flag("--json", opt->json, "Print a summary as JSON");
  cmd->callback([opt] { run_render(*opt); });
}

}  // namespace bvhopt::cli
