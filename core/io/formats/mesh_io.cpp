#include "core/io/formats/mesh_io.h"

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <filesystem>
#include <fstream>
#include <stdexcept>

namespace limn {

MeshData read_mesh_file(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw std::invalid_argument("mesh file '" + path + "' not found");
  Assimp::Importer importer;
  // Triangulate polygons; keep positions exactly as stored (welding happens later, by position).
  const aiScene* scene = importer.ReadFile(path, aiProcess_Triangulate);
  if (!scene || !scene->mRootNode) throw std::invalid_argument("cannot read mesh '" + path + "': " + importer.GetErrorString());
  MeshData out;
  for (unsigned mi = 0; mi < scene->mNumMeshes; ++mi) {
    const aiMesh* m = scene->mMeshes[mi];
    const uint32_t base = uint32_t(out.positions.size() / 3);
    for (unsigned v = 0; v < m->mNumVertices; ++v)
      out.positions.insert(out.positions.end(), {m->mVertices[v].x, m->mVertices[v].y, m->mVertices[v].z});
    const bool has_uv = m->HasTextureCoords(0);
    for (unsigned f = 0; f < m->mNumFaces; ++f) {
      const aiFace& face = m->mFaces[f];
      if (face.mNumIndices != 3) continue;  // points and lines carry no surface
      for (int k = 0; k < 3; ++k) out.indices.push_back(base + face.mIndices[k]);
      if (has_uv)
        for (int k = 0; k < 3; ++k) {
          const aiVector3D& t = m->mTextureCoords[0][face.mIndices[k]];
          out.corner_uvs.insert(out.corner_uvs.end(), {t.x, t.y});
        }
    }
  }
  if (out.indices.empty()) throw std::invalid_argument("mesh '" + path + "' contains no triangles");
  // A file where only some meshes have uvs: drop them rather than misalign them.
  if (out.corner_uvs.size() != out.indices.size() * 2) out.corner_uvs.clear();
  return out;
}

void write_ply(const std::string& path, const std::vector<float>& positions, const std::vector<uint32_t>& indices) {
  std::ofstream f(path, std::ios::binary);
  if (!f) throw std::invalid_argument("cannot write '" + path + "'");
  f << "ply\nformat binary_little_endian 1.0\ncomment written by limn\n"
    << "element vertex " << positions.size() / 3 << "\nproperty float x\nproperty float y\nproperty float z\n"
    << "element face " << indices.size() / 3 << "\nproperty list uchar int vertex_indices\nend_header\n";
  f.write(reinterpret_cast<const char*>(positions.data()), std::streamsize(positions.size() * sizeof(float)));
  for (size_t t = 0; t < indices.size(); t += 3) {
    const uint8_t n = 3;
    f.write(reinterpret_cast<const char*>(&n), 1);
    const int32_t tri[3] = {int32_t(indices[t]), int32_t(indices[t + 1]), int32_t(indices[t + 2])};
    f.write(reinterpret_cast<const char*>(tri), sizeof(tri));
  }
  if (!f) throw std::invalid_argument("cannot write '" + path + "'");
}

}  // namespace limn
