// An editable scene parameter: a float view into scene memory, its kind, and whether it moves
// geometry. Shapes list their own parameters (the shape interface, core/geometry/shapes/shape.h); the
// scene adds materials and emitters (core/render/scene.cpp).
#pragma once
#include <sstream>
#include <string>
#include <vector>

namespace limn {

struct Parameter {
  // Shape kinds' parameters, then the shape-independent ones. Geometric kinds move a surface and
  // can change visibility: they alone take part in the boundary terms.
  enum class Kind { VertexPositions, VertexNormals, SphereCenter, SphereRadius, DiskRadius, Heights, SdfData, CurveControlPoints, Translation, Reflectance, Alpha, EmitterValue };
  std::string name;            // "<owner id>.<field>"
  Kind kind;
  int index;                   // shape, bsdf or emitter index
  float* data;
  std::vector<size_t> shape;   // numpy-style shape; empty for a scalar
  bool geometric = false;      // moves a shape's surface (set by the shape that lists it)
  size_t size() const {
    size_t n = 1;
    for (size_t s : shape) n *= s;
    return n;
  }
};

// "[v0, v1, ...]" for error messages.
inline std::string format_values(const float* v, size_t n) {
  std::ostringstream s;
  s << "[";
  for (size_t i = 0; i < n; ++i) s << (i ? ", " : "") << v[i];
  s << "]";
  return s.str();
}

}  // namespace limn
