// Embree 3 user geometry for shapes with their own exact intersectors (spheres, disks, heightfields): one
// primitive per shape, intersected by G::intersect(ray, t) in the callbacks; the surface record is
// rebuilt afterwards by G::fill_hit. Callbacks never throw (they run inside Embree's C frames).
#pragma once
#include <embree3/rtcore.h>
#include "core/geometry/ray.h"

namespace limn::embree_user {

inline void set_bounds(RTCBounds* b, const Vec3& lo, const Vec3& hi) {
  b->lower_x = lo.x; b->lower_y = lo.y; b->lower_z = lo.z;
  b->upper_x = hi.x; b->upper_y = hi.y; b->upper_z = hi.z;
}

inline Ray ray_from_n(RTCRayN* ray, unsigned N, unsigned i) {
  Ray r;
  r.o = Vec3(RTCRayN_org_x(ray, N, i), RTCRayN_org_y(ray, N, i), RTCRayN_org_z(ray, N, i));
  r.d = Vec3(RTCRayN_dir_x(ray, N, i), RTCRayN_dir_y(ray, N, i), RTCRayN_dir_z(ray, N, i));
  r.tmin = RTCRayN_tnear(ray, N, i);
  r.tmax = RTCRayN_tfar(ray, N, i);
  return r;
}

// Records a hit at t for ray i of the packet; the surface is rebuilt later by G::fill_hit, so
// the normal and uv written here are placeholders.
inline void record_hit(const RTCIntersectFunctionNArguments* args, RTCRayN* ray, RTCHitN* hit, unsigned i, float t) {
  RTCRayN_tfar(ray, args->N, i) = t;
  RTCHitN_Ng_x(hit, args->N, i) = 0.0f;
  RTCHitN_Ng_y(hit, args->N, i) = 0.0f;
  RTCHitN_Ng_z(hit, args->N, i) = 1.0f;
  RTCHitN_u(hit, args->N, i) = 0.0f;
  RTCHitN_v(hit, args->N, i) = 0.0f;
  RTCHitN_primID(hit, args->N, i) = args->primID;
  RTCHitN_geomID(hit, args->N, i) = args->geomID;
  RTCHitN_instID(hit, args->N, i, 0) = args->context->instID[0];
}

template <typename G>
void intersect(const RTCIntersectFunctionNArguments* args) {
  const G& g = *static_cast<const G*>(args->geometryUserPtr);
  RTCRayN* ray = RTCRayHitN_RayN(args->rayhit, args->N);
  RTCHitN* hit = RTCRayHitN_HitN(args->rayhit, args->N);
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    const Ray r = ray_from_n(ray, args->N, i);
    float t;
    if (!g.intersect(r, t)) continue;
    record_hit(args, ray, hit, i, t);
  }
}

template <typename G>
void occluded(const RTCOccludedFunctionNArguments* args) {
  const G& g = *static_cast<const G*>(args->geometryUserPtr);
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    float t;
    if (g.intersect(ray_from_n(args->ray, args->N, i), t)) RTCRayN_tfar(args->ray, args->N, i) = -kInfinity;
  }
}

// One user primitive for shape g (which must stay at its address while the geometry lives).
template <typename G>
RTCGeometry new_geometry(RTCDevice device, const G& g, RTCBoundsFunction bounds) {
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
  rtcSetGeometryUserPrimitiveCount(geom, 1);
  rtcSetGeometryUserData(geom, const_cast<G*>(&g));
  rtcSetGeometryBoundsFunction(geom, bounds, nullptr);
  rtcSetGeometryIntersectFunction(geom, intersect<G>);
  rtcSetGeometryOccludedFunction(geom, occluded<G>);
  return geom;
}

}  // namespace limn::embree_user
