// Heightfield geometry: B-spline derivatives against central differences, the maximum mipmap bounds
// the surface and its incremental update equals a rebuild, mipmap ray traversal against brute-force
// marching, no self re-hit, Embree user geometry, and the taped surface (heights, ray distance)
// against central differences.
#include <doctest/doctest.h>

#include "tests/cpp/test_util.h"

#include "core/render/accel.h"
#include "core/diff/shapes/heightfield.h"
#include "core/math/rng.h"

using namespace limn;

namespace {
Heightfield bumpy(int nx, int ny, uint64_t seed, float amplitude = 0.3f) {
  Heightfield hf;
  hf.nx = nx;
  hf.ny = ny;
  hf.width = 2.0f;
  hf.depth = 1.5f;
  hf.height_scale = 0.8f;
  Pcg32 rng(seed);
  for (int r = 0; r < ny; ++r)
    for (int c = 0; c < nx; ++c)
      hf.heights.push_back(amplitude * (std::sin(0.7f * c) * std::cos(0.5f * r) + 0.5f * rng.next_float()));
  hf.build_mipmap();
  return hf;
}

// First t where the ray is below the surface, by dense marching plus bisection (reference).
bool brute_force(const Heightfield& hf, const Vec3d& o, const Vec3d& d, double tmax, double& t_hit) {
  auto F = [&](double t) {
    const Vec3d p = o + t * d;
    if (!hf.inside(p.x, p.y)) return std::nan("");  // outside the footprint: no surface (and no side walls)
    return p.z - hf.eval(p.x, p.y).z;
  };
  const int steps = 20000;
  double ta = 1e-9, fa = F(ta);
  for (int s = 1; s <= steps; ++s) {
    const double tb = tmax * s / steps, fb = F(tb);
    if (!std::isnan(fa) && !std::isnan(fb) && (fa > 0) != (fb > 0)) {
      double lo = ta, hi = tb;
      for (int i = 0; i < 60; ++i) {
        const double m = 0.5 * (lo + hi);
        ((F(m) > 0) == (fa > 0) ? lo : hi) = m;
      }
      t_hit = 0.5 * (lo + hi);
      return true;
    }
    ta = tb;
    fa = fb;
  }
  return false;
}
}  // namespace

TEST_CASE("heightfield: B-spline slopes and curvatures match central differences") {
  const Heightfield hf = bumpy(9, 7, 1);
  Pcg32 rng(7);
  const double h = 1e-5;
  for (int k = 0; k < 200; ++k) {
    const double x = (rng.next_float() - 0.5) * 0.98 * hf.width, y = (rng.next_float() - 0.5) * 0.98 * hf.depth;
    const HeightSample s = hf.eval(x, y);
    const HeightSample sx0 = hf.eval(x - h, y), sx1 = hf.eval(x + h, y), sy0 = hf.eval(x, y - h), sy1 = hf.eval(x, y + h);
    CHECK(s.dx == doctest::Approx((sx1.z - sx0.z) / (2 * h)).epsilon(1e-5));
    CHECK(s.dy == doctest::Approx((sy1.z - sy0.z) / (2 * h)).epsilon(1e-5));
    CHECK(s.dxx == doctest::Approx((sx1.dx - sx0.dx) / (2 * h)).epsilon(1e-4));
    CHECK(s.dyy == doctest::Approx((sy1.dy - sy0.dy) / (2 * h)).epsilon(1e-4));
    CHECK(s.dxy == doctest::Approx((sy1.dx - sy0.dx) / (2 * h)).epsilon(1e-4));
    CellPatch cell;  // the inner loops' per-cell evaluation agrees
    const PatchCoords pc = hf.patch(x, y);
    cell.load(hf, pc.c0, pc.r0);
    const HeightSample f = cell.eval(hf, x, y);
    CHECK(f.z == doctest::Approx(s.z).epsilon(1e-12));
    CHECK(f.dx == doctest::Approx(s.dx).epsilon(1e-12));
    CHECK(f.dy == doctest::Approx(s.dy).epsilon(1e-12));
  }
  // C1 across cell borders: slopes from both sides of a grid line agree.
  const double xc = hf.local_x(3.0);
  CHECK(hf.eval(xc - 1e-9, 0.1).dx == doctest::Approx(hf.eval(xc + 1e-9, 0.1).dx).epsilon(1e-6));
}

TEST_CASE("heightfield: the mipmap bounds the surface; incremental updates equal a rebuild") {
  Heightfield hf = bumpy(37, 21, 2);
  Pcg32 rng(3);
  for (int k = 0; k < 4000; ++k) {
    const double x = (rng.next_float() - 0.5) * hf.width, y = (rng.next_float() - 0.5) * hf.depth;
    const PatchCoords pc = hf.patch(x, y);
    const size_t cell = size_t(pc.r0) * hf.mip[0].w + pc.c0;
    const double z = hf.eval(x, y).z;
    CHECK(z <= hf.mip[0].node[cell].hi + 1e-6);
    CHECK(z >= hf.mip[0].node[cell].lo - 1e-6);
    // The second-derivative bounds of the curvature tests (peak_search.h), at a random point of
    // the cell and up the pyramid (a parent bounds its children).
    const HeightSample h = hf.eval(x, y);
    CHECK(std::abs(h.dxx) <= hf.mip[0].node[cell].zxx * (1.0 + 1e-5) + 1e-9);
    CHECK(std::abs(h.dyy) <= hf.mip[0].node[cell].zyy * (1.0 + 1e-5) + 1e-9);
    CHECK(std::abs(h.dxy) <= hf.mip[0].node[cell].zxy * (1.0 + 1e-5) + 1e-9);
    const size_t parent = size_t(pc.r0 / 2) * hf.mip[1].w + pc.c0 / 2;
    CHECK(hf.mip[0].node[cell].zxx <= hf.mip[1].node[parent].zxx);
  }
  CHECK(hf.mip.back().w == 1);
  CHECK(hf.mip.back().h == 1);
  // Edit a small block, update, compare with a fresh build.
  for (int r = 5; r < 8; ++r)
    for (int c = 30; c < 33; ++c) hf.heights[size_t(r) * hf.nx + c] += 2.0f;
  const size_t recomputed = hf.update_mipmap();
  CHECK(recomputed > 0);
  CHECK(recomputed < hf.mip[0].node.size() / 4);  // only the neighbourhood, not the whole grid
  Heightfield fresh = hf;
  fresh.build_mipmap();
  for (size_t l = 0; l < hf.mip.size(); ++l) {
    CHECK(hf.mip[l].node == fresh.mip[l].node);
  }
  CHECK(hf.update_mipmap() == 0);  // nothing changed since
}

TEST_CASE("heightfield: mipmap traversal finds the same first hit as brute-force marching") {
  const Heightfield hf = bumpy(33, 25, 4, 0.5f);
  Pcg32 rng(11);
  int hits = 0, both = 0;
  size_t cells = 0;
  for (int k = 0; k < 400; ++k) {
    // Rays from above the field towards random points on (or just beside) it; some grazing.
    const Vec3d target((rng.next_float() - 0.5) * 2.4, (rng.next_float() - 0.5) * 1.8, rng.next_float() * 0.4 - 0.2);
    const double elev = 0.05 + 1.4 * rng.next_float(), az = 6.2831853 * rng.next_float();
    const Vec3d d = -Vec3d(std::cos(elev) * std::cos(az), std::cos(elev) * std::sin(az), std::sin(elev));
    const Vec3d o = target - 4.0 * d;
    double t_ref = 0, t = 0;
    const bool ref = brute_force(hf, o, d, 8.0, t_ref);
    const bool got = hf.intersect_local(o, d, 0.0, 8.0, t, &cells);
    if (ref != got) MESSAGE("t_ref " << t_ref << " elev " << elev << " o " << o.x << "," << o.y << "," << o.z << " d " << d.x << "," << d.y << "," << d.z);
    CHECK(ref == got);
    if (ref && got) {
      CHECK(t == doctest::Approx(t_ref).epsilon(1e-5));
      ++both;
    }
    hits += ref;
  }
  CHECK(hits > 100);
  CHECK(both == hits);
  // The traversal touched far fewer cells than the rays crossed (about 30 per ray here).
  CHECK(double(cells) / 400.0 < 30.0);
}

TEST_CASE("heightfield: Embree user geometry, transform, and no self re-hit") {
  Shape s;
  s.id = "terrain";
  Heightfield hf = bumpy(17, 17, 5);
  hf.world_from_local = Transform::translate(Vec3d(1, -2, 3)) * Transform::rotate(Vec3d(1, 0, 0), -90.0) * Transform::scale(Vec3d(2.0));
  hf.scale = 2.0f;
  s.geometry = hf;
  std::vector<Shape> shapes = {s};
  Accel accel(shapes);
  const Heightfield& h = test::geometry<Heightfield>(shapes, 0);
  Pcg32 rng(13);
  int hits = 0;
  for (int k = 0; k < 300; ++k) {
    // Local up is world +y after the rotation: shoot down along -y.
    const Vec3 o(1.0f + 3.0f * (rng.next_float() - 0.5f), 3.0f, 3.0f + 2.0f * (rng.next_float() - 0.5f));
    SurfaceInteraction si;
    if (!accel.intersect(Ray{o, Vec3(0, -1, 0)}, si)) continue;
    ++hits;
    const Vec3 pl = h.world_from_local.inverse().point(si.p);
    CHECK(pl.z == doctest::Approx(float(h.eval(pl.x, pl.y).z)).epsilon(1e-4));
    CHECK(si.ng.y > 0.0f);  // up-facing normal, in world space
    // Leaving the hit point in any direction of the upper hemisphere does not hit it again at t ~ 0.
    for (int j = 0; j < 8; ++j) {
      Vec3 w = glm::normalize(Vec3(rng.next_float() - 0.5f, rng.next_float(), rng.next_float() - 0.5f));
      if (glm::dot(w, si.ng) <= 0.0f) w = -w;
      SurfaceInteraction again;
      if (accel.intersect(spawn_ray(si, w), again)) CHECK(again.t > 1e-3f);
    }
  }
  CHECK(hits > 100);
}

TEST_CASE("heightfield: taped height and ray distance match central differences in the heights") {
  Scene scene;
  Shape s;
  s.id = "hf";
  s.geometry = bumpy(8, 6, 6);
  scene.shapes.push_back(s);
  scene.bsdfs.push_back(Bsdf{"white", Diffuse{Texture{Spectrum(0.5f), nullptr}}, false});
  scene.shapes[0].bsdf = 0;
  scene.build();
  const DiffParams params(scene, {"hf.heights"});
  Heightfield& hf = test::geometry<Heightfield>(scene.shapes, 0);
  const Vec3d o(-0.9, 0.4, 1.2), d = glm::normalize(Vec3d(0.8, -0.5, -0.9));
  double t0;
  REQUIRE(hf.intersect_local(o, d, 0.0, 10.0, t0));
  const double x = o.x + t0 * d.x, y = o.y + t0 * d.y;  // the hit's patch: its heights move the hit
  const PatchCoords pc = hf.patch(x, y);
  for (int k : {pc.index[0][0], pc.index[1][2], pc.index[2][1], pc.index[3][3]}) {
    PathInputs in;
    ad::Tape::current().clear();
    const DiffHeightfieldFrame F(scene, params, in, 0);
    ad::Var z, zx, zy;
    F.height(in, ad::Var(x), ad::Var(y), z, zx, zy);
    const ad::V3<ad::Var> O(ad::Var(o.x), ad::Var(o.y), ad::Var(o.z)), D(ad::Var(d.x), ad::Var(d.y), ad::Var(d.z));
    const ad::Var t = F.ray_t(in, O, D, t0);
    auto grad = [&](const ad::Var& v) {
      std::vector<double> adj;
      ad::Tape::current().backward(v.idx, 1.0, adj);
      double g = 0;
      for (const auto& [node, slot] : in.nodes)
        if (long(slot) == long(k)) g += adj[node];
      return g;
    };
    const double gz = grad(z), gzx = grad(zx), gt = grad(t);
    const float h0 = hf.heights[k];
    const double eps = 1e-3;
    hf.heights[k] = h0 + float(eps);
    hf.build_mipmap();
    const HeightSample p = hf.eval(x, y);
    double tp;
    REQUIRE(hf.intersect_local(o, d, 0.0, 10.0, tp));
    hf.heights[k] = h0 - float(eps);
    hf.build_mipmap();
    const HeightSample m = hf.eval(x, y);
    double tm;
    REQUIRE(hf.intersect_local(o, d, 0.0, 10.0, tm));
    hf.heights[k] = h0;
    hf.build_mipmap();
    CHECK(gz == doctest::Approx((p.z - m.z) / (2 * eps)).epsilon(1e-3));
    CHECK(gzx == doctest::Approx((p.dx - m.dx) / (2 * eps)).epsilon(1e-3));
    CHECK(gt == doctest::Approx((tp - tm) / (2 * eps)).epsilon(2e-3));
  }
}
