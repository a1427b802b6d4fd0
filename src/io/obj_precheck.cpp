// The OBJ pre-check: positions and face indices walked line by line before assimp reads
// them, so that an error says where (assimp's say "index out of range" with no line).
#include "io/obj_precheck.h"

#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

#include "bvhopt/error.h"
#include "io/printable_text.h"

namespace bvhopt {
namespace {

// The next blank-separated word of `line` from `at`.
std::string_view next_word(std::string_view line, size_t& at) {
  while (at < line.size() && std::isspace(static_cast<unsigned char>(line[at]))) ++at;
  const size_t start = at;
  while (at < line.size() && !std::isspace(static_cast<unsigned char>(line[at]))) ++at;
  return line.substr(start, at - start);
}

void check_vertex(std::string_view line, size_t at, uint64_t vertex, const std::string& place) {
  for (int axis = 0; axis < 3; ++axis) {
    const std::string word(next_word(line, at));
    const std::string what = place + ": vertex " + std::to_string(vertex) + ": ";
    if (word.empty()) throw Error(what + std::to_string(axis) + " coordinates (expected x y z)");
    char* end = nullptr;
    errno = 0;
    const float v = std::strtof(word.c_str(), &end);
    if (end != word.c_str() + word.size()) throw Error(what + "coordinate '" + printable(word, 40) + "' is not a number");
    if (!std::isfinite(v))
      throw Error(what + "coordinate " + "xyz"[axis] + " is " + (std::isnan(v) ? "NaN" : "infinite") + " ('" +
                  printable(word, 40) + "')");
  }
}

// A positive face index above the vertices read so far: legal only if the file defines
// that many vertices in all (assimp resolves them at the end), so it is checked then.
struct ForwardIndex {
  uint64_t line = 0;
  int64_t index = 0;
};

// A face's vertex references "v", "v/t", "v//n" or "v/t/n": v is 1-based, or negative
// counting back from the last vertex so far.
void check_face(std::string_view line, size_t at, uint64_t vertices, uint64_t line_number, const std::string& place,
                std::vector<ForwardIndex>& forward) {
  for (;;) {
    const std::string_view word = next_word(line, at);
    if (word.empty()) return;
    const std::string_view v = word.substr(0, word.find('/'));
    int64_t index = 0;
    const auto [ptr, ec] = std::from_chars(v.data(), v.data() + v.size(), index);
    if (v.empty() || ec != std::errc() || ptr != v.data() + v.size())
      throw Error(place + ": face index '" + printable(word, 40) + "' is not a whole number");
    if (index == 0) throw Error(place + ": face index 0 is not a vertex (OBJ indices start at 1)");
    if (index > 0 && uint64_t(index) > vertices) {
      if (forward.empty() || forward.back().line != line_number || forward.back().index < index)
        forward.push_back({line_number, index});
      continue;
    }
    if (index < 0 && uint64_t(-(index + 1)) >= vertices)
      throw Error(place + ": face index " + std::to_string(index) + " out of range (" + std::to_string(vertices) +
                  " vertices above it)");
  }
}

}  // namespace

void check_obj(const std::filesystem::path& path, const std::string& where) {
  std::string extension = path.extension().string();
  for (char& c : extension) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (extension != ".obj") return;
  std::ifstream in(path, std::ios::binary);
  uint64_t vertices = 0, line_number = 0;
  std::vector<ForwardIndex> forward;
  std::string line;
  while (std::getline(in, line)) {
    const uint64_t first_line = ++line_number;
    // A backslash at the end continues the statement on the next line.
    std::string more;
    while (!line.empty() && (line.back() == '\\' || (line.back() == '\r' && line.size() > 1 && line[line.size() - 2] == '\\')) &&
           std::getline(in, more)) {
      line.erase(line.find_last_of('\\'));
      line += ' ' + more;
      ++line_number;
    }
    size_t at = 0;
    const std::string_view keyword = next_word(line, at);
    const std::string place = where + ": line " + std::to_string(first_line);
    if (keyword == "v") {
      check_vertex(line, at, vertices, place);
      ++vertices;
    } else if (keyword == "f") {
      check_face(line, at, vertices, first_line, place, forward);
    }
  }
  for (const ForwardIndex& f : forward)
    if (uint64_t(f.index) > vertices)
      throw Error(where + ": line " + std::to_string(f.line) + ": face index " + std::to_string(f.index) +
                  " out of range (the file has " + std::to_string(vertices) + " vertices)");
}

}  // namespace bvhopt
