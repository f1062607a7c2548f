#include "core/io/scene/shapes.h"

#include <cmath>

#include "core/io/formats/files.h"
#include "core/io/scene/bsdfs.h"

namespace limn::io_detail {

// One line per scene-format type: its loader.
const std::map<std::string, ShapeLoader>& shape_kinds() {
  static const std::map<std::string, ShapeLoader> table = {
      {"obj", load_mesh_shape},     {"ply", load_mesh_shape},  {"mesh", load_mesh_shape},
      {"rectangle", load_mesh_shape}, {"cube", load_mesh_shape}, {"sphere", load_sphere},
      {"heightfield", load_heightfield}, {"disk", load_disk},
      {"sdfgrid", load_sdfgrid},
      {"bsplinecurve", load_bsplinecurve},
  };
  return table;
}

void load_shape(Context& ctx, const json& j, const std::string& id) {
  const std::string type = type_of(j);
  Props p(ctx, j, describe("shape", id, type));
  Shape shape;
  shape.id = id;
  shape.type = type;
  const Transform to_world = p.transform("to_world");
  auto kind = shape_kinds().find(type);
  if (kind == shape_kinds().end()) p.fail("unknown shape type '" + type + "' (known: " + known_of(Category::Shape) + ")");
  shape.geometry = kind->second(p, type, to_world);
  const bool can_emit = shape.visit([](const auto& g) { return std::decay_t<decltype(g)>::can_emit; });

  // Nested bsdf (inline or reference) and area emitter.
  for (const auto& [key, child] : p.children()) {
    const std::string ctype = type_of(*child);
    auto cat = known_types().find(ctype);
    if (cat == known_types().end())
      p.fail("unknown type '" + printable(ctype, 60) + "' under '" + printable(key, 60) + "' (known: bsdfs " + known_of(Category::Bsdf) + "; emitter area; ref)");
    p.mark_used(key);
    if (cat->second == Category::Ref) {
      Props rp(ctx, *child, describe("shape", id, type) + ": '" + printable(key, 60) + "' (ref)");
      if (!child->contains("id") || !child->at("id").is_string())
        rp.fail("needs \"id\": the name of a top-level bsdf (got " + (child->contains("id") ? brief(child->at("id")) : std::string("no id")) + ")");
      const std::string ref = child->at("id").get<std::string>();
      auto it = ctx.named_bsdfs.find(ref);
      if (it == ctx.named_bsdfs.end())
        p.fail("'" + printable(key, 60) + "' refers to unknown bsdf '" + printable(ref, 60) + "'" +
               (ctx.ids.count(ref) ? " ('" + ref + "' is not a top-level bsdf)" : std::string()));
      if (shape.bsdf >= 0) p.fail("has more than one bsdf (another under '" + printable(key, 60) + "')");
      rp.check_unused();
      shape.bsdf = it->second;
    } else if (cat->second == Category::Bsdf) {
      if (shape.bsdf >= 0) p.fail("has more than one bsdf (another under '" + printable(key, 60) + "')");
      shape.bsdf = add_bsdf(ctx, load_bsdf(ctx, *child, nested_id(p, *child, id)));
    } else if (cat->second == Category::Emitter) {
      if (ctype != "area") p.fail("only 'area' emitters can be attached to a shape (got '" + ctype + "' under '" + printable(key, 60) + "')");
      if (!can_emit) p.fail("a " + type + " cannot be an area emitter (under '" + printable(key, 60) + "')");
      if (shape.emitter >= 0) p.fail("has more than one emitter (another under '" + printable(key, 60) + "')");
      Props ep(ctx, *child, describe("emitter", id, ctype));
      AreaEmitter a;
      a.shape = int(ctx.scene->shapes.size());
      a.radiance = ep.texture("radiance", Spectrum(1.0f));
      if (const Bitmap* bm = a.radiance.bitmap.get())  // radiance is >= 0 (constants are checked by spectrum_value)
        for (size_t i = 0; i < bm->rgb.size(); ++i)
          if (!(std::isfinite(bm->rgb[i]) && bm->rgb[i] >= 0.0f))
            ep.fail("radiance bitmap '" + bm->source + "': texel (row " + std::to_string(i / 3 / bm->width) + ", column " +
                    std::to_string(i / 3 % bm->width) + ") channel " + std::to_string(i % 3) + " must be finite and >= 0 (got " +
                    std::to_string(bm->rgb[i]) + ")");
      ep.check_unused();
      ctx.scene->emitters.push_back(Emitter{nested_id(p, *child, id), a});
      shape.emitter = int(ctx.scene->emitters.size() - 1);
    } else {
      p.fail("a '" + ctype + "' cannot be nested in a shape (under '" + printable(key, 60) + "')");
    }
  }
  if (shape.bsdf < 0) shape.bsdf = add_bsdf(ctx, Bsdf{id, Diffuse{Texture{Spectrum(0.5f), nullptr}}, false});
  p.check_unused();
  ctx.scene->shapes.push_back(std::move(shape));
}

}  // namespace limn::io_detail
