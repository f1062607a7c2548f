#include "core/diff/ad/diff_params.h"

#include <algorithm>
#include <stdexcept>

namespace limn {

DiffParams::DiffParams(const Scene& scene, const std::vector<std::string>& names) : m_moves(scene.shapes.size(), 0) {
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
    if (p->geometric) {
      m_geometry = true;
      if (!m_moves[size_t(p->index)]) m_moving_shapes.push_back(p->index);
      m_moves[size_t(p->index)] = 1;
    }
  }
}

}  // namespace limn
