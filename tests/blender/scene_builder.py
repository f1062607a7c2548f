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


def build_sphere_over_plane(width=64, height=48):
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
