"""Builds the small test scene with bpy: a UV sphere over a plane under an area light, seen by
one camera. Used by the add-on tests and by the Cycles comparison in docs/performance.md."""
from __future__ import annotations

import math

import bpy


def _principled(name, colour, roughness=0.5, metallic=0.0):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    node = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    node.inputs["Base Color"].default_value = (*colour, 1.0)
    node.inputs["Roughness"].default_value = roughness
    node.inputs["Metallic"].default_value = metallic
    return mat


def build_sphere_over_plane(width=64, height=48, reset=True):
    """reset=False builds into the current (empty) file, e.g. in a window after the caller's own
    read_factory_settings (which leaves a timer's context without a window)."""
    if reset:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100

    bpy.ops.mesh.primitive_plane_add(size=6.0, location=(0, 0, 0))
    plane = bpy.context.active_object
    plane.name = "floor"
    plane.data.materials.append(_principled("floor_mat", (0.6, 0.6, 0.6)))

    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=0.8, location=(0, 0, 1.0))
    sphere = bpy.context.active_object
    sphere.name = "ball"
    bpy.ops.object.shade_smooth()
    sphere.data.materials.append(_principled("ball_mat", (0.8, 0.2, 0.1)))

    bpy.ops.object.light_add(type="AREA", location=(1.0, -1.0, 4.0))
    light = bpy.context.active_object
    light.name = "lamp"
    light.data.energy = 400.0
    light.data.size = 1.5

    bpy.ops.object.camera_add(location=(0.0, -6.0, 3.0))
    cam = bpy.context.active_object
    cam.name = "camera"
    cam.rotation_euler = (math.radians(65.0), 0.0, 0.0)
    cam.data.lens = 35.0
    scene.camera = cam

    world = bpy.data.worlds.new("world")
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.05, 0.06, 0.08, 1.0)
    bg.inputs["Strength"].default_value = 1.0
    scene.world = world
    return scene


def _diffuse(name, colour):
    """A material whose surface is a plain Diffuse BSDF node (the same model in Cycles and limn)."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    for n in list(nodes):
        if n.type != "OUTPUT_MATERIAL":
            nodes.remove(n)
    out = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (*colour, 1.0)
    links.new(diffuse.outputs["BSDF"], out.inputs["Surface"])
    return mat


def build_cornell(size=256, max_depth=8):
    """A Cornell box with a sphere and a box, diffuse materials and one area light (the scene of
    the Cycles comparison in docs/performance.md)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    white, red, green = (_diffuse("white", (0.725, 0.71, 0.68)), _diffuse("red", (0.63, 0.065, 0.05)),
                         _diffuse("green", (0.14, 0.45, 0.091)))
    walls = {"floor": ((0, 0, -1), (0, 0, 0), white), "ceiling": ((0, 0, 1), (math.pi, 0, 0), white),
             "back": ((0, 1, 0), (math.pi / 2, 0, 0), white), "left": ((-1, 0, 0), (0, math.pi / 2, 0), red),
             "right": ((1, 0, 0), (0, -math.pi / 2, 0), green)}
    for name, (loc, rot, mat) in walls.items():
        bpy.ops.mesh.primitive_plane_add(size=2.0, location=loc, rotation=rot)
        obj = bpy.context.active_object
        obj.name = name
        obj.data.materials.append(mat)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=0.4, location=(-0.4, 0.3, -0.6))
    ball = bpy.context.active_object
    ball.name = "ball"
    bpy.ops.object.shade_smooth()
    ball.data.materials.append(white)
    bpy.ops.mesh.primitive_cube_add(size=0.6, location=(0.45, -0.1, -0.7), rotation=(0, 0, math.radians(20)))
    box = bpy.context.active_object
    box.name = "box"
    box.data.materials.append(white)
    bpy.ops.object.light_add(type="AREA", location=(0, 0, 0.98))
    lamp = bpy.context.active_object
    lamp.name = "lamp"
    lamp.data.size = 0.5
    lamp.data.energy = 30.0
    bpy.ops.object.camera_add(location=(0, -3.9, 0), rotation=(math.pi / 2, 0, 0))
    cam = bpy.context.active_object
    cam.data.sensor_fit = "HORIZONTAL"
    cam.data.angle = math.radians(39.3077)
    scene.camera = cam
    scene.world = None
    cycles = scene.cycles
    # Cycles' bounces are limn's max_depth - 2 (max_bounces = 0 is direct lighting).
    cycles.max_bounces = cycles.diffuse_bounces = cycles.glossy_bounces = cycles.transmission_bounces = max_depth - 2
    return scene


def bumps(n=17):
    """Ground-truth heights for the heightfield tests: a smooth bump, rows x columns with row 0 the
    far edge (limn's heightfield order)."""
    import numpy as np
    x = np.linspace(-1.0, 1.0, n)
    X, Y = np.meshgrid(x, -x)
    return np.exp(-(X ** 2 + Y ** 2) / (2 * 0.35 ** 2)).astype(np.float32)


def _look_at(obj, target):
    from mathutils import Vector
    direction = Vector(target) - obj.location
    obj.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()


def build_heightfield(kind="displace", n=17, res=24):
    """A heightfield scene: kind "displace" is a 2 x 2 plane with a Subdivision (simple) and a Displace
    modifier reading the float image "heights" (n x n, mid-level 0.5, strength 0.5: flat at 0.5);
    kind "grid" is an n x n vertex grid of size 2 (flat). Two cameras ("cam_front", "cam_side",
    res x res pixels) look at it under an area light ("lamp", aimed at the origin from a low angle)
    and a grey world; 1 bounce (limn max_depth 3). Returns the scene."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = res
    scene.render.resolution_percentage = 100
    if getattr(scene, "cycles", None) is not None:
        scene.cycles.max_bounces = 1
    if kind == "displace":
        bpy.ops.mesh.primitive_plane_add(size=2.0)
        obj = bpy.context.active_object
        obj.name = "terrain"
        obj.modifiers.new("subdivide", "SUBSURF").subdivision_type = "SIMPLE"
        obj.modifiers["subdivide"].levels = obj.modifiers["subdivide"].render_levels = 4
        img = bpy.data.images.new("heights", n, n, float_buffer=True)
        img.pixels.foreach_set([0.5] * (n * n * 4))
        tex = bpy.data.textures.new("heights", "IMAGE")
        tex.image = img
        mod = obj.modifiers.new("displace", "DISPLACE")
        mod.texture, mod.texture_coords, mod.direction = tex, "UV", "NORMAL"
        mod.strength, mod.mid_level = 0.5, 0.5
    else:
        bpy.ops.mesh.primitive_grid_add(x_subdivisions=n - 1, y_subdivisions=n - 1, size=2.0)
        obj = bpy.context.active_object
        obj.name = "terrain"
        assert len(obj.data.vertices) == n * n, len(obj.data.vertices)  # subdivisions are cuts since 3.0
    obj.data.materials.append(_diffuse("terrain_mat", (0.6, 0.6, 0.6)))

    bpy.ops.object.light_add(type="AREA", location=(2.0, 0.5, 1.2))
    lamp = bpy.context.active_object
    lamp.name = "lamp"
    lamp.data.size = 1.0
    lamp.data.energy = 60.0  # radiance 60 / (4 * 1 m^2) = 15 in limn
    _look_at(lamp, (0, 0, 0))
    for name, loc in (("cam_front", (0.0, -2.5, 2.5)), ("cam_side", (2.5, 0.0, 2.5))):
        bpy.ops.object.camera_add(location=loc)
        cam = bpy.context.active_object
        cam.name = name
        cam.data.lens = 43.5  # about 45 degrees across the 36 mm sensor
        _look_at(cam, (0, 0, 0))
    scene.camera = bpy.data.objects["cam_front"]
    world = bpy.data.worlds.new("world")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.1, 0.1, 0.1, 1.0)
    scene.world = world
    return scene


def add_curve(name, kind, points, radii, bevel, order=4, cyclic=False, material=True):
    """A legacy Curve object (3D, round bevel of depth `bevel`) with one spline of `kind` (NURBS,
    POLY or BEZIER with automatic handles) on / through `points` (n x 3) with point radii `radii`."""
    cu = bpy.data.curves.new(name, "CURVE")
    cu.dimensions = "3D"
    cu.bevel_depth = bevel
    sp = cu.splines.new(kind)
    if kind == "BEZIER":
        sp.bezier_points.add(len(points) - 1)
        for p, co, r in zip(sp.bezier_points, points, radii):
            p.co, p.radius = tuple(co), float(r)
            p.handle_left_type = p.handle_right_type = "AUTO"
    else:
        sp.points.add(len(points) - 1)
        for p, co, r in zip(sp.points, points, radii):
            p.co, p.radius = (*co, 1.0), float(r)
        if kind == "NURBS":
            sp.order_u = order
            sp.use_endpoint_u = sp.use_bezier_u = False
    sp.use_cyclic_u = cyclic
    obj = bpy.data.objects.new(name, cu)
    bpy.context.scene.collection.objects.link(obj)
    if material:
        cu.materials.append(bpy.data.materials.new(f"{name}_mat"))
    return obj
