#include "core/io/scene/shapes.h"

#include "core/io/scene/bsdfs.h"

namespace limn::io_detail {

// One line per scene-format type: its loader.
const std::map<std::string, ShapeLoader>& shape_kinds() {
  static const std::map<std::string, ShapeLoader> table = {
      {"obj", load_mesh_shape},     {"ply", load_mesh_shape},  {"mesh", load_mesh_shape},
      {"rectangle", load_mesh_shape}, {"cube", load_mesh_shape}, {"sphere", load_sphere},
      {"heightfield", load_heightfield}, {"bsplinecurve", load_bsplinecurve},
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
      p.fail("unknown type '" + ctype + "' under '" + key + "' (known: bsdfs " + known_of(Category::Bsdf) + "; emitter area; ref)");
    p.mark_used(key);
    if (cat->second == Category::Ref) {
      const std::string ref = str_field(*child, "id", "");
      auto it = ctx.named_bsdfs.find(ref);
      if (it == ctx.named_bsdfs.end()) p.fail("'" + key + "' refers to unknown bsdf '" + ref + "'");
      if (shape.bsdf >= 0) p.fail("has more than one bsdf");
      shape.bsdf = it->second;
    } else if (cat->second == Category::Bsdf) {
      if (shape.bsdf >= 0) p.fail("has more than one bsdf");
      shape.bsdf = add_bsdf(ctx, load_bsdf(ctx, *child, nested_id(p, *child, id)));
    } else if (cat->second == Category::Emitter) {
      if (ctype != "area") p.fail("only 'area' emitters can be attached to a shape (got '" + ctype + "' under '" + key + "')");
      if (!can_emit) p.fail("a " + type + " cannot be an area emitter (under '" + key + "')");
      if (shape.emitter >= 0) p.fail("has more than one emitter");
      Props ep(ctx, *child, describe("emitter", id, ctype));
      AreaEmitter a;
      a.shape = int(ctx.scene->shapes.size());
      a.radiance = ep.spectrum("radiance", Spectrum(1.0f));
      ep.check_unused();
      ctx.scene->emitters.push_back(Emitter{nested_id(p, *child, id), a});
      shape.emitter = int(ctx.scene->emitters.size() - 1);
    } else {
      p.fail("a '" + ctype + "' cannot be nested in a shape (under '" + key + "')");
    }
  }
  if (shape.bsdf < 0) shape.bsdf = add_bsdf(ctx, Bsdf{id, Diffuse{Texture{Spectrum(0.5f), nullptr}}, false});
  p.check_unused();
  ctx.scene->shapes.push_back(std::move(shape));
}

}  // namespace limn::io_detail
