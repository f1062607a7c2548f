#include "core/diff/primary.h"

#include "core/diff/film_projection.h"
#include "core/diff/local_derivatives.h"
#include "core/render/integrators/path.h"

namespace limn {
namespace {

using ad::Var;
using VV = ad::V3<Var>;
using Vec2d = glm::dvec2;

// Offset of the two radiance probes from the curve, in pixels: far above the float resolution of
// camera ray directions (~4e-5 px at 256 px across 40 degrees), far below any image feature.
constexpr double kProbeOffset = 1e-3;

ad::V3<double> d3(const Vec3& v) { return ad::V3<double>(v.x, v.y, v.z); }

// The sphere's silhouette circle seen from eye: centre, radius and the plane's frame.
template <typename T>
bool outline(const ad::V3<T>& c, const T& r, const ad::V3<double>& eye, ad::V3<T>& q, T& rho, ad::V3<T>& e1, ad::V3<T>& e2) {
  const ad::V3<T> axis = c - ad::V3<T>(T(eye.x), T(eye.y), T(eye.z));
  const T d = length(axis);
  if (ad::value(d) <= ad::value(r)) return false;  // the eye is inside: no silhouette
  const ad::V3<T> u = axis / d;
  q = c - u * (r * r / d);
  rho = r * sqrt(T(1.0) - (r * r) / (d * d));
  const diff::Frame3<T> f(u);
  e1 = f.s;
  e2 = f.t;
  return true;
}

}  // namespace

PrimaryBoundary::PrimaryBoundary(const Scene& scene, const DiffParams& params, int max_depth)
    : m_scene(scene), m_params(params), m_max_depth(max_depth) {
  const FilmProjection proj(scene.camera);
  const ad::V3<double> eye = d3(scene.camera.world_from_camera.point(Vec3(0.0f)));
  auto film_of = [&](const ad::V3<double>& p, Vec2d& s) {
    const auto pc = proj.to_camera(p);
    if (pc.z <= proj.near) return false;
    double fx, fy;
    proj.film(pc, fx, fy);
    s = Vec2d(fx, fy);
    return true;
  };
  std::vector<float> weights;
  for (int si : params.moving_shapes()) {
    const Shape& shape = scene.shapes[si];
    if (shape.is_mesh()) {
      const Mesh& m = shape.mesh();
      auto faces_eye = [&](int f) {
        const Vec3 p0 = m.vertex(m.indices[3 * f]);
        // Front-facing with a margin: a face within 1e-6 (cosine) of edge-on projects to no area
        // whichever way rounding tips it, and must not make a second outline next to the real one.
        return glm::dot(m.oriented_normal(f), glm::normalize(Vec3d(eye.x, eye.y, eye.z) - Vec3d(p0))) > 1e-6;
      };
      for (const MeshEdge& e : m.edges) {
        bool candidate = e.face_count != 2;  // boundary or non-manifold edges are always candidates
        if (!candidate) candidate = faces_eye(e.face0) != faces_eye(e.face1);  // silhouette
        // Flat shading: the radiance also jumps across a crease between two faces that both face
        // the camera (1e-6: cosine below which the faces count as coplanar, where the jump is zero).
        // Creases with a back-facing face are hidden or are silhouettes already; including them
        // would count an outline twice where a face is seen exactly edge-on.
        if (!candidate && m.face_normals && faces_eye(e.face0) && faces_eye(e.face1))
          candidate = glm::dot(m.oriented_normal(e.face0), m.oriented_normal(e.face1)) < 1.0 - 1e-6;
        if (!candidate) continue;
        const int a = int(e.a), b = int(e.b);
        Vec2d sa, sb;
        if (!film_of(d3(m.vertex(a)), sa) || !film_of(d3(m.vertex(b)), sb)) {
          ++m_skipped;  // limitation: edges crossing the near plane are skipped (and counted), not clipped
          continue;
        }
        const float len = float(glm::length(sb - sa));
        if (!(len > 0.0f)) continue;
        m_curves.push_back({si, a, b, len});
        weights.push_back(len);
      }
    } else if (shape.is_sphere()) {
      const Sphere& s = shape.sphere();
      ad::V3<double> q, e1, e2;
      double rho;
      if (!outline(d3(s.center), double(s.radius), eye, q, rho, e1, e2)) continue;
      // Selection weight: the projected perimeter, from a 64-gon.
      double len = 0;
      Vec2d prev(0.0);
      bool ok = true;
      for (int i = 0; i <= 64 && ok; ++i) {
        const double phi = 2 * M_PI * i / 64;
        Vec2d cur(0.0);
        ok = film_of(q + (e1 * std::cos(phi) + e2 * std::sin(phi)) * rho, cur);
        if (i > 0) len += glm::length(cur - prev);
        prev = cur;
      }
      if (!ok) {
        ++m_skipped;
        continue;
      }
      m_curves.push_back({si, -1, -1, float(len)});
      weights.push_back(float(len));
    }
  }
  if (!weights.empty()) m_select = Distribution1D(weights);
}

bool PrimaryBoundary::sample(Pcg32& rng, PathInputs& in, int& pixel, Spectrum& delta_L, Var& normal_velocity,
                             uint64_t& rays) const {
  const FilmProjection proj(m_scene.camera);
  const ad::V3<double> eye = d3(m_scene.camera.world_from_camera.point(Vec3(0.0f)));
  const size_t k = m_select.sample_discrete(rng.next_float());
  const double pmf = m_select.pmf(k);
  const float u = rng.next_float();
  const SilhouetteCurve& c = m_curves[k];
  const Shape& shape = m_scene.shapes[c.shape];

  VV P;                    // the curve point as a function of the parameters
  ad::V3<double> dP;       // d(point)/d(curve parameter)
  double pdf_param;        // density of the curve parameter
  if (shape.is_mesh()) {
    const VV a = diff_vertex(m_scene, m_params, in, c.shape, uint32_t(c.a)), b = diff_vertex(m_scene, m_params, in, c.shape, uint32_t(c.b));
    P = a + (b - a) * Var(u);
    dP = ad::values(b - a);
    pdf_param = 1.0;
  } else {
    const VV center = diff_sphere_center(m_scene, m_params, in, c.shape);
    const Var r = diff_sphere_radius(m_scene, m_params, in, c.shape);
    VV q, e1, e2;
    Var rho;
    if (!outline(center, r, eye, q, rho, e1, e2)) return false;
    const double phi = 2 * M_PI * u;
    P = q + (e1 * Var(std::cos(phi)) + e2 * Var(std::sin(phi))) * rho;
    dP = (ad::values(e1) * -std::sin(phi) + ad::values(e2) * std::cos(phi)) * rho.v;
    pdf_param = 1.0 / (2 * M_PI);
  }

  const ad::V3<Var> pc = proj.to_camera(P);
  if (pc.z.v <= proj.near) return false;
  Var fx, fy;
  proj.film(pc, fx, fy);
  if (!(fx.v >= 0 && fx.v < proj.W && fy.v >= 0 && fy.v < proj.H)) return false;
  const Vec2d ds = proj.film_derivative(ad::values(pc), dP);
  const double ds_len = glm::length(ds);
  if (!(ds_len > 0.0)) return false;
  const Vec2d n(-ds.y / ds_len, ds.x / ds_len);
  const double pdf_length = pmf * pdf_param / ds_len;  // per unit of film length
  pixel = int(fy.v) * int(proj.W) + int(fx.v);

  // Radiance on both sides with the same random numbers.
  PathCounters counters;
  const Pcg32 rng_paths = rng;
  Spectrum L[2];
  for (int side = 0; side < 2; ++side) {
    const double sign = side == 0 ? -1.0 : 1.0;
    const Vec2 film(float(fx.v + sign * kProbeOffset * n.x), float(fy.v + sign * kProbeOffset * n.y));
    Pcg32 r = rng_paths;
    L[side] = path_radiance(m_scene, m_scene.camera.generate_ray(film), r, counters, PathLimits{m_max_depth, true});
  }
  rays += counters.rays;
  delta_L = (L[0] - L[1]) / float(pdf_length);
  normal_velocity = fx * Var(n.x) + fy * Var(n.y);
  return is_finite(delta_L);
}

}  // namespace limn
