#include "core/io/scene_loader.h"

#include <fstream>
#include <limits>
#include <sstream>
#include "core/io/image_io.h"
#include "core/io/mesh_io.h"
#include "core/io/scene/bsdfs.h"
#include "core/io/scene/props.h"

namespace limn {

using namespace io_detail;

namespace {

// ---- shapes ---------------------------------------------------------------------------------------
Mesh build_mesh(const Props& p, MeshData data, const Transform& to_world, bool face_normals) {
  if (data.indices.size() % 3 != 0 || data.positions.size() % 3 != 0) p.fail("mesh buffers are not triangles of 3D points");
  const size_t nv = data.positions.size() / 3;
  for (size_t v = 0; v < nv; ++v)
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(data.positions[3 * v + c])) {
        std::ostringstream s;
        s << "vertex " << v << " is not finite ([" << data.positions[3 * v] << ", " << data.positions[3 * v + 1] << ", "
          << data.positions[3 * v + 2] << "])";
        p.fail(s.str());
      }
  for (size_t i = 0; i < data.indices.size(); ++i)
    if (data.indices[i] >= nv)
      p.fail("triangle " + std::to_string(i / 3) + " refers to vertex " + std::to_string(data.indices[i]) + " but there are only " +
             std::to_string(nv) + " vertices");
  Mesh m;
  m.face_normals = face_normals;
  m.indices = weld_by_position(data.positions, data.indices, m.positions);
  m.corner_uvs = std::move(data.corner_uvs);
  for (size_t v = 0; v < m.positions.size(); v += 3) {
    const Vec3 q = to_world.point(Vec3(m.positions[v], m.positions[v + 1], m.positions[v + 2]));
    if (!is_finite(q)) p.fail("vertex " + std::to_string(v / 3) + " is not finite after applying to_world");
    m.positions[v] = q.x; m.positions[v + 1] = q.y; m.positions[v + 2] = q.z;
  }
  // A mirroring transform reverses the winding; swap two corners so normals keep pointing outwards.
  if (glm::determinant(to_world.matrix()) < 0.0)
    for (size_t t = 0; t < m.indices.size(); t += 3) {
      std::swap(m.indices[t + 1], m.indices[t + 2]);
      if (!m.corner_uvs.empty())
        for (int c = 0; c < 2; ++c) std::swap(m.corner_uvs[2 * (t + 1) + c], m.corner_uvs[2 * (t + 2) + c]);
    }

  // Degenerate triangles (zero area or repeated vertices after welding): an error unless allowed.
  const bool allow = p.boolean("allow_degenerate", false);
  std::vector<uint32_t> kept;
  std::vector<float> kept_uv;
  size_t dropped = 0, first_bad = 0;
  for (size_t t = 0; t < m.indices.size() / 3; ++t) {
    const uint32_t a = m.indices[3 * t], b = m.indices[3 * t + 1], c = m.indices[3 * t + 2];
    const float area = glm::length(glm::cross(m.vertex(b) - m.vertex(a), m.vertex(c) - m.vertex(a)));
    if (a == b || b == c || a == c || !(area > 0.0f)) {
      if (!allow) {
        std::ostringstream s;
        s << "triangle " << t << " is degenerate (vertices " << a << ", " << b << ", " << c
          << " enclose zero area); fix the mesh or set \"allow_degenerate\": true to drop such triangles";
        p.fail(s.str());
      }
      if (dropped++ == 0) first_bad = t;
      continue;
    }
    kept.insert(kept.end(), {a, b, c});
    if (!m.corner_uvs.empty()) kept_uv.insert(kept_uv.end(), m.corner_uvs.begin() + 6 * t, m.corner_uvs.begin() + 6 * t + 6);
  }
  if (dropped) {
    p.ctx().scene->warnings.push_back(p.ctx().source + ": " + p.what() + ": dropped " + std::to_string(dropped) +
                                      " degenerate triangle(s), the first is triangle " + std::to_string(first_bad));
    m.indices = std::move(kept);
    m.corner_uvs = std::move(kept_uv);
  }
  if (m.indices.empty()) p.fail("mesh has no triangles");
  return m;
}

MeshData mesh_from_arrays(const Props& p) {
  MeshData d;
  const ArrayData v = p.array("vertex_positions");
  if (v.shape.size() != 2 || v.shape[1] != 3) p.fail("'vertex_positions' must have shape (N, 3)");
  d.positions.assign(v.values.begin(), v.values.end());
  const ArrayData f = p.array("faces");
  if (f.shape.size() != 2 || f.shape[1] != 3) p.fail("'faces' must have shape (F, 3)");
  if (!f.integer) p.fail("'faces' must hold integers");
  for (double x : f.values) {
    if (x < 0 || x > 4294967295.0) p.fail("'faces' has an index out of range (" + std::to_string(x) + ")");
    d.indices.push_back(uint32_t(x));
  }
  if (p.has("corner_uvs")) {
    const ArrayData uv = p.array("corner_uvs");
    if (uv.values.size() != d.indices.size() * 2) p.fail("'corner_uvs' must have shape (F, 3, 2)");
    d.corner_uvs.assign(uv.values.begin(), uv.values.end());
  }
  return d;
}

MeshData rectangle_data() {
  return MeshData{{-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0}, {0, 1, 2, 0, 2, 3}, {0, 0, 1, 0, 1, 1, 0, 0, 1, 1, 0, 1}};
}

MeshData cube_data() {
  MeshData d;
  for (int axis = 0; axis < 3; ++axis)
    for (float sign : {-1.0f, 1.0f}) {
      const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
      const uint32_t base = uint32_t(d.positions.size() / 3);
      const float corners[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
      for (const auto& c : corners) {
        float p[3];
        p[axis] = sign;
        p[a1] = c[0];
        p[a2] = c[1];
        d.positions.insert(d.positions.end(), {p[0], p[1], p[2]});
      }
      // (a1, a2, axis) is right-handed, so counter-clockwise in (a1, a2) faces +axis.
      if (sign > 0) d.indices.insert(d.indices.end(), {base, base + 1, base + 2, base, base + 2, base + 3});
      else d.indices.insert(d.indices.end(), {base, base + 2, base + 1, base, base + 3, base + 2});
      const float uv_pos[12] = {0, 0, 1, 0, 1, 1, 0, 0, 1, 1, 0, 1}, uv_neg[12] = {0, 0, 1, 1, 1, 0, 0, 0, 0, 1, 1, 1};
      d.corner_uvs.insert(d.corner_uvs.end(), sign > 0 ? uv_pos : uv_neg, (sign > 0 ? uv_pos : uv_neg) + 12);
    }
  return d;
}

// Heights from "filename" (any OpenImageIO format, first channel, no sRGB decoding) or "data" (a 2D
// array, row 0 at the far edge y = +depth/2 as in an image), scaled by "height_scale".
Heightfield load_heightfield(const Props& p, const Transform& to_world) {
  Heightfield hf;
  if (p.has("filename") == p.has("data")) p.fail("needs exactly one of 'filename' (an image) or 'data' (a 2D array of heights)");
  if (p.has("filename")) {
    const std::string path = p.file("filename");
    Bitmap bm;
    try {
      bm = read_image(path, true);
    } catch (const std::invalid_argument& e) {
      p.fail(e.what());
    }
    hf.nx = bm.width;
    hf.ny = bm.height;
    hf.heights.resize(size_t(bm.width) * bm.height);
    for (size_t i = 0; i < hf.heights.size(); ++i) hf.heights[i] = bm.rgb[3 * i];
  } else {
    const ArrayData a = p.array("data");
    if (a.shape.size() != 2) p.fail("'data' must be a 2D array (rows, columns) of heights");
    hf.ny = int(a.shape[0]);
    hf.nx = int(a.shape[1]);
    hf.heights.assign(a.values.begin(), a.values.end());
  }
  if (hf.nx < 2 || hf.ny < 2)
    p.fail("needs at least 2 x 2 heights (got " + std::to_string(hf.ny) + " rows x " + std::to_string(hf.nx) + " columns)");
  for (size_t i = 0; i < hf.heights.size(); ++i)
    if (!std::isfinite(hf.heights[i]))
      p.fail("height at row " + std::to_string(i / hf.nx) + ", column " + std::to_string(i % hf.nx) + " is not finite");
  Vec2 size(2.0f);
  if (p.has("size")) {
    const std::vector<double> v = p.numbers(p.raw("size"), "size", 2);
    size = Vec2(float(v[0]), float(v[1]));
  }
  hf.width = size.x;
  hf.depth = size.y;
  if (!(hf.width > 0.0f && hf.depth > 0.0f && std::isfinite(hf.width) && std::isfinite(hf.depth)))
    p.fail("size must be two positive numbers [width, depth] (got [" + std::to_string(hf.width) + ", " + std::to_string(hf.depth) + "])");
  hf.height_scale = p.number("height_scale", 1.0f);
  if (!(hf.height_scale > 0.0f && std::isfinite(hf.height_scale)))
    p.fail("height_scale must be finite and > 0 (got " + std::to_string(hf.height_scale) + ")");
  check_similarity(p, to_world, hf.scale);
  hf.world_from_local = to_world;
  return hf;
}

void load_shape(Context& ctx, const json& j, const std::string& id) {
  const std::string type = type_of(j);
  Props p(ctx, j, describe("shape", id, type));
  Shape shape;
  shape.id = id;
  shape.type = type;
  const Transform to_world = p.transform("to_world");
  if (type == "sphere") {
    Sphere s;
    s.center = p.vec3("center", Vec3(0.0f));
    s.radius = p.number("radius", 1.0f);
    if (!(s.radius > 0.0f)) p.fail("radius must be > 0 (got " + std::to_string(s.radius) + ")");
    if (p.has("to_world")) {
      float scale;
      check_similarity(p, to_world, scale);
      s.center = to_world.point(s.center);
      s.radius *= scale;
    }
    shape.geometry = s;
  } else if (type == "heightfield") {
    shape.geometry = load_heightfield(p, to_world);
  } else {
    MeshData data;
    bool face_normals = p.boolean("face_normals", type == "rectangle" || type == "cube");
    if (type == "obj" || type == "ply") {
      const std::string path = p.file("filename");
      try {
        data = read_mesh_file(path);
      } catch (const std::invalid_argument& e) {
        p.fail(e.what());
      }
    } else if (type == "mesh") {
      data = mesh_from_arrays(p);
    } else if (type == "rectangle") {
      data = rectangle_data();
    } else if (type == "cube") {
      data = cube_data();
    } else {
      p.fail("unknown shape type '" + type + "' (known: " + known_of(Category::Shape) + ")");
    }
    if (p.boolean("flip_normals", false))
      for (size_t t = 0; t < data.indices.size(); t += 3) {
        std::swap(data.indices[t + 1], data.indices[t + 2]);
        if (!data.corner_uvs.empty())
          for (int c = 0; c < 2; ++c) std::swap(data.corner_uvs[2 * (t + 1) + c], data.corner_uvs[2 * (t + 2) + c]);
      }
    shape.geometry = build_mesh(p, std::move(data), to_world, face_normals);
  }

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
      if (type == "heightfield") p.fail("a heightfield cannot be an area emitter (under '" + key + "')");
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

// ---- emitters, sensor, integrator -------------------------------------------------------------------
void load_emitter(Context& ctx, const json& j, const std::string& id) {
  const std::string type = type_of(j);
  Props p(ctx, j, describe("emitter", id, type));
  Emitter e;
  e.id = id;
  if (type == "point") {
    PointEmitter pe;
    pe.position = p.has("position") ? p.vec3("position", Vec3(0.0f)) : p.transform("to_world").point(Vec3(0.0f));
    pe.intensity = p.spectrum("intensity", Spectrum(1.0f));
    e.model = pe;
  } else if (type == "directional") {
    DirectionalEmitter de;
    const Vec3 d = p.has("direction") ? p.vec3("direction", Vec3(0, 0, 1)) : p.transform("to_world").vector(Vec3(0, 0, 1));
    if (!(glm::length(d) > 0.0f)) p.fail("direction must be non-zero");
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
      p.fail(err.what());
    }
    env.world_from_env = p.transform("to_world");
    float unused_scale;
    check_similarity(p, env.world_from_env, unused_scale);  // a shear would break the 2 pi^2 sin(theta) Jacobian
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

void load_sensor(Context& ctx, const json& j, const std::string& id) {
  const std::string type = type_of(j);
  Props p(ctx, j, describe("sensor", id, type));
  if (type != "perspective") p.fail("unknown sensor type '" + type + "' (known: perspective)");
  Camera& cam = ctx.scene->camera;
  cam.width = 768;
  cam.height = 576;
  for (const auto& [key, child] : p.children()) {
    const std::string ctype = type_of(*child);
    p.mark_used(key);
    if (ctype == "hdrfilm") {
      Props fp(ctx, *child, describe("film", key, ctype));
      cam.width = fp.integer("width", 768);
      cam.height = fp.integer("height", 576);
      if (cam.width <= 0 || cam.height <= 0 || cam.width > 32768 || cam.height > 32768)
        fp.fail("width and height must be in [1, 32768] (got " + std::to_string(cam.width) + " x " + std::to_string(cam.height) + ")");
      for (const auto& [fk, fchild] : fp.children()) {
        fp.mark_used(fk);
        const std::string ft = type_of(*fchild);
        if (ft != "box") ctx.scene->warnings.push_back(ctx.source + ": film '" + key + "': reconstruction filter '" + ft +
                                                       "' is not supported; limn averages samples uniformly over each pixel (box)");
      }
      fp.mark_used("pixel_format");
      fp.mark_used("component_format");
      fp.check_unused();
    } else if (known_types().count(ctype) && known_types().at(ctype) == Category::Sampler) {
      Props sp(ctx, *child, describe("sampler", key, ctype));
      ctx.scene->spp = sp.integer("sample_count", 4);
      if (ctx.scene->spp <= 0) sp.fail("sample_count must be > 0 (got " + std::to_string(ctx.scene->spp) + ")");
      if (ctype != "independent") ctx.scene->warnings.push_back(ctx.source + ": sampler '" + key + "': '" + ctype + "' is rendered with independent samples");
      sp.mark_used("seed");
      sp.check_unused();
    } else {
      p.fail("a '" + ctype + "' cannot be nested in a sensor (under '" + key + "')");
    }
  }
  cam.world_from_camera = p.transform("to_world");
  try {
    cam.set_fov(p.number("fov", 39.3077f), p.string("fov_axis", "x"));
  } catch (const std::invalid_argument& e) {
    p.fail(e.what());
  }
  cam.near_clip = p.number("near_clip", 1e-2f);
  cam.far_clip = p.number("far_clip", 1e4f);
  if (!(cam.near_clip > 0.0f && cam.far_clip > cam.near_clip)) p.fail("need 0 < near_clip < far_clip");
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

}  // namespace

namespace {
std::unique_ptr<Scene> load_scene_dict_impl(const json& d, const std::string& source, const std::filesystem::path& base_dir,
                                            const std::vector<ArrayData>& arrays) {
  auto scene = std::make_unique<Scene>();
  scene->source = source;
  Context ctx{source, base_dir, &arrays, scene.get(), {}, {}};
  if (!d.is_object()) throw std::invalid_argument(source + ": the scene description must be a dictionary");
  if (d.contains("type") && d.at("type") != "scene")
    throw std::invalid_argument(source + ": top-level \"type\" must be \"scene\" (got " + d.at("type").dump() + ")");

  // Classify the top-level objects, then load in dependency order: bsdfs (shapes may refer to them),
  // shapes (area emitters live in them), the rest.
  std::vector<std::pair<std::string, const json*>> by_cat[16];
  for (auto it = d.begin(); it != d.end(); ++it) {
    if (it.key() == "type") continue;
    const json& v = it.value();
    if (!v.is_object() || !v.contains("type") || !v.at("type").is_string())
      throw std::invalid_argument(source + ": '" + it.key() + "' must be an object with a \"type\" (got " + v.dump().substr(0, 80) + ")");
    const std::string type = v.at("type").get<std::string>();
    auto cat = known_types().find(type);
    if (cat == known_types().end() || cat->second == Category::Scene || cat->second == Category::Texture || cat->second == Category::Ref)
      throw std::invalid_argument(source + ": '" + it.key() + "' has unknown type '" + type + "' (known: sensors " + known_of(Category::Sensor) +
                                  "; integrators " + known_of(Category::Integrator) + "; shapes " + known_of(Category::Shape) + "; bsdfs " +
                                  known_of(Category::Bsdf) + "; emitters " + known_of(Category::Emitter) + ")");
    if (v.contains("id") && !v.at("id").is_string()) throw std::invalid_argument(source + ": '" + it.key() + "': \"id\" must be a string");
    const std::string id = str_field(v, "id", it.key());
    if (!ctx.ids.insert(id).second) throw std::invalid_argument(source + ": duplicate id '" + id + "'");
    by_cat[int(cat->second)].emplace_back(id, &v);
  }
  for (const auto& [id, j] : by_cat[int(Category::Bsdf)]) ctx.named_bsdfs[id] = add_bsdf(ctx, load_bsdf(ctx, *j, id));
  for (const auto& [id, j] : by_cat[int(Category::Shape)]) load_shape(ctx, *j, id);
  for (const auto& [id, j] : by_cat[int(Category::Emitter)]) load_emitter(ctx, *j, id);
  const auto& sensors = by_cat[int(Category::Sensor)];
  if (sensors.empty()) throw std::invalid_argument(source + ": the scene has no sensor (add a 'perspective' sensor)");
  if (sensors.size() > 1) scene->warnings.push_back(source + ": " + std::to_string(sensors.size()) + " sensors; only '" + sensors[0].first + "' is used");
  load_sensor(ctx, *sensors[0].second, sensors[0].first);
  const auto& integrators = by_cat[int(Category::Integrator)];
  if (integrators.size() > 1) throw std::invalid_argument(source + ": more than one integrator");
  if (!integrators.empty()) load_integrator(ctx, *integrators[0].second, integrators[0].first);
  for (int c : {int(Category::Film), int(Category::Sampler), int(Category::Filter)})
    for (const auto& [id, j] : by_cat[c]) throw std::invalid_argument(source + ": '" + id + "' (" + type_of(*j) + ") must be nested in the sensor");
  if (scene->emitters.empty()) scene->warnings.push_back(source + ": the scene has no emitters; it will render black");

  scene->build();
  return scene;
}
}  // namespace

std::unique_ptr<Scene> load_scene_dict(const json& d, const std::string& source, const std::filesystem::path& base_dir,
                                       const std::vector<ArrayData>& arrays) {
  try {
    return load_scene_dict_impl(d, source, base_dir, arrays);
  } catch (const json::exception& e) {  // a wrong JSON type that a check above did not anticipate
    throw std::invalid_argument(source + ": malformed scene description: " + e.what());
  } catch (const std::filesystem::filesystem_error& e) {
    throw std::invalid_argument(source + ": " + e.what());
  }
}

std::unique_ptr<Scene> load_scene_file(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw std::invalid_argument("scene file '" + path + "' not found or not readable");
  json d;
  try {
    d = json::parse(f);
  } catch (const json::parse_error& e) {
    throw std::invalid_argument(path + ": malformed JSON: " + e.what());
  }
  std::filesystem::path base = std::filesystem::path(path).parent_path();
  return load_scene_dict(d, path, base.empty() ? std::filesystem::path(".") : base);
}

}  // namespace limn
