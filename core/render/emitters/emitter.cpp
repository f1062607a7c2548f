#include "core/render/emitters/emitter.h"

#include "core/math/warp.h"

namespace limn {

// ---- environment map --------------------------------------------------------------------------
namespace {
Vec3 env_direction(const Vec2& uv) {
  const float phi = uv.x * 2.0f * kPi, theta = uv.y * kPi;
  const float st = std::sin(theta);
  return Vec3(std::sin(phi) * st, std::cos(theta), -std::cos(phi) * st);
}
Vec2 env_uv(const Vec3& d) {
  float u = std::atan2(d.x, -d.z) * kInvTwoPi;
  if (u < 0.0f) u += 1.0f;
  return Vec2(u, safe_acos(d.y) * kInvPi);
}
}  // namespace

void EnvmapEmitter::build_distribution() {
  const int w = image->width, h = image->height;
  std::vector<float> weights(size_t(w) * h);
  for (int y = 0; y < h; ++y) {
    const float sin_theta = std::sin((y + 0.5f) / h * kPi);
    for (int x = 0; x < w; ++x) weights[size_t(y) * w + x] = std::max(0.0f, luminance(image->texel(x, y))) * sin_theta;
  }
  distribution = Distribution2D(weights, w, h);
}

Spectrum EnvmapEmitter::eval(const Vec3& d_world) const {
  const Vec2 uv = env_uv(glm::normalize(world_from_env.inverse().vector(d_world)));
  if (!(uv.x >= 0.0f && uv.x <= 1.0f && uv.y >= 0.0f && uv.y <= 1.0f)) return Spectrum(0.0f);  // NaN: a direction that is not one
  const int x = std::min(int(uv.x * image->width), image->width - 1);
  const int y = std::min(int(uv.y * image->height), image->height - 1);
  return scale * image->texel(x, y);
}

float EnvmapEmitter::pdf_solid_angle(const Vec3& d_world) const {
  const Vec3 d = glm::normalize(world_from_env.inverse().vector(d_world));
  const Vec2 uv = env_uv(d);
  const float sin_exact = safe_sqrt(1.0f - d.y * d.y);
  if (sin_exact <= 0.0f) return 0.0f;
  // Change of variables: d omega = 2 pi^2 sin(theta) du dv.
  return distribution.pdf(uv) / (2.0f * kPi * kPi * sin_exact);
}

Vec3 EnvmapEmitter::sample(const Vec2& u, float* pdf) const {
  float pdf_uv = 0.0f;
  const Vec2 uv = distribution.sample(u, &pdf_uv);
  const Vec3 d_local = env_direction(uv);
  const float sin_theta = std::sin(uv.y * kPi);
  *pdf = sin_theta > 0.0f ? pdf_uv / (2.0f * kPi * kPi * sin_theta) : 0.0f;
  return glm::normalize(world_from_env.vector(d_local));
}

// ---- dispatch ---------------------------------------------------------------------------------
EmitterSample sample_emitter(const Emitter& e, const std::vector<Shape>& shapes, const Vec3& x, const Vec2& u, float u_extra) {
  EmitterSample s;
  std::visit([&](const auto& m) {
    using T = std::decay_t<decltype(m)>;
    if constexpr (std::is_same_v<T, AreaEmitter>) {
      const Shape& shape = shapes[m.shape];
      const PositionSample ps = shape.sample_position(u, u_extra);
      Vec3 d = ps.p - x;
      const float dist2 = glm::dot(d, d);
      if (!(dist2 > 0.0f)) return;
      const float dist = std::sqrt(dist2);
      d /= dist;
      const float cos_light = -glm::dot(ps.n, d);
      if (cos_light <= 0.0f) return;  // one-sided emission: the back does not emit
      s.wi = d;
      s.p = ps.p;
      s.position = ps;
      s.pdf = ps.pdf_area * dist2 / cos_light;
      s.radiance = m.radiance;
    } else if constexpr (std::is_same_v<T, PointEmitter>) {
      Vec3 d = m.position - x;
      const float dist2 = glm::dot(d, d);
      if (!(dist2 > 0.0f)) return;
      s.wi = d / std::sqrt(dist2);
      s.p = m.position;
      s.pdf = 1.0f;
      s.delta = true;
      s.radiance = m.intensity / dist2;
    } else if constexpr (std::is_same_v<T, DirectionalEmitter>) {
      s.wi = -m.direction;
      s.to_infinity = true;
      s.pdf = 1.0f;
      s.delta = true;
      s.radiance = m.irradiance;
    } else if constexpr (std::is_same_v<T, ConstantEmitter>) {
      s.wi = warp::square_to_uniform_sphere(u);
      s.to_infinity = true;
      s.pdf = warp::square_to_uniform_sphere_pdf();
      s.radiance = m.radiance;
    } else if constexpr (std::is_same_v<T, EnvmapEmitter>) {
      float pdf = 0.0f;
      s.wi = m.sample(u, &pdf);
      // Density and radiance from the same texel lookup of wi (rounding can move a sample that sat
      // on a texel edge into the neighbour; pdf and value must then both be the neighbour's).
      s.pdf = m.pdf_solid_angle(s.wi);
      if (!(pdf > 0.0f) || !(s.pdf > 0.0f)) return;
      s.to_infinity = true;
      s.radiance = m.eval(s.wi);
    }
  }, e.model);
  return s;
}

float pdf_emitter_area(const Emitter& e, const Shape& shape, const Vec3& x, const Vec3& p_emitter, const Vec3& n_emitter) {
  const Vec3 d = p_emitter - x;
  const float dist2 = glm::dot(d, d);
  const float cos_light = std::abs(glm::dot(n_emitter, d)) / std::sqrt(dist2);
  const float area = shape.surface_area();
  if (!(cos_light > 0.0f) || !(area > 0.0f)) return 0.0f;
  return dist2 / (cos_light * area);
}

Spectrum eval_infinite(const Emitter& e, const Vec3& d) {
  if (auto* c = std::get_if<ConstantEmitter>(&e.model)) return c->radiance;
  if (auto* m = std::get_if<EnvmapEmitter>(&e.model)) return m->eval(d);
  return Spectrum(0.0f);
}

float pdf_infinite(const Emitter& e, const Vec3& d) {
  if (std::holds_alternative<ConstantEmitter>(e.model)) return warp::square_to_uniform_sphere_pdf();
  if (auto* m = std::get_if<EnvmapEmitter>(&e.model)) return m->pdf_solid_angle(d);
  return 0.0f;
}

}  // namespace limn
