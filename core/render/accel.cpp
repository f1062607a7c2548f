#include "core/render/accel.h"

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

// ---- scene --------------------------------------------------------------------------------------
Accel::Accel(std::vector<Shape>& shapes) : m_shapes(shapes) {
  RTCDevice device = EmbreeDevice::get();
  m_scene = rtcNewScene(device);
  rtcSetSceneFlags(m_scene, RTC_SCENE_FLAG_DYNAMIC | RTC_SCENE_FLAG_ROBUST);
  for (size_t i = 0; i < shapes.size(); ++i) {
    RTCGeometry g = shapes[i].visit([&](const auto& geometry) { return geometry.create_embree_geometry(device); });
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
  m_shapes[i].visit([&](const auto& geometry) { geometry.update_embree_geometry(m_geoms[i]); });
  rtcCommitGeometry(m_geoms[i]);
}

void Accel::commit() {
  rtcCommitScene(m_scene);
  EmbreeDevice::check("committing the acceleration structure");
}

bool Accel::traceable(const Ray& ray) const {
  // Embree's RayK::valid(): |org|, |dir| <= FLT_LARGE per component (comparisons fail for NaN),
  // tnear and tfar not NaN.
  constexpr float kLarge = 1.844e18f;
  bool ok = !std::isnan(ray.tmin) && !std::isnan(ray.tmax);
  for (int a = 0; a < 3; ++a) ok = ok && std::abs(ray.o[a]) <= kLarge && std::abs(ray.d[a]) <= kLarge;
  if (!ok) m_invalid_rays.fetch_add(1, std::memory_order_relaxed);
  return ok;
}

bool Accel::intersect(const Ray& ray, SurfaceInteraction& si) const {
  if (!traceable(ray)) return false;
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
  shape.visit([&](const auto& geometry) { geometry.fill_hit(ray, si.t, rh.hit.primID, Vec2(rh.hit.u, rh.hit.v), si); });
  return true;
}

bool Accel::occluded(const Ray& ray) const {
  if (!traceable(ray)) return false;
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
