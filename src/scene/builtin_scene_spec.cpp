// The built-in scene's spec, "builtin[:atrium][?triangles=N&seed=S]", as the command line takes it.
#include <charconv>
#include <string>
#include <string_view>

#include "bvhopt/error.h"
#include "bvhopt/scene.h"

namespace bvhopt {

namespace {

constexpr std::string_view kBuiltin = "builtin";
uint64_t parse_number(const std::string& spec, std::string_view key, std::string_view text) {
  uint64_t value = 0;
  const char* first = text.data();
  const char* last = text.data() + text.size();
  auto [ptr, ec] = std::from_chars(first, last, value);
  if (text.empty() || ec != std::errc() || ptr != last)
    throw Error(spec + ": option '" + std::string(key) + "': '" + std::string(text) +
                "' is not a non-negative integer");
  return value;
}

}  // namespace

BuiltinSceneConfig parse_builtin_scene_spec(const std::string& spec) {
  if (!is_builtin_scene_spec(spec))
    throw Error(spec + ": not the built-in scene (expected builtin[:atrium][?triangles=N&seed=S])");
  std::string_view rest = std::string_view(spec).substr(kBuiltin.size());
  std::string_view name = "atrium";
  std::string_view options;
  if (size_t q = rest.find('?'); q != std::string_view::npos) {
    options = rest.substr(q + 1);
    rest = rest.substr(0, q);
    if (options.empty()) throw Error(spec + ": nothing after '?' (expected e.g. ?triangles=1000000&seed=7)");
  }
  if (!rest.empty()) {
    if (rest[0] != ':') throw Error(spec + ": unknown scene (expected builtin, builtin:atrium or a file)");
    name = rest.substr(1);
  }
  if (name != "atrium")
    throw Error(spec + ": unknown built-in scene '" + std::string(name) + "' (available: atrium)");

  BuiltinSceneConfig config;
  bool seen_triangles = false, seen_seed = false;
  while (!options.empty()) {
    size_t amp = options.find('&');
    std::string_view item = options.substr(0, amp);
    options = amp == std::string_view::npos ? std::string_view() : options.substr(amp + 1);
    size_t eq = item.find('=');
    if (eq == std::string_view::npos)
      throw Error(spec + ": option '" + std::string(item) + "' has no value (expected key=value)");
    std::string_view key = item.substr(0, eq), value = item.substr(eq + 1);
    if (key == "triangles") {
      if (seen_triangles) throw Error(spec + ": option 'triangles' given twice");
      seen_triangles = true;
      config.target_triangles = parse_number(spec, key, value);
      if (config.target_triangles == 0 || config.target_triangles > kMaxBuiltinTriangles)
        throw Error(spec + ": option 'triangles': " + std::string(value) + " is out of range (1 to " +
                    std::to_string(kMaxBuiltinTriangles) + ")");
    } else if (key == "seed") {
      if (seen_seed) throw Error(spec + ": option 'seed' given twice");
      seen_seed = true;
      config.seed = parse_number(spec, key, value);
    } else {
      throw Error(spec + ": unknown option '" + std::string(key) + "' (available: triangles, seed)");
    }
  }
  if (seen_triangles) {
    const uint64_t fewest = min_builtin_scene_triangles(config.seed);
    if (config.target_triangles < fewest)
      throw Error(spec + ": option 'triangles': " + std::to_string(config.target_triangles) +
                  " is below the smallest built-in scene, " + std::to_string(fewest) +
                  " triangles (its walls, vaults and stairs alone)");
  }
  return config;
}

Mesh load_builtin_scene(const std::string& spec) {
  Mesh mesh = make_builtin_scene(parse_builtin_scene_spec(spec));
  mesh.name = spec;
  return mesh;
}

bool is_builtin_scene_spec(const std::string& spec) {
  return spec.compare(0, kBuiltin.size(), kBuiltin) == 0 &&
         (spec.size() == kBuiltin.size() || spec[kBuiltin.size()] == ':' || spec[kBuiltin.size()] == '?');
}

}  // namespace bvhopt
