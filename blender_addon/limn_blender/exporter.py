"""Blender scene -> limn scene description (a dict in the JSON format, with numpy arrays).

Exports mesh-like objects with modifiers applied (world-space vertices, split by material), the
active camera, point / spot / sun / area lights, the world colour, and Principled BSDF (plus a few simple
BSDF nodes) mapped to the closest limn BSDF. Objects marked as limn heightfields (the object
property ``limn_heightfield``, or named in ``export_scene(heightfields=...)``) become limn
``heightfield`` shapes instead (see heightfield.py). Curve objects with a round bevel and hair
``Curves`` objects become limn ``bsplinecurve`` fibre curves (see curves.py). Everything that cannot be represented is listed
in the returned warnings; nothing is dropped silently. Works with Blender 3.4 and 4.x.
"""
from __future__ import annotations

import json
import math
import os

import bpy
import numpy as np

from . import curves, heightfield

# Blender camera space looks along -Z with +Y up; limn's looks along +Z with +X to the left.
# Rotating by 180 degrees about Y maps one onto the other.
_CAMERA_FLIP = np.diag([-1.0, 1.0, -1.0, 1.0])
# Area lights emit along their local -Z; limn's rectangle faces +Z: rotate 180 degrees about X.
_RECT_FLIP = np.diag([1.0, -1.0, -1.0, 1.0])

MESH_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT"}


def _matrix(m) -> np.ndarray:
    return np.array([list(row) for row in m], dtype=np.float64)


def _rows(m: np.ndarray) -> list[list[float]]:
    return [[float(x) for x in row] for row in m]


def _rgb(value) -> list[float]:
    return [float(value[0]), float(value[1]), float(value[2])]


def _socket(node, *names):
    """First input socket among `names` (socket names differ between Blender 3.x and 4.x)."""
    for n in names:
        s = node.inputs.get(n)
        if s is not None:
            return s
    return None


# ---- materials ----------------------------------------------------------------------------------
def _base_colour(node, material_name: str, warnings: list[str]):
    sock = _socket(node, "Base Color", "Color")
    if sock is None:
        return [0.8, 0.8, 0.8]
    if sock.is_linked:
        src = sock.links[0].from_node
        if src.type == "TEX_IMAGE" and src.image is not None:
            path = bpy.path.abspath(src.image.filepath, library=src.image.library)
            if path and os.path.exists(path):
                return {"type": "bitmap", "filename": os.path.abspath(path)}
            warnings.append(f"material '{material_name}': image '{src.image.name}' is not a file on disk; "
                            "using the socket's colour")
        else:
            warnings.append(f"material '{material_name}': base colour is driven by a '{src.type}' node, "
                            "which limn does not evaluate; using the socket's colour")
    return _rgb(sock.default_value)


def _value(node, default: float, *names) -> float:
    s = _socket(node, *names)
    return float(s.default_value) if s is not None else default


def _diffuse(reflectance) -> dict:
    return {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": reflectance}}


def _metal(colour, roughness: float) -> dict:
    alpha = roughness * roughness  # Blender's roughness is perceptual: GGX alpha = roughness^2
    if isinstance(colour, dict):
        colour = [0.8, 0.8, 0.8]  # textured specular colour is not supported
    if alpha < 1e-4:
        inner = {"type": "conductor", "material": "none", "specular_reflectance": colour}
    else:
        inner = {"type": "roughconductor", "material": "none", "distribution": "ggx", "alpha": alpha,
                 "specular_reflectance": colour}
    return {"type": "twosided", "bsdf": inner}


def _glass(roughness: float, ior: float) -> dict:
    alpha = roughness * roughness
    if alpha < 1e-4:
        return {"type": "dielectric", "int_ior": ior, "ext_ior": 1.0}
    return {"type": "roughdielectric", "distribution": "ggx", "alpha": alpha, "int_ior": ior, "ext_ior": 1.0}


def convert_material(mat, warnings: list[str]) -> tuple[dict, list[float] | None]:
    """Returns (bsdf description, emitted radiance or None)."""
    if mat is None:
        return _diffuse([0.8, 0.8, 0.8]), None
    name = mat.name
    if not (mat.use_nodes and mat.node_tree):
        if mat.metallic > 0.5:
            return _metal(_rgb(mat.diffuse_color), mat.roughness), None
        return _diffuse(_rgb(mat.diffuse_color)), None
    outputs = [n for n in mat.node_tree.nodes if n.type == "OUTPUT_MATERIAL"]
    output = next((n for n in outputs if n.is_active_output), outputs[0] if outputs else None)
    surface = output.inputs.get("Surface") if output else None
    if surface is None or not surface.is_linked:
        warnings.append(f"material '{name}': no surface shader connected; exported as grey diffuse")
        return _diffuse([0.8, 0.8, 0.8]), None
    node = surface.links[0].from_node
    if node.type == "BSDF_PRINCIPLED":
        colour = _base_colour(node, name, warnings)
        roughness = _value(node, 0.5, "Roughness")
        metallic = _value(node, 0.0, "Metallic")
        transmission = _value(node, 0.0, "Transmission Weight", "Transmission")
        ior = _value(node, 1.45, "IOR")
        emission = None
        e_sock = _socket(node, "Emission Color", "Emission")
        strength = _value(node, 1.0, "Emission Strength")
        if e_sock is not None and strength > 0.0 and max(_rgb(e_sock.default_value)) > 0.0:
            emission = [c * strength for c in _rgb(e_sock.default_value)]
        if transmission > 0.5:
            bsdf = _glass(roughness, ior)
        elif metallic > 0.5:
            bsdf = _metal(colour, roughness)
        else:
            if metallic > 0.0 or transmission > 0.0:
                warnings.append(f"material '{name}': metallic {metallic:.2f} / transmission {transmission:.2f} "
                                "mixes are not supported; exported as diffuse")
            bsdf = _diffuse(colour)
        return bsdf, emission
    if node.type == "BSDF_DIFFUSE":
        return _diffuse(_base_colour(node, name, warnings)), None
    if node.type == "BSDF_GLOSSY":
        return _metal(_base_colour(node, name, warnings), _value(node, 0.5, "Roughness")), None
    if node.type == "BSDF_GLASS":
        return _glass(_value(node, 0.0, "Roughness"), _value(node, 1.45, "IOR")), None
    if node.type == "EMISSION":
        colour = _rgb(_socket(node, "Color").default_value)
        return _diffuse([0.0, 0.0, 0.0]), [c * _value(node, 1.0, "Strength") for c in colour]
    warnings.append(f"material '{name}': shader node '{node.type}' is not supported; exported as grey diffuse")
    return _diffuse([0.8, 0.8, 0.8]), None


# ---- geometry -------------------------------------------------------------------------------------
def _mesh_arrays(mesh, world: np.ndarray):
    mesh.calc_loop_triangles()
    nv, nt = len(mesh.vertices), len(mesh.loop_triangles)
    co = np.empty(nv * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    tris = np.empty(nt * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    mat_index = np.empty(nt, dtype=np.int32)
    mesh.loop_triangles.foreach_get("material_index", mat_index)
    smooth = np.empty(nt, dtype=bool)
    mesh.loop_triangles.foreach_get("use_smooth", smooth)
    corner_uvs = None
    if mesh.uv_layers.active is not None and nt:
        loops = np.empty(nt * 3, dtype=np.int32)
        mesh.loop_triangles.foreach_get("loops", loops)
        uv = np.empty(len(mesh.loops) * 2, dtype=np.float32)
        mesh.uv_layers.active.data.foreach_get("uv", uv)
        corner_uvs = uv.reshape(-1, 2)[loops].reshape(nt, 3, 2)
    p = co.reshape(-1, 3).astype(np.float64) @ world[:3, :3].T + world[:3, 3]
    faces = tris.reshape(-1, 3)
    if np.linalg.det(world[:3, :3]) < 0:  # mirrored object: keep the winding outward
        faces = faces[:, [0, 2, 1]]
        if corner_uvs is not None:
            corner_uvs = corner_uvs[:, [0, 2, 1]]
    return p.astype(np.float32), faces, mat_index, smooth, corner_uvs


def _export_mesh_object(obj, world, desc, warnings, used_ids):
    mesh = obj.to_mesh()
    try:
        positions, faces, mat_index, smooth, corner_uvs = _mesh_arrays(mesh, world)
    finally:
        obj.to_mesh_clear()
    if len(faces) == 0:
        warnings.append(f"object '{obj.name}': no faces, skipped")
        return
    slots = [s.material for s in obj.material_slots] or [None]
    for slot in np.unique(mat_index):
        sel = mat_index == slot
        used, inverse = np.unique(faces[sel], return_inverse=True)
        mat = slots[slot] if slot < len(slots) else None
        sid = obj.name if len(np.unique(mat_index)) == 1 else f"{obj.name}.{mat.name if mat else slot}"
        sid = _unique(sid, used_ids)
        bsdf, emission = convert_material(mat, warnings)
        shape = {"type": "mesh", "vertex_positions": positions[used], "faces": inverse.reshape(-1, 3).astype(np.int64),
                 "face_normals": not bool(smooth[sel].any()), "allow_degenerate": True, "bsdf": bsdf}
        if corner_uvs is not None:
            shape["corner_uvs"] = corner_uvs[sel]
        if emission is not None:
            shape["emitter"] = {"type": "area", "radiance": emission}
        desc[sid] = shape


def _export_heightfield_object(original, obj, world, desc, warnings, used_ids):
    """A plane with an image Displace modifier or a regular grid mesh as a limn heightfield."""
    source = heightfield.Source(original)
    warnings.extend(source.warnings)
    slots = [s.material for s in obj.material_slots]
    if len([m for m in slots if m is not None]) > 1:
        warnings.append(f"object '{original.name}': a heightfield has one material; using '{slots[0].name if slots[0] else 'none'}'")
    mat = slots[0] if slots else None
    bsdf, emission = convert_material(mat, warnings)
    if emission is not None:
        raise ValueError(f"object '{original.name}': material '{mat.name}' emits light, and a limn heightfield cannot "
                         "be an area emitter")
    desc[_unique(original.name, used_ids)] = source.shape(world, bsdf)


def _export_curve_object(original, obj, world, desc, warnings, used_ids) -> bool:
    """A legacy Curve (round bevel) or hair Curves object as limn fibre curves (curves.py). Returns
    False, with a warning naming the object and what limn cannot represent, when a legacy curve
    must be exported as Blender's tessellated mesh instead (a hair object has no mesh: it is skipped
    with the warning)."""
    if obj.type == "CURVE" and curves.fibre_reason(original):
        return False  # not a round tube: Blender's mesh of it, as for any curve before
    try:
        source = curves.Source(original, obj)
        shape_world = source.shape(world, {})
    except ValueError as e:
        if obj.type == "CURVES":  # no mesh to fall back on
            warnings.append(f"{e}; skipped")
            return True
        warnings.append(f"{e}; exported as Blender's tessellated mesh instead")
        return False
    warnings.extend(source.warnings)
    slots = [s.material for s in original.material_slots]
    used = [slots[i] if i < len(slots) else None for i in source.materials] or [None]
    if len({id(m) for m in used}) > 1:
        warnings.append(f"object '{original.name}': limn fibre curves have one material; using "
                        f"'{used[0].name if used[0] else 'none'}'")
    mat = used[0] if used else (slots[0] if slots else None)
    bsdf, emission = convert_material(mat, warnings)
    if emission is not None:
        warnings.append(f"object '{original.name}': material '{mat.name}' emits light, and limn's fibre curves "
                        "cannot be area emitters; exported without emission")
    shape_world["bsdf"] = bsdf
    desc[_unique(original.name, used_ids)] = shape_world
    return True


def _unique(name: str, used: set[str]) -> str:
    base, k = name, 1
    while name in used:
        k += 1
        name = f"{base}.{k}"
    used.add(name)
    return name


# ---- lights, camera, world --------------------------------------------------------------------------
def _export_light(obj, world, desc, warnings, used_ids):
    light = obj.data
    colour = np.array(_rgb(light.color))
    sid = _unique(obj.name, used_ids)
    if light.type == "POINT":
        # Radiant intensity of an isotropic point source of power P: I = P / (4 pi).
        desc[sid] = {"type": "point", "position": [float(x) for x in world[:3, 3]],
                     "intensity": list(colour * light.energy / (4.0 * math.pi))}
        if getattr(light, "shadow_soft_size", 0.0) > 0.0:
            warnings.append(f"light '{obj.name}': radius {light.shadow_soft_size:g} ignored (limn point lights are points)")
    elif light.type == "SPOT":
        # limn's (Mitsuba's) spot: intensity P / (4 pi) on its axis as a point light of power P
        # (Cycles' convention), cutoff_angle = half of Blender's spot_size, and a linear ramp in angle
        # over the outer spot_blend of it (Cycles blends with a smoothstep in cos; approximated).
        d = -world[:3, 2]
        d = d / np.linalg.norm(d)
        helper = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = np.cross(helper, d)
        x /= np.linalg.norm(x)
        frame = np.eye(4)
        frame[:3, 0], frame[:3, 1], frame[:3, 2], frame[:3, 3] = x, np.cross(d, x), d, world[:3, 3]
        cutoff = math.degrees(light.spot_size) / 2.0
        desc[sid] = {"type": "spot", "to_world": _rows(frame), "intensity": list(colour * light.energy / (4.0 * math.pi)),
                     "cutoff_angle": cutoff, "beam_width": cutoff * (1.0 - light.spot_blend)}
        if getattr(light, "shadow_soft_size", 0.0) > 0.0:
            warnings.append(f"light '{obj.name}': radius {light.shadow_soft_size:g} ignored (limn spot lights are points)")
        if light.spot_blend > 0.0:
            warnings.append(f"light '{obj.name}': spot blend {light.spot_blend:g} exported as a linear falloff in angle "
                            "(Cycles blends smoothly in cos)")
    elif light.type == "SUN":
        d = -world[:3, 2]
        desc[sid] = {"type": "directional", "direction": list(d / np.linalg.norm(d)), "irradiance": list(colour * light.energy)}
    elif light.type == "AREA":
        sx = light.size
        sy = light.size_y if light.shape in ("RECTANGLE", "ELLIPSE") else light.size
        if light.shape in ("DISK", "ELLIPSE"):
            warnings.append(f"light '{obj.name}': {light.shape.lower()} area light exported as a rectangle of equal area")
            sx, sy = sx * math.sqrt(math.pi) / 2.0, sy * math.sqrt(math.pi) / 2.0
        m = world @ np.diag([sx / 2.0, sy / 2.0, 1.0, 1.0]) @ _RECT_FLIP
        area = 4.0 * np.linalg.norm(np.cross(m[:3, 0], m[:3, 1]))
        # Blender's area-light power P gives radiance P / (4 A) in Cycles (measured against Cycles:
        # see docs/blender.md), not the P / (pi A) of a Lambertian emitter of radiant power P.
        desc[sid] = {"type": "rectangle", "to_world": _rows(m),
                     "bsdf": {"type": "diffuse", "reflectance": 0.0},
                     "emitter": {"type": "area", "radiance": list(colour * light.energy / (4.0 * area))}}
    else:
        warnings.append(f"light '{obj.name}': {light.type.lower()} lights are not supported; skipped")


def _export_camera(scene, desc, spp: int):
    cam = scene.camera
    if cam is None:
        raise ValueError(f"scene '{scene.name}' has no active camera")
    data = cam.data
    if data.type != "PERSP":
        raise ValueError(f"camera '{cam.name}': only perspective cameras are supported (got {data.type})")
    r = scene.render
    width = max(1, int(r.resolution_x * r.resolution_percentage / 100))
    height = max(1, int(r.resolution_y * r.resolution_percentage / 100))
    fit = data.sensor_fit
    if fit == "AUTO":
        axis, fov = "larger", data.angle
    elif fit == "HORIZONTAL":
        axis, fov = "x", data.angle_x
    else:
        axis, fov = "y", data.angle_y
    desc["sensor"] = {
        "type": "perspective", "fov": math.degrees(fov), "fov_axis": axis,
        "near_clip": float(data.clip_start), "far_clip": float(data.clip_end),
        "to_world": _rows(_matrix(cam.matrix_world) @ _CAMERA_FLIP),
        "film": {"type": "hdrfilm", "width": width, "height": height},
        "sampler": {"type": "independent", "sample_count": int(spp)},
    }
    return data


def _export_world(scene, desc, warnings):
    w = scene.world
    if w is None:
        return
    radiance = _rgb(w.color)
    if w.use_nodes and w.node_tree:
        out = next((n for n in w.node_tree.nodes if n.type == "OUTPUT_WORLD"), None)
        surf = out.inputs.get("Surface") if out else None
        if surf is not None and surf.is_linked:
            node = surf.links[0].from_node
            if node.type == "BACKGROUND":
                col = node.inputs["Color"]
                if col.is_linked:
                    warnings.append(f"world '{w.name}': textured backgrounds are not exported; using the socket colour")
                radiance = [c * float(node.inputs["Strength"].default_value) for c in _rgb(col.default_value)]
            else:
                warnings.append(f"world '{w.name}': node '{node.type}' not supported; using the world colour")
        else:
            radiance = [0.0, 0.0, 0.0]
    if max(radiance) > 0.0:
        desc["world"] = {"type": "constant", "radiance": radiance}


def light_objects(collection) -> list:
    """The light objects (type LIGHT) of a Blender collection and of its child collections."""
    return [o for o in collection.all_objects if o.type == "LIGHT"]


def export_scene(scene=None, depsgraph=None, spp: int = 64, max_depth: int | None = None,
                 heightfields=(), light_collection=None) -> tuple[dict, list[str]]:
    """Returns (scene description for limn.load_dict, warnings). Mesh objects named in
    `heightfields`, and those whose property limn_heightfield is set, are exported as limn
    heightfields (a ValueError names the object when that is impossible).

    `light_collection` (a bpy Collection, or None for all lights) is a light set-up: only the
    light objects (type LIGHT) in it or in its child collections are exported. The rule covers
    light objects only: meshes with emissive materials and the world are exported either way."""
    heightfields = set(heightfields or ())
    allowed_lights = None if light_collection is None else {o.as_pointer() for o in light_objects(light_collection)}
    scene = scene or bpy.context.scene
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    warnings: list[str] = []
    desc: dict = {"type": "scene"}
    if max_depth is None:
        cycles = getattr(scene, "cycles", None)
        # Cycles' max_bounces = 0 is direct lighting, i.e. paths of 2 segments in limn's max_depth.
        max_depth = int(cycles.max_bounces) + 2 if cycles is not None else 8
    desc["integrator"] = {"type": "path", "max_depth": int(max_depth)}
    _export_camera(scene, desc, spp)
    used_ids = {"type", "integrator", "sensor", "world"}
    for inst in depsgraph.object_instances:
        obj = inst.object
        original = obj.original if hasattr(obj, "original") else obj
        if original.hide_render:
            continue
        parent = inst.parent if inst.is_instance else None
        if parent is not None and parent.type == "CURVE" and parent.original == original:
            continue  # a curve's own evaluated mesh (listed as its instance since Blender 3.0): the curve is exported itself
        world = _matrix(inst.matrix_world)
        if obj.type == "MESH" and (original.name in heightfields or getattr(original, "limn_heightfield", False)):
            _export_heightfield_object(original, obj, world, desc, warnings, used_ids)
        elif obj.type in ("CURVE", "CURVES") and _export_curve_object(original, obj, world, desc, warnings, used_ids):
            pass
        elif obj.type in MESH_TYPES:
            _export_mesh_object(obj, world, desc, warnings, used_ids)
        elif obj.type == "LIGHT":
            if allowed_lights is not None and original.as_pointer() not in allowed_lights:
                continue  # not in this view's light set-up
            _export_light(obj, world, desc, warnings, used_ids)
    _export_world(scene, desc, warnings)
    return desc, warnings


def write_scene(desc: dict, folder: str, name: str = "scene") -> str:
    """Writes the description as folder/name.json with meshes as binary PLY files in
    folder/meshes (meshes with texture coordinates as OBJ). Returns the JSON path."""
    import limn  # noqa: F401  (imported by the add-on through limn_loader before this is called)

    os.makedirs(os.path.join(folder, "meshes"), exist_ok=True)
    out = {}
    for key, value in desc.items():
        if isinstance(value, dict) and value.get("type") == "mesh":
            shape = {k: v for k, v in value.items() if k not in ("vertex_positions", "faces", "corner_uvs")}
            safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in key)
            if "corner_uvs" in value:
                rel = os.path.join("meshes", safe + ".obj")
                _write_obj(os.path.join(folder, rel), value["vertex_positions"], value["faces"], value["corner_uvs"])
                shape["type"] = "obj"
            else:
                rel = os.path.join("meshes", safe + ".ply")
                limn.write_ply(os.path.join(folder, rel), value["vertex_positions"], value["faces"])
                shape["type"] = "ply"
            shape["filename"] = rel
            out[key] = shape
        else:
            out[key] = value
    path = os.path.join(folder, name + ".json")
    with open(path, "w") as f:
        json.dump(out, f, indent=2, default=lambda a: a.tolist())
    return path


def _write_obj(path: str, positions, faces, corner_uvs) -> None:
    # %.9g round-trips float32 values.
    with open(path, "w") as f:
        f.write("# written by limn's Blender exporter\n")
        f.writelines(f"v {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in positions)
        f.writelines(f"vt {u:.9g} {v:.9g}\n" for u, v in corner_uvs.reshape(-1, 2))
        for t, (a, b, c) in enumerate(faces):
            f.write(f"f {a + 1}/{3 * t + 1} {b + 1}/{3 * t + 2} {c + 1}/{3 * t + 3}\n")
