#include "core/io/scene/emitters.h"

#include "core/io/formats/files.h"
#include "core/io/formats/image_io.h"
#include "core/io/scene/shapes.h"

namespace limn::io_detail {

void load_emitter(Context& ctx, const json& j, const std::string& id) {
  const std::string type = type_of(j);
  Props p(ctx, j, describe("emitter", id, type));
  Emitter e;
  e.id = id;
  if (type == "point") {
    PointEmitter pe;
    pe.position = p.has("position") ? p.vec3("position", Vec3(0.0f)) : p.transform("to_world").point(Vec3(0.0f));
    for (int a = 0; a < 3; ++a)
      if (!(std::abs(pe.position[a]) <= kMaxCoordinate))
        p.fail(std::string(p.has("position") ? "'position'" : "'to_world' puts the light at") + " [" + number_text(pe.position.x) + ", " +
               number_text(pe.position.y) + ", " + number_text(pe.position.z) + "], beyond " + number_text(kMaxCoordinate) +
               ", the largest world coordinate limn traces rays at");
    pe.intensity = p.spectrum("intensity", Spectrum(1.0f));
    e.model = pe;
  } else if (type == "spot") {
    // Mitsuba's spot: at to_world's origin, pointing along its +z, angles in degrees.
    PointEmitter pe;
    const Transform t = p.transform("to_world");
    check_similarity(p, t);
    pe.position = t.point(Vec3(0.0f));
    pe.axis = glm::normalize(t.vector(Vec3(0, 0, 1)));
    pe.intensity = p.spectrum("intensity", Spectrum(1.0f));
    pe.spot = true;
    const float cutoff = p.number("cutoff_angle", 20.0f);
    const float beam = p.number("beam_width", 0.75f * cutoff);
    if (!(cutoff > 0.0f && cutoff < 180.0f)) p.fail("cutoff_angle must be in (0, 180) degrees (got " + std::to_string(cutoff) + ")");
    if (!(beam >= 0.0f && beam <= cutoff))
      p.fail("beam_width must be in [0, cutoff_angle = " + std::to_string(cutoff) + "] degrees (got " + std::to_string(beam) + ")");
    pe.cutoff = cutoff * kPi / 180.0f;
    pe.beam_width = beam * kPi / 180.0f;
    e.model = pe;
  } else if (type == "directional") {
    DirectionalEmitter de;
    const Vec3 d = p.has("direction") ? p.vec3("direction", Vec3(0, 0, 1)) : p.transform("to_world").vector(Vec3(0, 0, 1));
    if (!is_finite(d) || !(glm::length(d) > 0.0f) || !std::isfinite(glm::length(d)))
      p.fail(std::string(p.has("direction") ? "'direction'" : "the direction from 'to_world'") + " must be non-zero and its length a finite float (got [" +
             number_text(d.x) + ", " + number_text(d.y) + ", " + number_text(d.z) + "])");
    de.direction = glm::normalize(d);
    de.irradiance = p.spectrum("irradiance", Spectrum(1.0f));
    e.model = de;
  } else if (type == "constant") {
    e.model = ConstantEmitter{p.spectrum("radiance", Spectrum(1.0f))};
  } else if (type == "envmap") {
    EnvmapEmitter env;
    const std::string path = p.file("filename");
    try {
      env.image = std::make_shared<Bitmap>(read_image(path, false));
    } catch (const std::invalid_argument& err) {
      p.fail(std::string("'filename': ") + err.what());
    }
    env.world_from_env = p.transform("to_world");
    const double scale = check_similarity(p, env.world_from_env);  // a shear would break the 2 pi^2 sin(theta) Jacobian
    if (!(scale >= 1e-18 && scale <= 1e18)) p.fail("'to_world' scales by " + number_text(scale) + " (must be within [1e-18, 1e18])");
    env.scale = p.number("scale", 1.0f);
    if (!(env.scale >= 0.0f)) p.fail("scale must be >= 0 (got " + std::to_string(env.scale) + ")");
    e.model = std::move(env);
  } else if (type == "area") {
    p.fail("an 'area' emitter must be nested inside a shape");
  } else {
    p.fail("unknown emitter type '" + type + "' (known: " + known_of(Category::Emitter) + ")");
  }
  p.check_unused();
  ctx.scene->emitters.push_back(std::move(e));
}

}  // namespace limn::io_detail
