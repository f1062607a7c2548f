// What the libFuzzer targets share: a private scratch folder (in /dev/shm when there is one) for the
// files the readers open, with a few small valid files next to them that scene inputs can name.
//
// The contract every target checks: a reader given any bytes either returns data that satisfies its
// invariants or throws std::invalid_argument. Any other exception escapes and libFuzzer reports it
// ("uncaught exception"), like a crash, a hang (-timeout) or a sanitizer report.
#pragma once
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>
#include "core/io/formats/image_io.h"
#include "core/io/formats/mesh_io.h"

namespace limn_fuzz {

namespace fs = std::filesystem;

inline const fs::path& scratch() {
  static const fs::path dir = [] {
    const std::string base = fs::is_directory("/dev/shm") ? "/dev/shm" : fs::temp_directory_path().string();
    std::string tmpl = base + "/limn-fuzz-XXXXXX";
    if (!mkdtemp(tmpl.data())) std::abort();
    std::atexit([] { std::error_code ec; fs::remove_all(scratch(), ec); });
    return fs::path(tmpl);
  }();
  return dir;
}

inline std::string write_file(const std::string& name, const uint8_t* data, size_t size) {
  const fs::path p = scratch() / name;
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f.write(reinterpret_cast<const char*>(data), std::streamsize(size));
  if (!f) std::abort();
  return p.string();
}

// Valid files that fuzzed scenes may name: mesh.ply, mesh.obj, tex.png, env.exr, height.png.
inline void write_valid_files() {
  const std::vector<float> v = {-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0};
  const std::vector<uint32_t> f = {0, 1, 2, 0, 2, 3};
  limn::write_ply((scratch() / "mesh.ply").string(), v, f);
  std::ofstream((scratch() / "mesh.obj").string()) << "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n";
  limn::Image img{4, 4, std::vector<float>(48)};
  for (size_t i = 0; i < img.rgb.size(); ++i) img.rgb[i] = float(i % 7) / 7.0f;
  limn::write_image((scratch() / "tex.png").string(), img);
  limn::write_image((scratch() / "env.exr").string(), img);
  limn::write_image((scratch() / "height.png").string(), img);
}

[[noreturn]] inline void invariant_broken(const char* what) {
  std::fprintf(stderr, "invariant broken: %s\n", what);
  std::abort();
}

// What a reader's MeshData must satisfy whenever it returns.
inline void check_mesh(const limn::MeshData& m) {
  if (m.positions.size() % 3 != 0 || m.indices.size() % 3 != 0 || m.indices.empty()) invariant_broken("buffer sizes");
  for (uint32_t i : m.indices)
    if (i >= m.positions.size() / 3) invariant_broken("index out of range");
  for (float x : m.positions)
    if (!std::isfinite(x)) invariant_broken("non-finite position");
  if (!m.corner_uvs.empty() && m.corner_uvs.size() != m.indices.size() * 2) invariant_broken("corner_uvs size");
  for (float x : m.corner_uvs)
    if (!std::isfinite(x)) invariant_broken("non-finite uv");
}

}  // namespace limn_fuzz
