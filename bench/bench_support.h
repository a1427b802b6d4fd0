// Helpers every benchmark program in bench/ needs. They lived as copies in each *_bench.cpp,
// and the copies had started to drift apart (folder checks, JSON write checks); one
// implementation here keeps the programs' shared behaviour the same. Header-only: each bench
// is a single-file program, and bench/CMakeLists.txt puts this folder on its include path.
#pragma once

#include <tbb/global_control.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "bvhopt/error.h"
#include "bvhopt/optimize_report.h"
#include "bvhopt/scene.h"

namespace bvhopt::bench {

// ---- command line ----

// Numbers on a bench's command line. The whole text must be the number, else an Error naming
// the option and the text: std::stod and std::stoi alone report just "stod" or "stoi", and
// read "3x" as 3.
inline double parse_double(const std::string& text, const std::string& option) {
  double v = 0.0;
  const char* end = text.data() + text.size();
  const auto [p, ec] = std::from_chars(text.data(), end, v);
  if (ec != std::errc() || p != end || !std::isfinite(v))
    throw Error("option " + option + ": '" + text + "' is not a finite number");
  return v;
}
inline int64_t parse_integer(const std::string& text, const std::string& option, int64_t min, int64_t max) {
  int64_t v = 0;
  const char* end = text.data() + text.size();
  const auto [p, ec] = std::from_chars(text.data(), end, v);
  if (ec != std::errc() || p != end)
    throw Error("option " + option + ": '" + text + "' is not a whole number");
  if (v < min || v > max)
    throw Error("option " + option + ": " + text + " is out of range (" + std::to_string(min) + " to " +
                std::to_string(max) + ")");
  return v;
}
inline int parse_int(const std::string& text, const std::string& option) {
  return int(parse_integer(text, option, INT_MIN, INT_MAX));
}

// Walks argv for a bench's option loop. Each program keeps its own option table; what is
// common is fetching an option's value and failing, named after the program, when it is
// missing.
class Args {
 public:
  Args(int argc, char** argv, std::string program) : argc_(argc), argv_(argv), program_(std::move(program)) {}

  // Moves to the next argument; false when there is none left.
  bool next() {
    if (++i_ >= argc_) return false;
    current_ = argv_[i_];
    return true;
  }
  const std::string& current() const { return current_; }
  const std::string& program() const { return program_; }

  // The argument after the current option (consumed).
  std::string value() {
    if (i_ + 1 >= argc_) throw Error(program_ + ": option " + current_ + " needs a value");
    return argv_[++i_];
  }
  // The value as a number (see parse_double, parse_integer).
  double double_value() { return parse_double(value(), current_); }
  int int_value() { return parse_int(value(), current_); }
  uint32_t u32_value() { return uint32_t(parse_integer(value(), current_, 0, UINT32_MAX)); }
  uint64_t u64_value() { return uint64_t(parse_integer(value(), current_, 0, INT64_MAX)); }

 private:
  int argc_;
  char** argv_;
  std::string program_;
  int i_ = 0;
  std::string current_;
};

// "a,b,,c" -> {"a", "b", "c"}: the form of every list option (--threads 1,2, --kinds ...).
inline std::vector<std::string> split_list(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

// A comma-separated list of costs above 0 (c_blk values, say), at least one.
inline std::vector<double> parse_positive_list(const std::string& text, const std::string& option) {
  std::vector<double> out;
  for (const std::string& c : split_list(text)) {
    const double v = parse_double(c, option);
    if (!(v > 0.0)) throw Error("option " + option + " takes costs above 0, got '" + c + "'");
    out.push_back(v);
  }
  if (out.empty()) throw Error("option " + option + " needs at least one cost");
  return out;
}

// ---- scenes ----

// The scenes folder when --scenes is not given: $BVHOPT_SCENES if set and not empty, else
// the shared folder beside the checkout (relative, so it works from the checkout's root).
inline std::filesystem::path default_scenes_dir() {
  if (const char* env = std::getenv("BVHOPT_SCENES"); env && *env) return env;
  return "../shared/scenes";
}

// Every scene file (.obj, .ply, .glb, .gltf) in `dir`, sorted so that runs and their JSON
// list the scenes in the same order. Throws if `dir` is not a folder.
inline std::vector<std::string> list_scene_files(const std::filesystem::path& dir) {
  if (!std::filesystem::is_directory(dir))
    throw Error(dir.string() + ": scenes folder not found (set BVHOPT_SCENES or pass --scenes DIR)");
  std::vector<std::string> files;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    const std::string ext = e.path().extension().string();
    if (e.is_regular_file() && (ext == ".obj" || ext == ".ply" || ext == ".glb" || ext == ".gltf"))
      files.push_back(e.path().string());
  }
  std::sort(files.begin(), files.end());
  return files;
}

// Which scenes a bench runs: --scenes DIR, --scene FILE (repeatable) and, for the benches
// that load through load_scene, the built-in scene (--no-builtin, --builtin SPEC).
struct SceneOptions {
  std::filesystem::path dir = default_scenes_dir();
  std::vector<std::string> files;  // --scene picks; empty = every scene in `dir`
  bool builtin_options = true;     // false: no built-in scene, and its options are unknown
  bool builtin = true;
  std::string builtin_spec = "builtin";

  static SceneOptions files_only() {
    SceneOptions s;
    s.builtin_options = false;
    s.builtin = false;
    return s;
  }
};

// Reads the current argument if it is one of the scene options; false if it is not.
inline bool read_scene_option(Args& args, SceneOptions& s) {
  const std::string& a = args.current();
  if (a == "--scenes") s.dir = args.value();
  else if (a == "--scene") s.files.push_back(args.value());
  else if (s.builtin_options && a == "--no-builtin") s.builtin = false;
  else if (s.builtin_options && a == "--builtin") s.builtin_spec = args.value();
  else return false;
  return true;
}

// Throws, naming the first file that is missing, before a run starts: a bench loads its
// scenes in turn, and a wrong path found after the large scenes' runs wastes them.
inline void require_scene_files(const std::vector<std::string>& specs) {
  for (const std::string& spec : specs)
    if (!is_builtin_scene_spec(spec) && !std::filesystem::is_regular_file(spec))
      throw Error(spec + ": scene file not found (the shared scenes are read from $BVHOPT_SCENES, by default "
                         "../shared/scenes from the working directory; --scene takes a path)");
}

// The scenes to run, in order: the --scene picks, or else every scene of the folder; then
// the built-in scene if enabled. A pick that is not a file is an error, before anything
// runs (require_scene_files). A missing folder is an error, unless `warn_as` names the
// program: then it is a warning on stderr and the run goes on (insertion_bench still runs
// the built-in scene without the shared folder).
inline std::vector<std::string> scene_specs(const SceneOptions& s, const char* warn_as = nullptr) {
  std::vector<std::string> specs = s.files;
  require_scene_files(specs);
  if (specs.empty()) {
    try {
      specs = list_scene_files(s.dir);
    } catch (const Error& e) {
      if (!warn_as) throw;
      std::fprintf(stderr, "%s: %s\n", warn_as, e.what());
    }
  }
  if (s.builtin) specs.push_back(s.builtin_spec);
  return specs;
}

// ---- timing ----

// Wall seconds of one call, on the steady clock.
inline double seconds_of(const std::function<void()>& f) {
  const auto start = std::chrono::steady_clock::now();
  f();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// CPU seconds so far of the whole process (all threads) and of the calling thread. CPU time
// is what the benches use where a shared machine's load would skew wall times.
inline double cpu_seconds(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}
inline double process_cpu_seconds() { return cpu_seconds(CLOCK_PROCESS_CPUTIME_ID); }
inline double thread_cpu_seconds() { return cpu_seconds(CLOCK_THREAD_CPUTIME_ID); }

// The benches report medians of repeated runs: robust to the odd run another process
// slows down. Two conventions are in use and both are kept, since changing one would move
// a program's published figures for even run counts:
//   median        the mean of the two middle values for an even count (build, rotations, evh);
//   upper_median  the upper of the two middle values (insertion, trace).
// Both return 0 for no values.
inline double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}
inline double upper_median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// Caps oneTBB at `threads` worker threads while in scope: how every bench times the same
// work on 1 and on 2 threads.
class ThreadLimit {
 public:
  explicit ThreadLimit(int threads) : control_(tbb::global_control::max_allowed_parallelism, size_t(threads)) {}

 private:
  tbb::global_control control_;
};

// ---- optimizer traces ----

// The cost after the last pass that ended within `seconds` into the run (the initial cost if
// none did); with `best`, the lowest cost by then (what a time budget of that length keeps).
inline double cost_within(const OptimizeReport& rep, double seconds, bool best = false) {
  double cost = rep.initial_cost;
  for (const PassRecord& p : rep.trace)
    if (p.seconds <= seconds) cost = best ? p.best_cost : p.cost;
  return cost;
}

// ---- output ----

// printf into a std::string, for table cells built before the row is printed.
inline std::string strprintf(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
inline std::string strprintf(const char* fmt, ...) {
  va_list args;
  va_start(args, fmt);
  va_list again;
  va_copy(again, args);
  const int n = std::vsnprintf(nullptr, 0, fmt, args);
  va_end(args);
  std::string out(size_t(std::max(n, 0)), '\0');
  std::vsnprintf(out.data(), out.size() + 1, fmt, again);
  va_end(again);
  return out;
}

// Writes the --json result: two-space indent and a final newline, as every bench always
// did. Failing to open or to write the file is an error, not a silent loss of the results.
inline void write_json(const std::string& path, const nlohmann::json& j) {
  std::ofstream f(path);
  if (!f) throw Error(path + ": cannot open for writing");
  f << j.dump(2) << "\n";
  f.flush();
  if (!f) throw Error(path + ": cannot write");
}

// The body of every bench's main(): runs `body` and turns an exception into a message on
// stderr ("<prefix>: <what>") and exit status 1.
inline int guarded_main(const char* prefix, const std::function<int()>& body) {
  try {
    return body();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", prefix, e.what());
    return 1;
  }
}

}  // namespace bvhopt::bench
