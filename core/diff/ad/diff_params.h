// Which scene parameters are differentiable, and where each one's values live in the flat
// gradient / tangent vector used by render_forward and render_backward.
#pragma once
#include <string>
#include <unordered_map>
#include <vector>
#include "core/diff/ad/ad.h"
#include "core/render/scene.h"

namespace limn {

struct DiffParam {
  std::string name;
  Parameter::Kind kind;
  int index;        // shape, bsdf or emitter index
  size_t offset;    // first slot in the flat vector
  size_t size;      // number of floats
  std::vector<size_t> shape;
};

class DiffParams {
 public:
  DiffParams() = default;
  // Throws std::invalid_argument for unknown names.
  DiffParams(const Scene& scene, const std::vector<std::string>& names);

  const std::vector<DiffParam>& params() const { return m_params; }
  size_t slot_count() const { return m_slots; }
  bool empty() const { return m_params.empty(); }

  // First slot of a parameter of the given kind on object `index`, or -1 when not differentiable.
  long slot(Parameter::Kind kind, int index) const {
    auto it = m_lookup.find(key(kind, index));
    return it == m_lookup.end() ? -1 : long(it->second);
  }
  bool any_geometry() const { return m_geometry; }
  // Shapes whose geometry is differentiable (they alone can create visibility discontinuities).
  const std::vector<int>& moving_shapes() const { return m_moving_shapes; }
  // Whether any parameter moves the geometry of `shape`.
  bool moves(int shape) const { return shape >= 0 && size_t(shape) < m_moves.size() && m_moves[size_t(shape)]; }

 private:
  static long key(Parameter::Kind kind, int index) { return long(kind) * 1000003L + index; }
  std::vector<DiffParam> m_params;
  std::unordered_map<long, size_t> m_lookup;
  std::vector<int> m_moving_shapes;
  std::vector<char> m_moves;  // per shape
  size_t m_slots = 0;
  bool m_geometry = false;
};

// The inputs one path registered on the tape: tape node -> slot.
struct PathInputs {
  std::vector<std::pair<int32_t, size_t>> nodes;

  // A differentiable value: a tape input tied to `slot`, or a constant when slot < 0.
  ad::Var make(double value, long slot) {
    if (slot < 0) return ad::Var(value);
    ad::Var v = ad::Var::input(value);
    nodes.emplace_back(v.idx, size_t(slot));
    return v;
  }
  void clear() { nodes.clear(); }
};

}  // namespace limn
