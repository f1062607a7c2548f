#include "core/geometry/accel.h"

#include <atomic>
#include <cstring>
#include <mutex>
#include <stdexcept>

namespace limn {

// ---- device and error callback ----------------------------------------------------------------
namespace {
std::mutex g_error_mutex;
std::string g_last_error;
std::atomic<size_t> g_error_count{0};
size_t g_checked_count = 0;

const char* embree_error_name(RTCError code) {
  switch (code) {
    case RTC_ERROR_NONE: return "none";
    case RTC_ERROR_UNKNOWN: return "unknown";
    case RTC_ERROR_INVALID_ARGUMENT: return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION: return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY: return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU: return "unsupported CPU";
    case RTC_ERROR_CANCELLED: return "cancelled";
  }
  return "?";
}

// Called by Embree on any API error; must not throw through Embree's C frames.
void embree_error_callback(void*, RTCError code, const char* message) {
  std::lock_guard<std::mutex> lock(g_error_mutex);
  g_last_error = std::string("Embree error (") + embree_error_name(code) + "): " + (message ? message : "");
  g_error_count.fetch_add(1);
}
}  // namespace

RTCDevice EmbreeDevice::get() {
  static RTCDevice device = [] {
    RTCDevice d = rtcNewDevice(nullptr);
    if (!d) throw std::runtime_error("Embree: could not create a device (error " + std::to_string(int(rtcGetDeviceError(nullptr))) + ")");
    rtcSetDeviceErrorFunction(d, embree_error_callback, nullptr);
    return d;
  }();
  return device;
}

void EmbreeDevice::check(const std::string& what) {
  std::lock_guard<std::mutex> lock(g_error_mutex);
  const size_t count = g_error_count.load();
  if (count != g_checked_count) {
    g_checked_count = count;
    throw std::runtime_error(what + ": " + g_last_error);
  }
}

size_t EmbreeDevice::error_count() { return g_error_count.load(); }
std::string EmbreeDevice::last_error() {
  std::lock_guard<std::mutex> lock(g_error_mutex);
  return g_last_error;
}

// ---- user geometry: spheres and heightfields, with our exact intersectors --------------------------
namespace {
void user_bounds(RTCBounds* b, const Vec3& lo, const Vec3& hi) {
  b->lower_x = lo.x; b->lower_y = lo.y; b->lower_z = lo.z;
  b->upper_x = hi.x; b->upper_y = hi.y; b->upper_z = hi.z;
}

void sphere_bounds(const RTCBoundsFunctionArguments* args) {
  const Sphere& s = *static_cast<const Sphere*>(args->geometryUserPtr);
  // Widened by a few ulps: the box is rounded to float, the intersector works in double.
  const float r = s.radius * (1.0f + 1e-6f) + 1e-6f * max_component(glm::abs(s.center));
  user_bounds(args->bounds_o, s.center - Vec3(r), s.center + Vec3(r));
}

void heightfield_bounds(const RTCBoundsFunctionArguments* args) {
  const Heightfield& h = *static_cast<const Heightfield*>(args->geometryUserPtr);
  Vec3 lo, hi;
  h.bounds(lo, hi);
  // The same few-ulp widening as spheres: the surface is evaluated in double.
  const Vec3 pad = 1e-6f * (glm::abs(lo) + glm::abs(hi) + Vec3(1e-3f));
  user_bounds(args->bounds_o, lo - pad, hi + pad);
}

Ray ray_from_n(RTCRayN* ray, unsigned N, unsigned i) {
  Ray r;
  r.o = Vec3(RTCRayN_org_x(ray, N, i), RTCRayN_org_y(ray, N, i), RTCRayN_org_z(ray, N, i));
  r.d = Vec3(RTCRayN_dir_x(ray, N, i), RTCRayN_dir_y(ray, N, i), RTCRayN_dir_z(ray, N, i));
  r.tmin = RTCRayN_tnear(ray, N, i);
  r.tmax = RTCRayN_tfar(ray, N, i);
  return r;
}

// Shape::intersect(ray, t) for Embree; the surface record is rebuilt by Accel::intersect.
template <typename G>
void user_intersect(const RTCIntersectFunctionNArguments* args) {
  const G& g = *static_cast<const G*>(args->geometryUserPtr);
  RTCRayN* ray = RTCRayHitN_RayN(args->rayhit, args->N);
  RTCHitN* hit = RTCRayHitN_HitN(args->rayhit, args->N);
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    const Ray r = ray_from_n(ray, args->N, i);
    float t;
    if (!g.intersect(r, t)) continue;
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
}

template <typename G>
void user_occluded(const RTCOccludedFunctionNArguments* args) {
  const G& g = *static_cast<const G*>(args->geometryUserPtr);
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    float t;
    if (g.intersect(ray_from_n(args->ray, args->N, i), t)) RTCRayN_tfar(args->ray, args->N, i) = -kInfinity;
  }
}

void upload_vertices(RTCGeometry g, const Mesh& m) {
  auto* dst = static_cast<float*>(rtcGetGeometryBufferData(g, RTC_BUFFER_TYPE_VERTEX, 0));
  std::memcpy(dst, m.positions.data(), m.positions.size() * sizeof(float));
  rtcUpdateGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0);
}
}  // namespace

// ---- scene --------------------------------------------------------------------------------------
Accel::Accel(std::vector<Shape>& shapes) : m_shapes(shapes) {
  RTCDevice device = EmbreeDevice::get();
  m_scene = rtcNewScene(device);
  rtcSetSceneFlags(m_scene, RTC_SCENE_FLAG_DYNAMIC | RTC_SCENE_FLAG_ROBUST);
  for (size_t i = 0; i < shapes.size(); ++i) {
    RTCGeometry g = nullptr;
    if (shapes[i].is_mesh()) {
      const Mesh& m = shapes[i].mesh();
      g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
      // Embree-owned buffers (padded as Embree requires); our copy stays the one users edit.
      rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), m.vertex_count());
      auto* idx = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                 3 * sizeof(uint32_t), m.triangle_count()));
      std::memcpy(idx, m.indices.data(), m.indices.size() * sizeof(uint32_t));
      upload_vertices(g, m);
      // Vertices move during optimisation: refit the BVH instead of rebuilding it.
      rtcSetGeometryBuildQuality(g, RTC_BUILD_QUALITY_REFIT);
    } else {
      g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
      rtcSetGeometryUserPrimitiveCount(g, 1);
      if (shapes[i].is_sphere()) {
        rtcSetGeometryUserData(g, &shapes[i].sphere());
        rtcSetGeometryBoundsFunction(g, sphere_bounds, nullptr);
        rtcSetGeometryIntersectFunction(g, user_intersect<Sphere>);
        rtcSetGeometryOccludedFunction(g, user_occluded<Sphere>);
      } else {
        rtcSetGeometryUserData(g, &shapes[i].heightfield());
        rtcSetGeometryBoundsFunction(g, heightfield_bounds, nullptr);
        rtcSetGeometryIntersectFunction(g, user_intersect<Heightfield>);
        rtcSetGeometryOccludedFunction(g, user_occluded<Heightfield>);
      }
    }
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(m_scene, g, unsigned(i));  // geomID == shape index
    m_geoms.push_back(g);
  }
  try {
    commit();
    EmbreeDevice::check("building the acceleration structure");
  } catch (...) {
    for (RTCGeometry g : m_geoms) rtcReleaseGeometry(g);
    rtcReleaseScene(m_scene);
    throw;
  }
}

Accel::~Accel() {
  for (RTCGeometry g : m_geoms) rtcReleaseGeometry(g);
  if (m_scene) rtcReleaseScene(m_scene);
}

void Accel::shape_changed(int i) {
  if (m_shapes[i].is_mesh()) upload_vertices(m_geoms[i], m_shapes[i].mesh());
  rtcCommitGeometry(m_geoms[i]);
}

void Accel::commit() {
  rtcCommitScene(m_scene);
  EmbreeDevice::check("committing the acceleration structure");
}

bool Accel::intersect(const Ray& ray, SurfaceInteraction& si) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh;
  rh.ray.org_x = ray.o.x; rh.ray.org_y = ray.o.y; rh.ray.org_z = ray.o.z;
  rh.ray.dir_x = ray.d.x; rh.ray.dir_y = ray.d.y; rh.ray.dir_z = ray.d.z;
  rh.ray.tnear = ray.tmin;
  rh.ray.tfar = ray.tmax;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.flags = 0;
  rh.ray.time = 0.0f;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(m_scene, &ctx, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;

  const Shape& shape = m_shapes[rh.hit.geomID];
  si.t = rh.ray.tfar;
  si.shape = int(rh.hit.geomID);
  if (shape.is_mesh()) shape.mesh().fill_interaction(int(rh.hit.primID), rh.hit.u, rh.hit.v, si);
  else if (shape.is_sphere()) shape.sphere().fill_interaction(ray(si.t), si);
  else shape.heightfield().fill_interaction_world(ray(si.t), si);
  return true;
}

bool Accel::occluded(const Ray& ray) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRay r;
  r.org_x = ray.o.x; r.org_y = ray.o.y; r.org_z = ray.o.z;
  r.dir_x = ray.d.x; r.dir_y = ray.d.y; r.dir_z = ray.d.z;
  r.tnear = ray.tmin;
  r.tfar = ray.tmax;
  r.mask = 0xFFFFFFFFu;
  r.flags = 0;
  r.time = 0.0f;
  rtcOccluded1(m_scene, &ctx, &r);
  return r.tfar < 0.0f;  // Embree sets tfar = -inf on a hit
}

}  // namespace limn
