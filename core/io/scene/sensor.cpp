#include "core/io/scene/sensor.h"

#include <cfloat>
#include <cstdint>
#include <limits>
#include "core/io/formats/files.h"
#include "core/io/scene/shapes.h"
#include "core/render/integrators/render.h"

namespace limn::io_detail {

void load_sensor(Context& ctx, const json& j, const std::string& id) {
  const std::string type = type_of(j);
  Props p(ctx, j, describe("sensor", id, type));
  if (type != "perspective") p.fail("unknown sensor type '" + type + "' (known: perspective)");
  Camera& cam = ctx.scene->camera;
  cam.width = 768;
  cam.height = 576;
  std::string film_key, sampler_key;
  for (const auto& [key, child] : p.children()) {
    const std::string ctype = type_of(*child);
    const std::string k = printable(key, 60);
    p.mark_used(key);
    if (ctype == "hdrfilm") {
      if (!film_key.empty()) p.fail("has two films ('" + film_key + "' and '" + k + "'); a sensor has one");
      film_key = k;
      Props fp(ctx, *child, describe("film", k, ctype));
      cam.width = fp.integer("width", 768);
      cam.height = fp.integer("height", 576);
      if (cam.width <= 0 || cam.height <= 0 || cam.width > 32768 || cam.height > 32768)
        fp.fail("width and height must be in [1, 32768] (got " + std::to_string(cam.width) + " x " + std::to_string(cam.height) + ")");
      if (uint64_t(cam.width) * uint64_t(cam.height) > kMaxFilmPixels)
        fp.fail("width x height must be at most " + std::to_string(kMaxFilmPixels) + " pixels (got " + std::to_string(cam.width) + " x " +
                std::to_string(cam.height) + ")");
      // Mitsuba's crop window: the image is the window; the fov still covers the whole film.
      if (fp.has("crop_offset_x") || fp.has("crop_offset_y") || fp.has("crop_width") || fp.has("crop_height")) {
        cam.full_width = cam.width;
        cam.full_height = cam.height;
        cam.crop_x = fp.integer("crop_offset_x", 0);
        cam.crop_y = fp.integer("crop_offset_y", 0);
        cam.width = fp.integer("crop_width", cam.full_width - cam.crop_x);
        cam.height = fp.integer("crop_height", cam.full_height - cam.crop_y);
        if (cam.crop_x < 0 || cam.crop_y < 0 || cam.width <= 0 || cam.height <= 0 || cam.crop_x + cam.width > cam.full_width ||
            cam.crop_y + cam.height > cam.full_height)
          fp.fail("the crop window (offset " + std::to_string(cam.crop_x) + ", " + std::to_string(cam.crop_y) + ", size " +
                  std::to_string(cam.width) + " x " + std::to_string(cam.height) + ") must lie inside the " +
                  std::to_string(cam.full_width) + " x " + std::to_string(cam.full_height) + " film");
      }
      for (const auto& [fk, fchild] : fp.children()) {
        fp.mark_used(fk);
        const std::string ft = type_of(*fchild);
        if (known_types().count(ft) == 0 || known_types().at(ft) != Category::Filter)
          fp.fail("a '" + printable(ft, 60) + "' cannot be nested in a film (under '" + printable(fk, 60) + "'; known filters: " + known_of(Category::Filter) + ")");
        Props rp(ctx, *fchild, describe("rfilter", fk, ft));
        if (ft == "box") {
          cam.filter = FilmFilter{};
        } else if (ft == "gaussian") {
          cam.filter.type = FilmFilter::Type::Gaussian;
          cam.filter.stddev = rp.number("stddev", 0.5f);
          // Bounds: a support below a pixel would leave pixels between samples; 16 px keeps splats small.
          if (!(cam.filter.stddev >= 0.25 && cam.filter.stddev <= 4.0))
            rp.fail("stddev must be in [0.25, 4] pixels (got " + std::to_string(cam.filter.stddev) + ")");
          cam.filter.radius = 4.0 * cam.filter.stddev;  // Mitsuba's cut-off
        } else {
          ctx.scene->warnings.push_back(ctx.source + ": film '" + k + "': reconstruction filter '" + printable(ft, 60) +
                                        "' is not supported (known: box, gaussian); limn uses box (uniform over each pixel)");
          continue;
        }
        rp.check_unused();
      }
      fp.mark_used("pixel_format");
      fp.mark_used("component_format");
      fp.check_unused();
    } else if (known_types().count(ctype) && known_types().at(ctype) == Category::Sampler) {
      if (!sampler_key.empty()) p.fail("has two samplers ('" + sampler_key + "' and '" + k + "'); a sensor has one");
      sampler_key = k;
      Props sp(ctx, *child, describe("sampler", k, ctype));
      // The same default as a sensor without a sampler (Scene::spp).
      ctx.scene->spp = sp.integer("sample_count", ctx.scene->spp);
      if (ctx.scene->spp <= 0 || ctx.scene->spp > kMaxSpp)
        sp.fail("sample_count must be in [1, " + std::to_string(kMaxSpp) + "] (got " + std::to_string(ctx.scene->spp) + ")");
      if (ctype != "independent") ctx.scene->warnings.push_back(ctx.source + ": sampler '" + k + "': '" + ctype + "' is rendered with independent samples");
      sp.mark_used("seed");
      sp.check_unused();
    } else {
      p.fail("a '" + printable(ctype, 60) + "' cannot be nested in a sensor (under '" + k + "')");
    }
  }
  cam.world_from_camera = p.transform("to_world");
  // Rays leave from the transformed origin along transformed directions, in float.
  const Mat4d& m = cam.world_from_camera.matrix();
  for (int a = 0; a < 3; ++a) {
    const double len = glm::length(Vec3d(m[a]));
    if (!(len >= 1e-18 && len <= 1e18))
      p.fail("'to_world' scales camera axis " + std::to_string(a) + " by " + number_text(len) + " (must be within [1e-18, 1e18])");
    if (!(std::abs(m[3][a]) <= kMaxCoordinate))
      p.fail("'to_world' puts the camera at coordinate " + number_text(m[3][a]) + ", beyond " + number_text(kMaxCoordinate) +
             ", the largest world coordinate limn traces rays at");
  }
  try {
    cam.set_fov(p.number("fov", 39.3077f), p.string("fov_axis", "x"));
  } catch (const std::invalid_argument& e) {
    p.fail(e.what());
  }
  cam.near_clip = p.number("near_clip", 1e-2f);
  cam.far_clip = p.number("far_clip", 1e4f);
  if (!(cam.near_clip > 0.0f && cam.far_clip > cam.near_clip))
    p.fail("need 0 < near_clip < far_clip (got near_clip " + number_text(cam.near_clip) + ", far_clip " + number_text(cam.far_clip) + ")");
  p.check_unused();
}

void load_integrator(Context& ctx, const json& j, const std::string& id) {
  const std::string type = type_of(j);
  Props p(ctx, j, describe("integrator", id, type));
  IntegratorSettings& s = ctx.scene->integrator;
  s.type = type;
  s.hide_emitters = p.boolean("hide_emitters", false);
  if (type == "path") {
    s.max_depth = p.integer("max_depth", -1);
    s.rr_depth = p.integer("rr_depth", 5);
    if (s.max_depth < -1) p.fail("max_depth must be -1 (unbounded) or >= 0 (got " + std::to_string(s.max_depth) + ")");
    if (s.rr_depth < 1) p.fail("rr_depth must be >= 1 (got " + std::to_string(s.rr_depth) + ")");
  } else if (type == "direct") {
    s.max_depth = 2;  // emitters seen directly plus one bounce
    s.rr_depth = std::numeric_limits<int>::max();
    const int ne = p.integer("emitter_samples", 1), nb = p.integer("bsdf_samples", 1);
    if (ne < 0 || ne > 1 || nb < 0 || nb > 1 || ne + nb == 0)
      p.fail("emitter_samples and bsdf_samples must each be 0 or 1, not both 0 (got " + std::to_string(ne) + ", " + std::to_string(nb) + ")");
    s.emitter_sampling = ne == 1;
    s.bsdf_sampling = nb == 1;
  } else {
    p.fail("unknown integrator type '" + type + "' (known: path, direct)");
  }
  p.check_unused();
}

}  // namespace limn::io_detail
