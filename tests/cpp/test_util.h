// Small helpers shared by the doctest files.
#pragma once
#include <cmath>
#include <sstream>
#include <string>
#include <variant>
#include "core/render/scene.h"

namespace limn::test {

// Shape i's geometry as kind G (the test knows which kind it built).
template <typename G>
G& geometry(std::vector<Shape>& shapes, size_t i) { return std::get<G>(shapes[i].geometry); }
template <typename G>
const G& geometry(const Scene& scene, size_t i) { return std::get<G>(scene.shapes[i].geometry); }

// A latitude-longitude sphere of radius r with bumps (projections have work to do), as the JSON
// of a flat-shaded "mesh" shape.
inline std::string bumpy_sphere_json(int nu, int nv, float r, float bump) {
  std::ostringstream v, f;
  v << "[";
  int count = 0;
  auto vertex = [&](float theta, float phi) {
    const float rr = r * (1.0f + bump * std::sin(5.0f * phi) * std::sin(3.0f * theta));
    v << (count++ ? "," : "") << "[" << rr * std::sin(theta) * std::cos(phi) << "," << rr * std::sin(theta) * std::sin(phi)
      << "," << rr * std::cos(theta) << "]";
  };
  vertex(0.0f, 0.0f);  // north pole: 0
  for (int i = 1; i < nv; ++i)
    for (int j = 0; j < nu; ++j) vertex(kPi * i / nv, 2.0f * kPi * j / nu);
  vertex(kPi, 0.0f);  // south pole: last
  v << "]";
  const int south = count - 1;
  auto ring = [&](int i, int j) { return 1 + (i - 1) * nu + (j % nu); };
  f << "[";
  bool first = true;
  auto tri = [&](int a, int b, int c) {
    f << (first ? "" : ",") << "[" << a << "," << b << "," << c << "]";
    first = false;
  };
  for (int j = 0; j < nu; ++j) tri(0, ring(1, j), ring(1, j + 1));
  for (int i = 1; i < nv - 1; ++i)
    for (int j = 0; j < nu; ++j) {
      tri(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1));
      tri(ring(i, j), ring(i + 1, j + 1), ring(i, j + 1));
    }
  for (int j = 0; j < nu; ++j) tri(south, ring(nv - 1, j + 1), ring(nv - 1, j));
  f << "]";
  return R"({"type": "mesh", "face_normals": true, "vertex_positions": )" + v.str() + R"(, "faces": )" + f.str() + "}";
}

}  // namespace limn::test
