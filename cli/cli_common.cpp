// Options and output helpers shared by the subcommands.
#include "cli_common.h"

#include <tbb/task_arena.h>
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <vector>

#include "bvhopt/error.h"
#include "bvhopt/scene_file.h"

namespace bvhopt::cli {

void ThreadsOption::add_to(CLI::App* app) {
  app->add_option("--threads", threads, "Worker threads (default, or 0: all cores)")
      ->check(CLI::Range(0, 4096))
      ->type_name("N");
}

std::unique_ptr<tbb::global_control> ThreadsOption::apply() const {
  if (threads <= 0) return nullptr;
  return std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                               static_cast<size_t>(threads));
}

int ThreadsOption::effective() const {
  // global_control only lowers the parallelism: the default arena never runs more threads
  // than the machine has cores, whatever count was asked for.
  const int cores = tbb::this_task_arena::max_concurrency();
  return threads > 0 ? std::min(threads, cores) : cores;
}

CLI::Validator finite_number() {
  return CLI::Validator(
      [](std::string& text) {
        double value = 0.0;
        if (CLI::detail::lexical_cast(text, value) && !std::isfinite(value))
          return std::string("'" + text + "' is not a finite number");
        return std::string();
      },
      "FINITE");
}

namespace {

CLI::Validator compared_to_zero(bool allow_zero) {
  return CLI::Validator(
      [allow_zero](std::string& text) {
        double value = 0.0;
        if (!CLI::detail::lexical_cast(text, value)) return std::string("'" + text + "' is not a number");
        if (allow_zero ? value >= 0.0 : value > 0.0) return std::string();
        return std::string("'" + text + "' must be " + (allow_zero ? ">= 0" : "> 0"));
      },
      allow_zero ? "NUMBER >= 0" : "NUMBER > 0");
}

}  // namespace

CLI::Validator positive_number() { return compared_to_zero(false); }
CLI::Validator non_negative_number() { return compared_to_zero(true); }

CLI::Validator whole_number(uint64_t lo, uint64_t hi) {
  const std::string range = std::to_string(lo) + " to " + std::to_string(hi);
  return CLI::Validator(
      [lo, hi, range](std::string& text) {
        uint64_t value = 0;
        const char* end = text.data() + text.size();
        const auto [ptr, ec] = std::from_chars(text.data(), end, value);
        if (text.empty() || ec != std::errc() || ptr != end || value < lo || value > hi)
          return std::string("'" + text + "' is not a whole number from " + range);
        return std::string();
      },
      "N in " + range);
}

namespace {

// "X,Y,Z" in degrees; the whole text must be three finite numbers.
Vec3 parse_rotation(const std::string& text) {
  const std::string what = "--rotate '" + text + "': ";
  std::vector<float> values;
  size_t start = 0;
  for (;;) {
    size_t comma = text.find(',', start);
    std::string item = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    size_t used = 0;
    float v = 0;
    try {
      v = std::stof(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    // Skip trailing blanks so "10, 20, 30" reads naturally.
    while (used < item.size() && item[used] == ' ') ++used;
    if (item.empty() || used != item.size())
      throw Error(what + "'" + item + "' is not a number (expected three angles in degrees, X,Y,Z)");
    if (!std::isfinite(v)) throw Error(what + "'" + item + "' is not a finite angle");
    values.push_back(v);
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  if (values.size() != 3)
    throw Error(what + "expected three angles in degrees, X,Y,Z, got " + std::to_string(values.size()));
  return {values[0], values[1], values[2]};
}

}  // namespace

void SceneOption::add_to(CLI::App* app, const std::string& name, bool required) {
  auto* opt = app->add_option(name, spec,
                              "A scene file (OBJ, PLY, glTF/GLB, ... anything assimp reads) or the built-in scene: "
                              "builtin[:atrium][?triangles=N&seed=S]");
  opt->type_name("SCENE");
  if (required) opt->required();
  app->add_option("--rotate", rotate, "Rotate the scene about its centre by X,Y,Z degrees (x first, then y, then z)")
      ->type_name("X,Y,Z");
}

Mesh SceneOption::load() const {
  // Parse the angles before a possibly long load, so a typo fails at once.
  const bool rotating = !rotate.empty();
  const Vec3 degrees = rotating ? parse_rotation(rotate) : Vec3();
  Mesh mesh = load_scene(spec);
  check_mesh(mesh);
  if (rotating) rotate_mesh(mesh, degrees);
  return mesh;
}

bool stderr_is_terminal() { return ::isatty(2) == 1; }

ProgressLine::ProgressLine() : enabled_(stderr_is_terminal()) {}

ProgressLine::~ProgressLine() { finish(); }

void ProgressLine::update(const std::string& text, bool force) {
  if (!enabled_) return;
  const auto now = std::chrono::steady_clock::now();
  // At most five redraws a second: a terminal flooded with updates slows the work down.
  if (drawn_ && !force && now - last_ < std::chrono::milliseconds(200)) return;
  std::fprintf(stderr, "\r%s\033[K", text.c_str());
  std::fflush(stderr);
  drawn_ = true;
  last_ = now;
}

void ProgressLine::finish() {
  if (!enabled_ || !drawn_) return;
  std::fputs("\r\033[K", stderr);
  std::fflush(stderr);
  drawn_ = false;
}

void print_json(const nlohmann::json& j) { std::cout << j.dump(2) << "\n"; }

nlohmann::json spatial_split_json(const SpatialSplitStats& s) {
  return {{"budget_references", s.budget},
          {"spatial_splits", s.spatial_splits},
          {"object_splits", s.object_splits},
          {"split_references", s.split_references},
          {"unsplit_references", s.unsplit_references}};
}

std::string format_double(double v, int precision) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  std::ostringstream s;
  s << std::fixed << std::setprecision(precision) << v;
  return s.str();
}

}  // namespace bvhopt::cli
