#include "core/render/scene.h"

#include <cstring>
#include <mutex>
#include <sstream>
#include <stdexcept>

namespace limn {

void Scene::build() {
  infinite_emitters.clear();
  for (size_t i = 0; i < emitters.size(); ++i) {
    if (auto* env = std::get_if<EnvmapEmitter>(&emitters[i].model)) env->build_distribution();
    if (std::holds_alternative<ConstantEmitter>(emitters[i].model) || std::holds_alternative<EnvmapEmitter>(emitters[i].model))
      infinite_emitters.push_back(int(i));
  }
  for (Shape& s : shapes) s.visit([](auto& g) { g.build_derived(); });
  m_accel = std::make_unique<Accel>(shapes);
  collect_parameters();
  m_snapshots.clear();
  for (const Parameter& p : m_params) m_snapshots.emplace_back(p.data, p.data + p.size());
}

void Scene::collect_parameters() {
  m_params.clear();
  for (size_t i = 0; i < shapes.size(); ++i) {
    Shape& s = shapes[i];
    s.visit([&](auto& g) { g.list_parameters(s.id, int(i), m_params); });
    m_params.push_back({s.id + ".to_world.translation", Parameter::Kind::Translation, int(i), &s.translation.x, {3}, true});
  }
  for (size_t i = 0; i < bsdfs.size(); ++i) {
    Bsdf& b = bsdfs[i];
    if (auto* d = std::get_if<Diffuse>(&b.model)) {
      if (d->reflectance.bitmap) {
        Bitmap& bm = *d->reflectance.bitmap;
        m_params.push_back({b.id + ".reflectance", Parameter::Kind::Reflectance, int(i), bm.rgb.data(), {size_t(bm.height), size_t(bm.width), 3}});
      } else {
        m_params.push_back({b.id + ".reflectance", Parameter::Kind::Reflectance, int(i), &d->reflectance.value.x, {3}});
      }
    } else if (auto* rc = std::get_if<RoughConductor>(&b.model)) {
      m_params.push_back({b.id + ".alpha", Parameter::Kind::Alpha, int(i), &rc->distribution.alpha, {}});
    } else if (auto* rd = std::get_if<RoughDielectric>(&b.model)) {
      m_params.push_back({b.id + ".alpha", Parameter::Kind::Alpha, int(i), &rd->distribution.alpha, {}});
    }
  }
  for (size_t i = 0; i < emitters.size(); ++i) {
    Emitter& e = emitters[i];
    auto add = [&](const char* field, Spectrum& v) {
      m_params.push_back({e.id + "." + field, Parameter::Kind::EmitterValue, int(i), &v.x, {3}});
    };
    std::visit([&](auto& m) {
      using T = std::decay_t<decltype(m)>;
      if constexpr (std::is_same_v<T, AreaEmitter> || std::is_same_v<T, ConstantEmitter>) add("radiance", m.radiance);
      else if constexpr (std::is_same_v<T, PointEmitter>) add("intensity", m.intensity);
      else if constexpr (std::is_same_v<T, DirectionalEmitter>) add("irradiance", m.irradiance);
    }, e.model);
  }
}

const Parameter* Scene::find_parameter(const std::string& name) const {
  for (const Parameter& p : m_params)
    if (p.name == name) return &p;
  return nullptr;
}

void Scene::validate_parameter(const Parameter& p) const {
  const std::string where = source + ": parameter '" + p.name + "'";
  const size_t n = p.size();
  if (p.geometric && p.kind != Parameter::Kind::Translation) {  // the shape's own parameters
    shapes[p.index].visit([&](const auto& g) { g.validate_parameter(p, where); });
    return;
  }
  switch (p.kind) {
    case Parameter::Kind::Translation:
      for (size_t i = 0; i < n; i += 3)
        if (!std::isfinite(p.data[i]) || !std::isfinite(p.data[i + 1]) || !std::isfinite(p.data[i + 2]))
          throw std::invalid_argument(where + ": vertex " + std::to_string(i / 3) + " is not finite (" + format_values(p.data + i, 3) + ")");
      break;
    case Parameter::Kind::Alpha:
      if (!(std::isfinite(p.data[0]) && p.data[0] > 0.0f))
        throw std::invalid_argument(where + ": must be finite and > 0 (got " + std::to_string(p.data[0]) + ")");
      break;
    case Parameter::Kind::Reflectance:
    case Parameter::Kind::EmitterValue:
      for (size_t i = 0; i < n; ++i)
        if (!(std::isfinite(p.data[i]) && p.data[i] >= 0.0f))
          throw std::invalid_argument(where + ": entry " + std::to_string(i) + " must be finite and >= 0 (got " + std::to_string(p.data[i]) + ")");
      break;
    default:  // a shape kind's own parameters, validated by the shape above
      break;
  }
}

void Scene::validate_translation(size_t i) const {
  // The shape moves by the change of its translation: its bounds must stay finite.
  const Parameter& p = m_params[i];
  const Vec3 delta = Vec3(p.data[0], p.data[1], p.data[2]) - Vec3(m_snapshots[i][0], m_snapshots[i][1], m_snapshots[i][2]);
  Vec3 lo, hi;
  shapes[p.index].visit([&](const auto& g) { g.bounds(lo, hi); });
  const Vec3 reach = glm::max(glm::abs(lo + delta), glm::abs(hi + delta));
  if (lo.x <= hi.x && !(is_finite(reach) && max_component(reach) <= kMaxCoordinate))
    throw std::invalid_argument(source + ": parameter '" + p.name + "': moves shape '" + shapes[p.index].id + "' (bounds " +
                                format_values(&lo.x, 3) + " to " + format_values(&hi.x, 3) + ") by " + format_values(&delta.x, 3) +
                                ", beyond the traceable range (|coordinate| <= 1e18)");
}

void Scene::apply_parameter(const Parameter& p) {
  // Translation is applied in update(), which knows the previous value; materials and emitters
  // are read directly by the renderer and have nothing derived.
  if (!p.geometric || p.kind == Parameter::Kind::Translation) return;
  shapes[p.index].visit([&](auto& g) { g.apply_parameter(p); });
  m_accel->shape_changed(p.index);
}

std::vector<std::string> Scene::update() {
  std::vector<size_t> changed;
  for (size_t i = 0; i < m_params.size(); ++i)
    if (std::memcmp(m_params[i].data, m_snapshots[i].data(), m_snapshots[i].size() * sizeof(float)) != 0) changed.push_back(i);
  if (changed.empty()) return {};
  std::unique_lock<std::shared_mutex> lock(m_mutex, std::try_to_lock);
  if (!lock.owns_lock())
    throw std::runtime_error(source + ": update(): parameters changed while a render of this scene is running; "
                             "edit parameters only between renders");
  // Validate everything first, so a bad value leaves the whole scene as it was.
  for (size_t i : changed) {
    try {
      validate_parameter(m_params[i]);
      if (m_params[i].kind == Parameter::Kind::Translation) validate_translation(i);
    } catch (...) {
      for (size_t j : changed) std::memcpy(m_params[j].data, m_snapshots[j].data(), m_snapshots[j].size() * sizeof(float));
      throw;
    }
  }
  bool geometry = false;
  std::vector<std::string> names;
  for (size_t i : changed) {
    if (m_params[i].kind == Parameter::Kind::Translation) {
      // Move the geometry by the change of the translation; its own parameters (positions, centre)
      // then hold the moved values, and their snapshots follow so the move is not seen twice.
      const Parameter& p = m_params[i];
      const Vec3 delta = Vec3(p.data[0], p.data[1], p.data[2]) - Vec3(m_snapshots[i][0], m_snapshots[i][1], m_snapshots[i][2]);
      shapes[p.index].visit([&](auto& g) { g.translate(delta); });
      m_accel->shape_changed(p.index);
      for (size_t j = 0; j < m_params.size(); ++j)
        if (m_params[j].geometric && m_params[j].kind != Parameter::Kind::Translation && m_params[j].index == p.index) {
          apply_parameter(m_params[j]);
          std::memcpy(m_snapshots[j].data(), m_params[j].data, m_snapshots[j].size() * sizeof(float));
        }
      geometry = true;
    }
    apply_parameter(m_params[i]);
    std::memcpy(m_snapshots[i].data(), m_params[i].data, m_snapshots[i].size() * sizeof(float));
    geometry |= m_params[i].geometric;
    names.push_back(m_params[i].name);
  }
  if (geometry) m_accel->commit();
  return names;
}

}  // namespace limn
