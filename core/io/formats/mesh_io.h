// Triangle meshes from OBJ and PLY files, read by limn's own readers (no third-party parser):
// every count, index and size in a file is checked against the file's length and the vertex
// count before it is used, and errors name the file and the line (OBJ, ASCII PLY) or the element
// and instance (binary PLY).
#pragma once
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace limn {

struct MeshData {
  std::vector<float> positions;   // 3 per vertex, as stored in the file (not welded)
  std::vector<uint32_t> indices;  // 3 per triangle
  std::vector<float> corner_uvs;  // 6 per triangle, empty if the file has none
};

// Files larger than this are refused before they are read.
inline constexpr uint64_t kMaxMeshFileBytes = uint64_t(1) << 30;

// By content: a file that starts with the line "ply" is PLY, else one named *.ply must be PLY, else
// OBJ. Throws std::invalid_argument naming the file on failure.
MeshData read_mesh_file(const std::string& path);

// The readers on bytes in memory; `name` names the source in error messages.
// PLY: ascii, binary_little_endian and binary_big_endian; the element "vertex" with x, y, z and
// optionally texture coordinates (u v, s t, texture_u texture_v or texture_s texture_t); the element
// "face" with a list vertex_indices (or vertex_index) of 3 or more vertices, triangulated as a fan;
// other elements and properties are skipped by their declared types.
MeshData read_ply(std::string_view bytes, const std::string& name);
// OBJ: v, vt and f (v, v/vt, v//vn, v/vt/vn; negative indices count back from the last vertex);
// polygons are triangulated as a fan; other statements are ignored. Vertices are numbered in the
// order the faces first use them (unused vertices are left out), as assimp did.
MeshData read_obj(std::string_view bytes, const std::string& name);

// Binary little-endian PLY with float positions and int faces (what the Blender exporter writes).
void write_ply(const std::string& path, const std::vector<float>& positions, const std::vector<uint32_t>& indices);

}  // namespace limn
