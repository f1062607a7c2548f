#include "core/io/scene/shapes.h"

#include <limits>
#include <sstream>
#include "core/io/formats/files.h"
#include "core/io/formats/mesh_io.h"

// Triangle meshes: obj and ply files, "mesh" from arrays, the built-in rectangle and cube.
namespace limn::io_detail {

// `field` names where the data came from in messages: "vertex_positions", or "filename" for a file
// `file` (also named).
Mesh build_mesh(const Props& p, MeshData data, const Transform& to_world, bool face_normals, const std::string& field, const std::string& file) {
  const std::string where = file.empty() ? std::string() : "'" + field + "' '" + printable(file) + "': ";
  if (data.indices.size() % 3 != 0 || data.positions.size() % 3 != 0) p.fail("mesh buffers are not triangles of 3D points");
  const size_t nv = data.positions.size() / 3;
  for (size_t v = 0; v < nv; ++v)
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(data.positions[3 * v + c])) {
        std::ostringstream s;
        s << "'" << field << "': vertex " << v << " is not finite ([" << data.positions[3 * v] << ", " << data.positions[3 * v + 1] << ", "
          << data.positions[3 * v + 2] << "])";
        p.fail(s.str());
      }
  for (size_t i = 0; i < data.indices.size(); ++i)
    if (data.indices[i] >= nv)
      p.fail("'" + field + "': triangle " + std::to_string(i / 3) + " refers to vertex " + std::to_string(data.indices[i]) + " but there are only " +
             std::to_string(nv) + " vertices");
  Mesh m;
  m.face_normals = face_normals;
  m.indices = weld_by_position(data.positions, data.indices, m.positions);
  m.corner_uvs = std::move(data.corner_uvs);
  const std::vector<float> local = to_world.is_identity() ? std::vector<float>() : m.positions;  // for messages
  for (size_t v = 0; v < m.positions.size(); v += 3) {
    const Vec3 q = to_world.point(Vec3(m.positions[v], m.positions[v + 1], m.positions[v + 2]));
    if (!(std::abs(q.x) <= kMaxCoordinate && std::abs(q.y) <= kMaxCoordinate && std::abs(q.z) <= kMaxCoordinate)) {
      const Vec3d qd = Vec3d(to_world.matrix() * glm::dvec4(Vec3d(m.positions[v], m.positions[v + 1], m.positions[v + 2]), 1.0));
      p.fail(where + (to_world.is_identity() ? (where.empty() ? "'" + field + "': vertex " : std::string("vertex ")) : std::string("'to_world' moves vertex ")) + std::to_string(v / 3) + " ([" + number_text(m.positions[v]) +
             ", " + number_text(m.positions[v + 1]) + ", " + number_text(m.positions[v + 2]) + "])" +
             (to_world.is_identity() ? std::string() : " to [" + number_text(qd.x) + ", " + number_text(qd.y) + ", " + number_text(qd.z) + "]") +
             ", beyond " + number_text(kMaxCoordinate) + ", the largest world coordinate limn traces rays at");
    }
    m.positions[v] = q.x; m.positions[v + 1] = q.y; m.positions[v + 2] = q.z;
  }
  // A mirroring transform reverses the winding; swap two corners so normals keep pointing outwards.
  if (glm::determinant(to_world.matrix()) < 0.0)
    for (size_t t = 0; t < m.indices.size(); t += 3) {
      std::swap(m.indices[t + 1], m.indices[t + 2]);
      if (!m.corner_uvs.empty())
        for (int c = 0; c < 2; ++c) std::swap(m.corner_uvs[2 * (t + 1) + c], m.corner_uvs[2 * (t + 2) + c]);
    }

  // Degenerate triangles (repeated vertices after welding, or corners on a line, decided exactly in
  // double, so that the scale does not matter): an error unless allowed. A triangle whose area the
  // float arithmetic of the renderer cannot represent (overflow far above 1e19, underflow to 0 far
  // below 1e-19) is refused, or dropped with the degenerate ones when it underflows.
  const bool allow = p.boolean("allow_degenerate", false);
  std::vector<uint32_t> kept;
  std::vector<float> kept_uv;
  size_t dropped = 0, first_bad = 0;
  for (size_t t = 0; t < m.indices.size() / 3; ++t) {
    const uint32_t a = m.indices[3 * t], b = m.indices[3 * t + 1], c = m.indices[3 * t + 2];
    const Vec3d pa(m.vertex(a)), n = glm::cross(Vec3d(m.vertex(b)) - pa, Vec3d(m.vertex(c)) - pa);
    const double area = 0.5 * std::sqrt(glm::dot(n, n));
    const float area_f = 0.5f * glm::length(glm::cross(m.vertex(b) - m.vertex(a), m.vertex(c) - m.vertex(a)));  // as the renderer computes it
    const bool degenerate = a == b || b == c || a == c || !(area > 0.0);
    if (!degenerate && !std::isfinite(area_f))
      p.fail(where + "triangle " + std::to_string(t) + " (vertices " + std::to_string(a) + ", " + std::to_string(b) + ", " + std::to_string(c) + ") has area " +
             number_text(area) + (to_world.is_identity() ? std::string() : " after 'to_world'") +
             ", too large for float arithmetic (the renderer needs the cross product of its edges, about 1e19 at most); scale the mesh down");
    if (degenerate || !(area_f > 0.0f)) {
      if (!allow) {
        std::ostringstream s;
        s << where;
        const auto local_area = [&] {
          const auto at = [&](uint32_t i) { return Vec3d(local[3 * size_t(i)], local[3 * size_t(i) + 1], local[3 * size_t(i) + 2]); };
          return local.empty() ? 0.0 : 0.5 * norm(glm::cross(at(b) - at(a), at(c) - at(a)));
        };
        if (degenerate && a != b && b != c && a != c && local_area() > 0.0)
          s << "triangle " << t << " (vertices " << a << ", " << b << ", " << c << ", area " << local_area()
            << ") becomes degenerate after 'to_world' (its corners collapse in float)";
        else if (degenerate)
          s << "triangle " << t << " is degenerate (vertices " << a << ", " << b << ", " << c << " enclose zero area)";
        else
          s << "triangle " << t << " (vertices " << a << ", " << b << ", " << c << ") has area " << area
            << (to_world.is_identity() ? "" : " after 'to_world'") << ", too small for float arithmetic (it comes out as 0)";
        s << "; fix the mesh or set \"allow_degenerate\": true to drop such triangles";
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
  if (m.indices.empty()) p.fail(where + "the mesh has no triangles left (all were degenerate and dropped)");
  return m;
}

MeshData mesh_from_arrays(const Props& p) {
  MeshData d;
  const ArrayData v = p.array("vertex_positions");
  if (v.shape.size() != 2 || v.shape[1] != 3) p.fail("'vertex_positions' must have shape (N, 3) (got " + shape_text(v.shape) + ")");
  if (v.shape[0] > std::numeric_limits<uint32_t>::max()) p.fail("'vertex_positions' has more than 2^32 - 1 vertices");
  d.positions.reserve(v.values.size());
  for (size_t i = 0; i < v.values.size(); ++i) {
    const double x = v.values[i];
    if (!(std::abs(x) <= double(std::numeric_limits<float>::max())))
      p.fail("'vertex_positions': vertex " + std::to_string(i / 3) + " is not finite in float (coordinate " + number_text(x) + ")");
    d.positions.push_back(float(x));
  }
  const ArrayData f = p.array("faces");
  if (f.shape.size() != 2 || f.shape[1] != 3) p.fail("'faces' must have shape (F, 3) (got " + shape_text(f.shape) + ")");
  if (f.shape[0] == 0) p.fail("'faces' is empty (a mesh needs at least one triangle)");
  if (!f.integer) p.fail("'faces' must hold integers");
  const size_t nv = v.shape[0];
  for (size_t i = 0; i < f.values.size(); ++i) {
    const double x = f.values[i];
    if (!(x >= 0 && x < double(nv)))
      p.fail("'faces': triangle " + std::to_string(i / 3) + " refers to vertex " + number_text(x) + " but there are only " + std::to_string(nv) + " vertices");
    d.indices.push_back(uint32_t(x));
  }
  if (p.has("corner_uvs")) {
    const ArrayData uv = p.array("corner_uvs");
    if (uv.shape != std::vector<size_t>{f.shape[0], 3, 2})
      p.fail("'corner_uvs' must have shape (F, 3, 2) = (" + std::to_string(f.shape[0]) + ", 3, 2) (got " + shape_text(uv.shape) + ")");
    for (double x : uv.values)
      if (!(std::abs(x) <= double(std::numeric_limits<float>::max()))) p.fail("'corner_uvs' has an entry that is not a finite float (" + number_text(x) + ")");
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

ShapeGeometry load_mesh_shape(const Props& p, const std::string& type, const Transform& to_world) {
  MeshData data;
  std::string field = "vertex_positions";
  bool face_normals = p.boolean("face_normals", type == "rectangle" || type == "cube");
  if (type == "obj" || type == "ply") {
    const std::string path = p.file("filename");
    field = "filename";
    try {
      data = read_mesh_file(path);
    } catch (const std::invalid_argument& e) {
      p.fail(std::string("'filename': ") + e.what());
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
  return build_mesh(p, std::move(data), to_world, face_normals, field, field == "filename" ? p.raw("filename").get<std::string>() : std::string());
}

}  // namespace limn::io_detail
