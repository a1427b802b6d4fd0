// Scene files through assimp: every mesh of every node, transformed and merged.
#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>
#include <cstring>
#include <unordered_map>
#include <system_error>

#include "bvhopt/bvh_file.h"
#include "bvhopt/error.h"
#include "bvhopt/scene_file.h"
#include "io/gltf_precheck.h"
#include "io/obj_precheck.h"
#include "io/regular_file.h"
#include "io/ply_precheck.h"
#include "io/scene_camera.h"

namespace bvhopt {

namespace {

// Assimp's error strings sometimes end in a newline or are empty; the message we throw
// should read as one line.
std::string clean_assimp_error(const char* text) {
  std::string s = text ? text : "";
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r' || s.back() == ' ')) s.pop_back();
  return s.empty() ? std::string("unknown assimp error") : s;
}

// What assimp does after reading. No aiProcess_FindDegenerates: zero-area triangles are part
// of the input (conference.obj has 52,670) and must be kept and counted, not removed.
// No aiProcess_JoinIdenticalVertices: it welds vertices closer than a fixed absolute epsilon,
// which shrinks a mesh at 1e-6 scale and flattens one at 1e-12; weld_identical_positions
// merges only bit-identical positions instead.
constexpr unsigned kPostProcessing = aiProcess_Triangulate | aiProcess_PreTransformVertices | aiProcess_RemoveComponent;

// Shares one vertex among corners whose positions are bit for bit the same (assimp's OBJ
// reader gives every face corner its own vertex), keeping the first occurrence's order. The
// triangles are exactly the file's: no position moves.
void weld_identical_positions(Mesh& mesh) {
  struct Key {
    uint32_t bits[3];
    bool operator==(const Key&) const = default;
  };
  struct KeyHash {
    size_t operator()(const Key& k) const {
      uint64_t h = (uint64_t(k.bits[0]) << 32 | k.bits[1]) * 0x9e3779b97f4a7c15ull;
      return size_t((h ^ (h >> 29) ^ k.bits[2]) * 0xbf58476d1ce4e5b9ull);
    }
  };
  const size_t n = mesh.positions.size() / 3;
  std::unordered_map<Key, uint32_t, KeyHash> first;
  first.reserve(n);
  std::vector<uint32_t> remap(n);
  std::vector<float> welded;
  welded.reserve(mesh.positions.size());
  for (size_t v = 0; v < n; ++v) {
    Key k;
    std::memcpy(k.bits, &mesh.positions[3 * v], sizeof k.bits);
    auto [it, inserted] = first.try_emplace(k, uint32_t(welded.size() / 3));
    if (inserted) welded.insert(welded.end(), &mesh.positions[3 * v], &mesh.positions[3 * v] + 3);
    remap[v] = it->second;
  }
  for (uint32_t& i : mesh.indices) i = remap[i];
  mesh.positions = std::move(welded);
}

void check_file(const std::filesystem::path& path, const std::string& where) {
  require_regular_file(path, "scene file");
  std::error_code ec;
  if (std::filesystem::file_size(path, ec) == 0 && !ec) throw Error(where + ": empty file");
}

// The file as assimp reads it, before any post-processing.
const aiScene* read_scene(Assimp::Importer& importer, const std::filesystem::path& path, const std::string& where) {
  // Only positions are used: dropping normals, texture coordinates and the like before the
  // post-processing steps keeps loading fast and memory small.
  importer.SetPropertyInteger(AI_CONFIG_PP_RVC_FLAGS, aiComponent_NORMALS | aiComponent_TANGENTS_AND_BITANGENTS |
                                                          aiComponent_COLORS | aiComponent_TEXCOORDS |
                                                          aiComponent_BONEWEIGHTS | aiComponent_ANIMATIONS |
                                                          aiComponent_TEXTURES | aiComponent_LIGHTS |
                                                          aiComponent_CAMERAS | aiComponent_MATERIALS);
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
  return scene;
}

// Faces and numbers of the unprocessed scene.
void check_scene(const aiScene* scene, const std::string& where) {
  bool any_face = false;
  for (unsigned m = 0; m < scene->mNumMeshes && !any_face; ++m)
    for (unsigned f = 0; f < scene->mMeshes[m]->mNumFaces && !any_face; ++f)
      any_face = scene->mMeshes[m]->mFaces[f].mNumIndices >= 3;
  if (!any_face) throw Error(where + ": no triangles (the file holds no polygon faces)");
  // Bad numbers must be caught before post-processing, which trusts the face indices, and
  // before welding, which would treat NaN bit patterns as ordinary positions.
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
}

// Every mesh of the post-processed scene merged into one, in assimp's order.
Mesh merge_meshes(const aiScene* scene, const std::filesystem::path& path, const std::string& where) {
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
  return out;
}

}  // namespace

Mesh load_mesh_file(const std::filesystem::path& path) {
  const std::string where = path.string();
  check_file(path, where);
  if (has_bvh_file_magic(path))
    throw Error(where + ": a bvhopt BVH file (a tree), not a scene: pass the scene the tree was built from");
  check_ply(path, where);
  check_gltf(path, where);
  check_obj(path, where);
  Assimp::Importer importer;
  // Read first and post-process second, so that a file with no faces gets our "no
  // triangles" rather than an error from a post-processing step about orphaned meshes.
  const aiScene* scene = read_scene(importer, path, where);
  check_scene(scene, where);
  const std::string ext = path.extension().string();
  const bool gltf = ext == ".gltf" || ext == ".glb" || ext == ".GLTF" || ext == ".GLB";
  const std::optional<Camera> camera = scene_file_camera(scene, gltf);
  scene = importer.ApplyPostProcessing(kPostProcessing);
  if (!scene) throw Error(where + ": cannot process: " + clean_assimp_error(importer.GetErrorString()));
  Mesh out = merge_meshes(scene, path, where);
  out.camera = camera;
  weld_identical_positions(out);
  check_mesh(out);
  return out;
}

}  // namespace bvhopt
