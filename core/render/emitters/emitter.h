// The closed set of emitters. Radiance units: area and environment emitters are radiance
// (W m^-2 sr^-1), point lights intensity (W sr^-1), directional lights irradiance (W m^-2).
#pragma once
#include <memory>
#include <string>
#include <variant>
#include <vector>
#include "core/geometry/shapes/shape.h"
#include "core/geometry/transform.h"
#include "core/math/distribution.h"
#include "core/render/textures/texture.h"

namespace limn {

struct AreaEmitter {
  int shape = -1;            // emits from the front side of this shape
  Texture radiance{Spectrum(1.0f), nullptr};  // a constant or a bitmap over the shape's uv
};
// A point light, isotropic or (Mitsuba's `spot`) with a linear falloff around `axis`: full
// intensity within beam_width of the axis, falling linearly in angle to 0 at cutoff_angle.
struct PointEmitter {
  Vec3 position{0.0f};
  Spectrum intensity{1.0f};  // W/sr (a spot's on its axis)
  bool spot = false;
  Vec3 axis{0, 0, 1};        // unit; the spot's direction (to_world's +z)
  float cutoff = 0.0f, beam_width = 0.0f;  // radians, 0 <= beam_width <= cutoff < pi

  // Falloff in [0, 1] for the cosine between the axis and the direction from the light; on the
  // tape for T = ad::Var (continuous unless beam_width == cutoff, a hard edge).
  template <typename T>
  T falloff(const T& cos_theta) const {
    using std::acos;
    if (!spot || double(value_of(cos_theta)) >= std::cos(double(beam_width))) return T(1.0);
    if (!(double(value_of(cos_theta)) > std::cos(double(cutoff)))) return T(0.0);
    return (T(double(cutoff)) - acos(cos_theta)) * T(1.0 / (double(cutoff) - double(beam_width)));
  }
  // Intensity towards point x (W/sr).
  Spectrum intensity_towards(const Vec3& x) const {
    if (!spot) return intensity;
    const Vec3 d = x - position;
    const float len = glm::length(d);
    return len > 0.0f ? intensity * float(falloff(double(glm::dot(axis, d)) / double(len))) : Spectrum(0.0f);
  }
  // A hard edge: the cone's boundary is a discontinuity of the lighting.
  bool hard_edge() const { return spot && !(cutoff > beam_width); }

 private:
  static double value_of(double x) { return x; }
  template <typename T>
  static double value_of(const T& x) { return x.v; }
};
struct DirectionalEmitter {
  Vec3 direction{0, 0, -1};  // unit; the direction light travels in
  Spectrum irradiance{1.0f};
};
struct ConstantEmitter {
  Spectrum radiance{1.0f};
};
// Equirectangular environment map, Mitsuba's convention: in the map's own frame +y is up and
// (u, v) = (atan2(x, -z) / 2pi, acos(y) / pi). Looked up per texel (piecewise constant), which
// is exactly the density importance sampling draws from.
struct EnvmapEmitter {
  std::shared_ptr<Bitmap> image;
  Transform world_from_env;
  float scale = 1.0f;
  Distribution2D distribution;   // texel luminance * sin(theta)

  void build_distribution();
  Spectrum eval(const Vec3& d_world) const;
  float pdf_solid_angle(const Vec3& d_world) const;
  Vec3 sample(const Vec2& u, float* pdf_solid_angle) const;
};

using EmitterModel = std::variant<AreaEmitter, PointEmitter, DirectionalEmitter, ConstantEmitter, EnvmapEmitter>;

struct Emitter {
  std::string id;
  EmitterModel model;
  bool is_delta() const {
    return std::holds_alternative<PointEmitter>(model) || std::holds_alternative<DirectionalEmitter>(model);
  }
  bool is_infinite() const {
    return std::holds_alternative<ConstantEmitter>(model) || std::holds_alternative<EnvmapEmitter>(model) ||
           std::holds_alternative<DirectionalEmitter>(model);
  }
};

// A direction from a reference point towards an emitter.
struct EmitterSample {
  Vec3 wi;                  // unit direction from the reference point
  Vec3 p;                   // point on the emitter (finite emitters) for shadow rays
  bool to_infinity = false; // shadow ray is unbounded
  Spectrum radiance{0.0f};  // arriving radiance (delta lights: irradiance-like value, see below)
  float pdf = 0.0f;         // solid angle density of wi; 1 for delta emitters
  bool delta = false;
  PositionSample position;  // area emitters: the sampled point with its material coordinates
};

// Samples a direction towards emitter e from point x. For delta emitters `radiance` is the
// incident quantity that multiplies f |cos| directly (intensity / r^2, or irradiance).
EmitterSample sample_emitter(const Emitter& e, const std::vector<Shape>& shapes, const Vec3& x, const Vec2& u, float u_extra);
// Solid-angle density with which sample_emitter picks direction wi reaching point p_emitter on a
// shape (area emitters) or escaping (infinite emitters).
float pdf_emitter_area(const Emitter& e, const Shape& shape, const Vec3& x, const Vec3& p_emitter, const Vec3& n_emitter);
// Radiance towards -d of an infinite emitter seen along direction d.
Spectrum eval_infinite(const Emitter& e, const Vec3& d);
float pdf_infinite(const Emitter& e, const Vec3& d);

}  // namespace limn
