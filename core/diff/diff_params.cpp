#include "core/diff/diff_params.h"

#include <algorithm>
#include <stdexcept>
#include "core/heightfield/diff_heightfield.h"

namespace limn {

DiffParams::DiffParams(const Scene& scene, const std::vector<std::string>& names) {
  for (const std::string& name : names) {
    const Parameter* p = scene.find_parameter(name);
    if (!p) {
      std::string known;
      for (const Parameter& q : const_cast<Scene&>(scene).parameters()) known += (known.empty() ? "" : ", ") + q.name;
      throw std::invalid_argument(scene.source + ": unknown parameter '" + name + "' (parameters: " + known + ")");
    }
    if (m_lookup.count(key(p->kind, p->index))) continue;  // listed twice
    m_lookup[key(p->kind, p->index)] = m_slots;
    m_params.push_back({p->name, p->kind, p->index, m_slots, p->size(), p->shape});
    m_slots += p->size();
    const bool geometric = p->kind == Parameter::Kind::VertexPositions || p->kind == Parameter::Kind::SphereCenter ||
                           p->kind == Parameter::Kind::SphereRadius || p->kind == Parameter::Kind::Heights ||
                           p->kind == Parameter::Kind::Translation;
    if (geometric) {
      m_geometry = true;
      if (std::find(m_moving_shapes.begin(), m_moving_shapes.end(), p->index) == m_moving_shapes.end())
        m_moving_shapes.push_back(p->index);
    }
  }
}

namespace {
ad::V3<ad::Var> plus_translation(const DiffParams& params, PathInputs& in, int shape, ad::V3<ad::Var> p) {
  const long t = params.slot(Parameter::Kind::Translation, shape);
  if (t < 0) return p;
  // The stored geometry already includes the translation: the offset enters with value 0.
  return p + ad::V3<ad::Var>(in.make(0.0, t), in.make(0.0, t + 1), in.make(0.0, t + 2));
}
}  // namespace

ad::V3<ad::Var> diff_vertex(const Scene& scene, const DiffParams& params, PathInputs& in, int shape, uint32_t i) {
  const Mesh& m = scene.shapes[shape].mesh();
  const long slot = params.slot(Parameter::Kind::VertexPositions, shape);
  const float* p = &m.positions[3 * size_t(i)];
  const long base = slot < 0 ? -1 : slot + 3 * long(i);
  return plus_translation(params, in, shape, ad::V3<ad::Var>(in.make(p[0], base), in.make(p[1], base < 0 ? -1 : base + 1),
                                                             in.make(p[2], base < 0 ? -1 : base + 2)));
}

ad::V3<ad::Var> diff_sphere_center(const Scene& scene, const DiffParams& params, PathInputs& in, int shape) {
  const Sphere& s = scene.shapes[shape].sphere();
  const long cs = params.slot(Parameter::Kind::SphereCenter, shape);
  return plus_translation(params, in, shape, ad::V3<ad::Var>(in.make(s.center.x, cs), in.make(s.center.y, cs < 0 ? -1 : cs + 1),
                                                             in.make(s.center.z, cs < 0 ? -1 : cs + 2)));
}

ad::Var diff_sphere_radius(const Scene& scene, const DiffParams& params, PathInputs& in, int shape) {
  return in.make(scene.shapes[shape].sphere().radius, params.slot(Parameter::Kind::SphereRadius, shape));
}

ad::V3<ad::Var> diff_surface_point(const Scene& scene, const DiffParams& params, PathInputs& in, const SurfaceInteraction& si) {
  const Shape& sh = scene.shapes[si.shape];
  if (sh.is_heightfield()) {
    const DiffHeightfieldFrame F(scene, params, in, si.shape);
    const Heightfield& hf = sh.heightfield();
    const ad::Var x(hf.local_x(si.bary.x)), y(hf.local_y(si.bary.y));
    ad::Var z, zx, zy;
    F.height(in, x, y, z, zx, zy);
    return F.to_world_point(ad::V3<ad::Var>(x, y, z));
  }
  if (sh.is_sphere()) {
    const ad::V3<ad::Var> n(ad::Var(si.ng.x), ad::Var(si.ng.y), ad::Var(si.ng.z));
    return diff_sphere_center(scene, params, in, si.shape) + n * diff_sphere_radius(scene, params, in, si.shape);
  }
  const uint32_t* idx = &sh.mesh().indices[3 * size_t(si.prim)];
  const ad::Var b1(si.bary.x), b2(si.bary.y);
  return diff_vertex(scene, params, in, si.shape, idx[0]) * (ad::Var(1.0) - b1 - b2) +
         diff_vertex(scene, params, in, si.shape, idx[1]) * b1 + diff_vertex(scene, params, in, si.shape, idx[2]) * b2;
}

bool moves_geometry(const DiffParams& params, int shape) {
  for (Parameter::Kind k : {Parameter::Kind::VertexPositions, Parameter::Kind::SphereCenter, Parameter::Kind::SphereRadius,
                            Parameter::Kind::Heights, Parameter::Kind::Translation})
    if (params.slot(k, shape) >= 0) return true;
  return false;
}

}  // namespace limn
