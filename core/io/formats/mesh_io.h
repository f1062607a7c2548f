// Triangle meshes from OBJ and PLY files through assimp.
#pragma once
#include <string>
#include <vector>

namespace limn {

struct MeshData {
  std::vector<float> positions;   // 3 per vertex, as stored in the file (not welded)
  std::vector<uint32_t> indices;  // 3 per triangle
  std::vector<float> corner_uvs;  // 6 per triangle, empty if the file has none
};

// Throws std::invalid_argument naming the file on failure.
MeshData read_mesh_file(const std::string& path);
// Binary little-endian PLY with float positions and int faces (what the Blender exporter writes).
void write_ply(const std::string& path, const std::vector<float>& positions, const std::vector<uint32_t>& indices);

}  // namespace limn
