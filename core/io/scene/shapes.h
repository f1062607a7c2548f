// Shape loaders. A shape kind is a loader function (in its own file: meshes.cpp, sphere.cpp,
// heightfield.cpp) plus one line in the table of shape_kinds() (shapes.cpp), which also makes its
// type name known (known_types()). load_shape does what all kinds share: the object's to_world, the
// nested bsdf (inline or reference) and area emitter, the default bsdf.
#pragma once
#include <map>
#include <string>
#include "core/geometry/ray.h"
#include "core/io/scene/props.h"

namespace limn::io_detail {

// Sphere radii after to_world: the intersection and the area use r^2 in float.
inline constexpr float kMinRadius = 1e-18f, kMaxRadius = 1e18f;
// World coordinates of geometry and of the camera are within kMaxCoordinate (core/geometry/ray.h),
// the same bound update() checks.
using limn::kMaxCoordinate;

// Heightfields have at most this many heights (rows x columns).
inline constexpr uint64_t kMaxHeightfieldSamples = uint64_t(1) << 24;  // e.g. 4096 x 4096

// Builds the geometry of a shape of type `type`; to_world has been read already.
using ShapeLoader = ShapeGeometry (*)(const Props& p, const std::string& type, const Transform& to_world);

// Type name -> loader, for every shape type of the scene format. Whether the shape may carry an
// area emitter is its kind's (can_emit, core/geometry/shapes/shape.h).
const std::map<std::string, ShapeLoader>& shape_kinds();

// obj, ply, mesh, rectangle, cube (meshes.cpp).
ShapeGeometry load_mesh_shape(const Props& p, const std::string& type, const Transform& to_world);
// sphere (sphere.cpp).
ShapeGeometry load_sphere(const Props& p, const std::string& type, const Transform& to_world);
// disk (disk.cpp).
ShapeGeometry load_disk(const Props& p, const std::string& type, const Transform& to_world);
// heightfield (heightfield.cpp).
ShapeGeometry load_heightfield(const Props& p, const std::string& type, const Transform& to_world);
// bsplinecurve (curve.cpp).
ShapeGeometry load_bsplinecurve(const Props& p, const std::string& type, const Transform& to_world);

// sdfgrid (sdfgrid.cpp).
ShapeGeometry load_sdfgrid(const Props& p, const std::string& type, const Transform& to_world);

void load_shape(Context& ctx, const json& j, const std::string& id);

}  // namespace limn::io_detail
