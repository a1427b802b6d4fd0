// Scene files through assimp: every mesh of every node, transformed and merged.
#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "bvhopt/error.h"
#include "bvhopt/scene.h"

namespace bvhopt {

namespace {

// Assimp's error strings sometimes end in a newline or are empty; the message we throw
// should read as one line.
std::string clean_assimp_error(const char* text) {
  std::string s = text ? text : "";
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r' || s.back() == ' ')) s.pop_back();
  return s.empty() ? std::string("unknown assimp error") : s;
}

// Assimp 5.2's binary PLY reader runs off the end of its buffer (a crash, not an error) when
// the data stops short of what the header promises or a face names a vertex that does not
// exist, and its ASCII reader fills a short file's missing faces with junk. So PLY files
// are walked here first, element by element, and a short or inconsistent one is rejected
// with the place where it goes wrong. Other formats go straight to assimp.
void check_ply(const std::filesystem::path& path, const std::string& where) {
  std::ifstream in(path, std::ios::binary);
  std::string magic;
  if (!std::getline(in, magic) || (magic != "ply" && magic != "ply\r")) return;  // not PLY: assimp decides
  struct Property {
    int size = 0;        // bytes of a scalar, or of each list item
    int count_size = 0;  // lists only: bytes of the item count
  };
  struct Element {
    std::string name;
    uint64_t count = 0;
    std::vector<Property> properties;
  };
  auto type_size = [&](const std::string& type, int line) {
    if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
    if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
    if (type == "int" || type == "uint" || type == "int32" || type == "uint32" || type == "float" || type == "float32")
      return 4;
    if (type == "double" || type == "float64") return 8;
    throw Error(where + ": header line " + std::to_string(line) + ": unknown property type '" + type + "'");
  };
  std::vector<Element> elements;
  std::string format;
  bool ended = false;
  std::string text;
  for (int line = 2; !ended && std::getline(in, text); ++line) {
    if (!text.empty() && text.back() == '\r') text.pop_back();
    std::istringstream words(text);
    std::string word;
    words >> word;
    if (word == "format") {
      words >> format;
    } else if (word == "element") {
      Element e;
      if (!(words >> e.name >> e.count))
        throw Error(where + ": header line " + std::to_string(line) + ": malformed element line '" + text + "'");
      elements.push_back(std::move(e));
    } else if (word == "property") {
      if (elements.empty())
        throw Error(where + ": header line " + std::to_string(line) + ": property before any element");
      std::string type;
      words >> type;
      Property p;
      if (type == "list") {
        std::string count_type, item_type;
        words >> count_type >> item_type;
        p.count_size = type_size(count_type, line);
        p.size = type_size(item_type, line);
      } else {
        p.size = type_size(type, line);
      }
      elements.back().properties.push_back(p);
    } else if (word == "end_header") {
      ended = true;
    }
    if (line > 100000) break;
  }
  if (!ended) throw Error(where + ": PLY header has no end_header line (truncated or corrupt)");
  const bool little = format == "binary_little_endian";
  const std::vector<char> data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  uint64_t vertex_count = 0;
  for (const Element& e : elements)
    if (e.name == "vertex") vertex_count = e.count;
  if (format == "ascii") {
    // Assimp fills the faces of a short ASCII file with whatever it finds; walk the
    // whitespace-separated numbers instead.
    size_t at = 0;
    auto next_token = [&](std::string_view& token) {
      while (at < data.size() && std::isspace(static_cast<unsigned char>(data[at]))) ++at;
      const size_t start = at;
      while (at < data.size() && !std::isspace(static_cast<unsigned char>(data[at]))) ++at;
      token = std::string_view(data.data() + start, at - start);
      return at > start;
    };
    auto to_integer = [](std::string_view t, int64_t& v) {
      auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
      return ec == std::errc() && ptr == t.data() + t.size();
    };
    std::string_view token;
    for (const Element& e : elements) {
      const bool is_face = e.name == "face";
      auto short_by = [&](uint64_t index) {
        return Error(where + ": truncated: the data ends in " + e.name + " " + std::to_string(index) + " of " +
                     std::to_string(e.count));
      };
      for (uint64_t i = 0; i < e.count; ++i)
        for (const Property& prop : e.properties) {
          if (!next_token(token)) throw short_by(i);
          if (!prop.count_size) continue;
          int64_t n = 0;
          if (!to_integer(token, n) || n < 0)
            throw Error(where + ": " + e.name + " " + std::to_string(i) + ": bad list length '" + std::string(token) + "'");
          for (int64_t k = 0; k < n; ++k) {
            if (!next_token(token)) throw short_by(i);
            int64_t index = 0;
            if (is_face && (!to_integer(token, index) || index < 0 || static_cast<uint64_t>(index) >= vertex_count))
              throw Error(where + ": face " + std::to_string(i) + ": vertex index '" + std::string(token) +
                          "' out of range (" + std::to_string(vertex_count) + " vertices)");
          }
        }
    }
    return;
  }
  if (!little && format != "binary_big_endian")
    throw Error(where + ": PLY header: unknown format '" + format + "'");

  const unsigned char* p = reinterpret_cast<const unsigned char*>(data.data());
  const size_t size = data.size();
  auto read_unsigned = [&](size_t offset, int bytes) {
    uint64_t n = 0;
    for (int b = 0; b < bytes; ++b) n |= uint64_t(p[offset + (little ? b : bytes - 1 - b)]) << (8 * b);
    return n;
  };
  // A corrupt vertex index crashes the reader as surely as missing data, so face lists
  // are checked against the vertex count too (a negative index reads as a huge one).
  size_t at = 0;
  for (const Element& e : elements) {
    const bool is_face = e.name == "face";
    uint64_t fixed = 0;
    bool has_list = false;
    for (const Property& prop : e.properties) {
      if (prop.count_size) has_list = true;
      else fixed += prop.size;
    }
    auto short_by = [&](uint64_t index) {
      return Error(where + ": truncated: the data ends in " + e.name + " " + std::to_string(index) + " of " +
                   std::to_string(e.count) + " (" + std::to_string(size) + " bytes after the header)");
    };
    if (!has_list) {
      // Elements of fixed size are checked in one step.
      if (fixed && e.count > (size - at) / fixed) throw short_by((size - at) / fixed);
      at += fixed * e.count;
      continue;
    }
    for (uint64_t i = 0; i < e.count; ++i)
      for (const Property& prop : e.properties) {
        if (!prop.count_size) {
          if (size - at < static_cast<size_t>(prop.size)) throw short_by(i);
          at += prop.size;
          continue;
        }
        if (size - at < static_cast<size_t>(prop.count_size)) throw short_by(i);
        const uint64_t n = read_unsigned(at, prop.count_size);
        at += prop.count_size;
        if (n > (size - at) / prop.size) throw short_by(i);
        if (is_face)
          for (uint64_t k = 0; k < n; ++k) {
            const uint64_t index = read_unsigned(at + k * prop.size, prop.size);
            if (index >= vertex_count)
              throw Error(where + ": face " + std::to_string(i) + ": vertex index " + std::to_string(index) +
                          " out of range (" + std::to_string(vertex_count) + " vertices)");
          }
        at += n * prop.size;
      }
  }
}
}  // namespace

Mesh load_mesh_file(const std::filesystem::path& path) {
  const std::string where = path.string();
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(status)) throw Error(where + ": no such file");
  if (std::filesystem::is_directory(status)) throw Error(where + ": is a directory, not a scene file");
  if (std::filesystem::file_size(path, ec) == 0 && !ec) throw Error(where + ": empty file");

  check_ply(path, where);

  Assimp::Importer importer;
  // Only positions are used: dropping normals, texture coordinates and the like before the
  // post-processing steps keeps loading fast and memory small.
  importer.SetPropertyInteger(AI_CONFIG_PP_RVC_FLAGS, aiComponent_NORMALS | aiComponent_TANGENTS_AND_BITANGENTS |
                                                          aiComponent_COLORS | aiComponent_TEXCOORDS |
                                                          aiComponent_BONEWEIGHTS | aiComponent_ANIMATIONS |
                                                          aiComponent_TEXTURES | aiComponent_LIGHTS |
                                                          aiComponent_CAMERAS | aiComponent_MATERIALS);
  // No aiProcess_FindDegenerates: zero-area triangles are part of the input (conference.obj
  // has 52,670) and must be kept and counted, not removed.
  const unsigned flags = aiProcess_Triangulate | aiProcess_PreTransformVertices | aiProcess_RemoveComponent | aiProcess_JoinIdenticalVertices;
  // Read first and post-process second, so that a file with no faces gets our "no
  // triangles" rather than an error from a post-processing step about orphaned meshes.
  const aiScene* scene = importer.ReadFile(where, 0);
  if (!scene) {
    const std::string ext = path.extension().string();
    if (!importer.IsExtensionSupported(ext.empty() ? std::string(".") : ext))
      throw Error(where + ": unknown file format " + (ext.empty() ? std::string("(no extension)") : "'" + ext + "'") +
                  " (" + clean_assimp_error(importer.GetErrorString()) + ")");
    throw Error(where + ": cannot read: " + clean_assimp_error(importer.GetErrorString()));
  }
  if (scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE)
    throw Error(where + ": incomplete scene (the file is truncated or corrupt, or not a " +
                path.extension().string() + " file)");
  bool any_face = false;
  for (unsigned m = 0; m < scene->mNumMeshes && !any_face; ++m)
    for (unsigned f = 0; f < scene->mMeshes[m]->mNumFaces && !any_face; ++f)
      any_face = scene->mMeshes[m]->mFaces[f].mNumIndices >= 3;
  if (!any_face) throw Error(where + ": no triangles (the file holds no polygon faces)");
  // Bad numbers must be caught before post-processing: JoinIdenticalVertices compares with
  // NaN, finds no difference and would quietly weld a NaN vertex onto a good one, and
  // every step trusts the face indices.
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* mesh = scene->mMeshes[m];
    const std::string mesh_name =
        "mesh " + std::to_string(m) + (mesh->mName.length ? " '" + std::string(mesh->mName.C_Str()) + "'" : "");
    for (unsigned v = 0; v < mesh->mNumVertices; ++v)
      for (int axis = 0; axis < 3; ++axis) {
        const float c = mesh->mVertices[v][axis];
        if (!std::isfinite(c))
          throw Error(where + ": " + mesh_name + ", vertex " + std::to_string(v) + ": coordinate " + "xyz"[axis] +
                      " is " + (std::isnan(c) ? "NaN" : "infinite"));
      }
    for (unsigned f = 0; f < mesh->mNumFaces; ++f)
      for (unsigned k = 0; k < mesh->mFaces[f].mNumIndices; ++k)
        if (mesh->mFaces[f].mIndices[k] >= mesh->mNumVertices)
          throw Error(where + ": " + mesh_name + ", face " + std::to_string(f) + ": vertex index " +
                      std::to_string(mesh->mFaces[f].mIndices[k]) + " out of range (" +
                      std::to_string(mesh->mNumVertices) + " vertices)");
  }
  scene = importer.ApplyPostProcessing(flags);
  if (!scene) throw Error(where + ": cannot process: " + clean_assimp_error(importer.GetErrorString()));

  size_t vertex_total = 0, triangle_total = 0;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* mesh = scene->mMeshes[m];
    vertex_total += mesh->mNumVertices;
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) triangle_total += mesh->mFaces[f].mNumIndices == 3;
  }
  if (triangle_total == 0) throw Error(where + ": no triangles (the file holds no polygon faces)");
  if (vertex_total > std::numeric_limits<uint32_t>::max())
    throw Error(where + ": " + std::to_string(vertex_total) + " vertices, more than 32-bit indices can address");

  Mesh out;
  out.name = path.filename().string();
  out.positions.resize(3 * vertex_total);
  out.indices.reserve(3 * triangle_total);
  size_t base = 0;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* mesh = scene->mMeshes[m];
    float* dst = out.positions.data() + 3 * base;
    for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
      dst[3 * v] = static_cast<float>(mesh->mVertices[v].x);
      dst[3 * v + 1] = static_cast<float>(mesh->mVertices[v].y);
      dst[3 * v + 2] = static_cast<float>(mesh->mVertices[v].z);
    }
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      // Points and lines (fewer than three indices) are not surfaces: skipped. After
      // aiProcess_Triangulate nothing has more than three.
      if (face.mNumIndices != 3) continue;
      for (int k = 0; k < 3; ++k) {
        const unsigned i = face.mIndices[k];
        if (i >= mesh->mNumVertices)
          throw Error(where + ": mesh " + std::to_string(m) + ", face " + std::to_string(f) + ": vertex index " +
                      std::to_string(i) + " out of range (" + std::to_string(mesh->mNumVertices) + " vertices)");
        out.indices.push_back(static_cast<uint32_t>(base + i));
      }
    }
    base += mesh->mNumVertices;
  }
  check_mesh(out);
  return out;
}

}  // namespace bvhopt
