#include "core/diff/shapes/heightfield.h"

#include "core/diff/ad/local_derivatives.h"

namespace limn {

using ad::Var;
using VV = ad::V3<Var>;

DiffHeightfieldFrame::DiffHeightfieldFrame(const Scene& scene, const DiffParams& params, PathInputs& in, int shape)
    : hf(std::get<Heightfield>(scene.shapes[shape].geometry)),
      scale(hf.scale),
      world(hf.world_from_local.matrix()),
      local(hf.world_from_local.inverse_matrix()),
      heights_slot(params.slot(Parameter::Kind::Heights, shape)) {
  const long t = params.slot(Parameter::Kind::Translation, shape);
  // The stored transform already includes the translation: the offset enters with value 0.
  if (t >= 0) offset = VV(in.make(0.0, t), in.make(0.0, t + 1), in.make(0.0, t + 2));
}

namespace {
VV apply(const Mat4d& m, const VV& p, double w) {
  return VV(Var(m[0][0]) * p.x + Var(m[1][0]) * p.y + Var(m[2][0]) * p.z + Var(w * m[3][0]),
            Var(m[0][1]) * p.x + Var(m[1][1]) * p.y + Var(m[2][1]) * p.z + Var(w * m[3][1]),
            Var(m[0][2]) * p.x + Var(m[1][2]) * p.y + Var(m[2][2]) * p.z + Var(w * m[3][2]));
}
}  // namespace

VV DiffHeightfieldFrame::to_world_point(const VV& p) const { return apply(world, p, 1.0) + offset; }
VV DiffHeightfieldFrame::to_world_vector(const VV& v) const { return apply(world, v, 0.0); }
VV DiffHeightfieldFrame::to_local_point(const VV& p) const { return apply(local, p - offset, 1.0); }
VV DiffHeightfieldFrame::to_local_vector(const VV& v) const { return apply(local, v, 0.0); }

void DiffHeightfieldFrame::height(PathInputs& in, const Var& x, const Var& y, Var& z, Var& zx, Var& zy) const {
  const PatchCoords pc = hf.patch(x.v, y.v);
  const double kc = (hf.nx - 1) / double(hf.width), kr = -(hf.ny - 1) / double(hf.depth);  // dc/dx, dr/dy
  const Var fc = (x / Var(hf.width) + Var(0.5)) * Var(hf.nx - 1) - Var(pc.c0);
  const Var fr = (Var(0.5) - y / Var(hf.depth)) * Var(hf.ny - 1) - Var(pc.r0);
  Var bc[4], dbc[4], d2bc[4], br[4], dbr[4], d2br[4];
  bspline_basis(fc, bc, dbc, d2bc);
  bspline_basis(fr, br, dbr, d2br);
  z = zx = zy = Var(0.0);
  for (int b = 0; b < 4; ++b)
    for (int a = 0; a < 4; ++a) {
      const int k = pc.index[b][a];
      const Var h = in.make(hf.heights[k], heights_slot < 0 ? -1 : heights_slot + k);
      z += br[b] * bc[a] * h;
      zx += br[b] * dbc[a] * h;
      zy += dbr[b] * bc[a] * h;
    }
  const Var s(hf.height_scale);
  z = z * s;
  zx = zx * s * Var(kc);
  zy = zy * s * Var(kr);
}

void DiffHeightfieldFrame::surface(PathInputs& in, const Var& x, const Var& y, VV& p, VV& n) const {
  Var z, zx, zy;
  height(in, x, y, z, zx, zy);
  p = to_world_point(VV(x, y, z));
  n = ad::normalize(to_world_vector(VV(-zx, -zy, Var(1.0))));  // a similarity maps normals like vectors
}

Var DiffHeightfieldFrame::ray_t(PathInputs& in, const VV& o, const VV& d, double t0) const {
  const VV ol = to_local_point(o), dl = to_local_vector(d);
  const Var x = ol.x + dl.x * Var(t0), y = ol.y + dl.y * Var(t0);
  Var z, zx, zy;
  height(in, x, y, z, zx, zy);
  const Var g = ol.z + dl.z * Var(t0) - z;                             // 0 at the primal root
  const double dg = dl.z.v - zx.v * dl.x.v - zy.v * dl.y.v;           // dg/dt there
  if (dg == 0.0) return Var(t0);  // exactly tangent: no first-order motion along the ray is defined
  return Var(t0) - g / Var(dg);
}

namespace {
// The material point at grid coordinates sp.bary: fixed local (x, y), its height and slopes.
struct AttachedHeight {
  DiffHeightfieldFrame F;
  Var x, y, z, zx, zy;
  AttachedHeight(const DiffContext& c, const Heightfield& hf, const SurfacePoint& sp)
      : F(c.scene, c.params, c.in, sp.shape), x(hf.local_x(sp.bary.x)), y(hf.local_y(sp.bary.y)) {
    F.height(c.in, x, y, z, zx, zy);
  }
  VV world_point() const { return F.to_world_point(VV(x, y, z)); }
};
}  // namespace

VV SurfaceDiff<Heightfield>::position(const DiffContext& c, const Heightfield& hf, const SurfacePoint& sp) {
  return AttachedHeight(c, hf, sp).world_point();
}

DiffVertex SurfaceDiff<Heightfield>::attach(const DiffContext& c, const Heightfield& hf, const SurfacePoint& sp) {
  DiffVertex x;
  const AttachedHeight h(c, hf, sp);
  const Var &zx = h.zx, &zy = h.zy;
  const DiffHeightfieldFrame& F = h.F;
  x.p = h.world_point();
  x.ng = x.ns = normalize(F.to_world_vector(VV(-zx, -zy, Var(1.0))));
  const Var area = sqrt(Var(1.0) + zx * zx + zy * zy);  // dA / (dx dy)
  x.jacobian = area / Var(area.v);
  x.u = Var(sp.uv.x);
  x.v = Var(sp.uv.y);
  return x;
}

DiffVertex SurfaceDiff<Heightfield>::ray_hit(const DiffContext& c, const Heightfield& hf, const VV& o, const VV& d,
                                             const SurfaceInteraction& si, const Ray&) {
  DiffVertex x;
  const DiffHeightfieldFrame F(c.scene, c.params, c.in, si.shape);
  const Var t = F.ray_t(c.in, o, d, double(si.t));
  const VV pl = F.to_local_point(o + d * t);
  F.surface(c.in, pl.x, pl.y, x.p, x.ng);
  x.ns = x.ng;
  // Texture coordinates slide with the hit: u = x / W + 1/2, v = y / D + 1/2.
  x.u = pl.x / Var(hf.width) + Var(0.5);
  x.v = pl.y / Var(hf.depth) + Var(0.5);
  return x;
}

}  // namespace limn
