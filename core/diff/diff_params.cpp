#include "core/diff/diff_params.h"

#include <algorithm>
#include <stdexcept>

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
                           p->kind == Parameter::Kind::SphereRadius;
    if (geometric) {
      m_geometry = true;
      if (std::find(m_moving_shapes.begin(), m_moving_shapes.end(), p->index) == m_moving_shapes.end())
        m_moving_shapes.push_back(p->index);
    }
  }
}

}  // namespace limn
