"""limn for Blender: render the scene with the limn differentiable renderer and optimise a mesh
(its vertices, its heights as a limn heightfield, or a signed-distance grid voxelised from it) or
a curve object (the control points and radii of a round-bevelled Curve or of hair Curves, as limn
fibre curves) so that its renders match target images.

Registers as a legacy add-on in Blender 3.x (bl_info) and as an extension in 4.2+
(blender_manifest.toml). Scripts can call ``render(...)`` and ``export_scene(...)`` directly."""

bl_info = {
    "name": "limn",
    "author": "limn developers",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "Properties > Render > limn",
    "description": "Render and optimise geometry with the limn differentiable renderer",
    "category": "Render",
}

import bpy

from . import exporter, jobs, optimize_ops, render_ops
from .exporter import export_scene, write_scene
from .optimize_ops import optimize
from .render_ops import render, load_blender_scene

__all__ = ["render", "optimize", "export_scene", "write_scene", "load_blender_scene"]


class LimnPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    module_path: bpy.props.StringProperty(
        name="limn module folder", subtype="DIR_PATH",
        description="Folder that contains the 'limn' Python package, if it is neither bundled nor importable")

    def draw(self, context):
        self.layout.prop(self, "module_path")


class LimnSettings(bpy.types.PropertyGroup):
    spp: bpy.props.IntProperty(name="Samples", default=64, min=1, description="Samples per pixel")
    seed: bpy.props.IntProperty(name="Seed", default=0, min=0)
    max_depth: bpy.props.IntProperty(name="Max depth", default=0, min=0,
                                     description="Longest path in segments; 0 uses Cycles' max bounces + 2")
    image_name: bpy.props.StringProperty(name="Image", default="limn render")
    # Optimisation
    optimize_object: bpy.props.PointerProperty(name="Object", type=bpy.types.Object, poll=lambda self, o: o.type in ("MESH", "CURVE", "CURVES"))
    targets: bpy.props.CollectionProperty(type=optimize_ops.LimnTarget)
    iterations: bpy.props.IntProperty(name="Iterations", default=50, min=1)
    learning_rate: bpy.props.FloatProperty(name="Learning rate", default=0.01, min=1e-6, precision=4)
    large_steps_lambda: bpy.props.FloatProperty(name="Large-Steps lambda", default=20.0, min=0.0)
    optimize_mode: bpy.props.EnumProperty(
        name="Optimise", default="AUTO",
        items=[("AUTO", "Detect", "Heights for objects marked as limn heightfields and meshes with an image Displace "
                                  "modifier; control points for curve and hair curves objects; vertices otherwise"),
               ("MESH", "Mesh vertices", "Move the mesh's vertices"),
               ("HEIGHTFIELD", "Heightfield", "Optimise heights: the image of a plane's Displace modifier, or the z of "
                                              "a regular grid mesh"),
               ("SDF", "Signed distance grid", "Voxelise the closed mesh into a limn SDF, optimise the grid and write "
                                               "it back as a mesh (marching cubes; replaces the mesh's vertices and faces)"),
               ("CURVE", "Curve control points", "Control points and radii of a curve (round bevel) or hair curves "
                                                 "object, as limn fibre curves")])
    sdf_resolution: bpy.props.IntProperty(
        name="SDF resolution", default=32, min=2, max=1024, soft_max=128,
        description="SDF mode: grid samples along the mesh's longest side (cubic voxels); memory and time grow with its cube")
    sdf_padding: bpy.props.FloatProperty(
        name="SDF padding", default=0.1, min=0.0, max=10.0,
        description="SDF mode: room around the mesh inside the grid, as a share of its longest side (the shape cannot "
                    "grow beyond the grid)")
    sdf_learning_rate: bpy.props.FloatProperty(
        name="SDF learning rate", default=optimize_ops.sdf.LEARNING_RATE, min=1e-6, precision=3,
        description="SDF mode: Adam's step size in voxels per iteration (the grid values move by about this many "
                    "voxel sizes per step)")
    sdf_smoothing: bpy.props.FloatProperty(
        name="SDF smoothing", default=optimize_ops.sdf.SMOOTHING, min=0.0,
        description="SDF mode: lambda (voxels squared) of the Sobolev preconditioner (I + lambda L)^-1 on the grid's "
                    "gradient (Large Steps on a grid); 0: the raw gradient")
    sdf_redistance_every: bpy.props.IntProperty(
        name="Redistance every", default=optimize_ops.sdf.REDISTANCE_EVERY, min=0,
        description="SDF mode: iterations between redistancings of the grid (a brute-force distance transform that "
                    "keeps it a signed distance field); 0: never")
    mask_vertex_group: bpy.props.StringProperty(
        name="Mask group", description="Heightfield of a grid mesh: heights of vertices with zero weight (or outside "
                                       "the group) stay fixed")
    mask_image: bpy.props.PointerProperty(
        name="Mask image", type=bpy.types.Image,
        description="Heightfield: heights stay fixed where this image (columns x rows of the heights) is zero")


class LIMN_PT_render(bpy.types.Panel):
    bl_label = "limn"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"

    def draw(self, context):
        s = context.scene.limn
        col = self.layout.column()
        col.prop(s, "spp")
        col.prop(s, "seed")
        col.prop(s, "max_depth")
        col.prop(s, "image_name")
        col.operator(render_ops.LIMN_OT_render.bl_idname, icon="RENDER_STILL")
        for job in jobs.running():
            if isinstance(job, render_ops.RenderJob):
                row = col.row()
                row.label(text=f"Rendering into '{job.image_name}': {job.status_text or 'starting'}", icon="TIME")
                row.operator(optimize_ops.LIMN_OT_stop.bl_idname, icon="CANCEL").job = job.label
        col.operator(render_ops.LIMN_OT_export.bl_idname, icon="EXPORT")
        box = self.layout.box()
        box.label(text="Optimise geometry")
        box.prop(s, "optimize_object")
        box.prop(s, "optimize_mode")
        obj = s.optimize_object
        if obj is not None and obj.type == "MESH":
            box.prop(obj, "limn_heightfield")
        if s.optimize_mode == "SDF":
            box.prop(s, "sdf_resolution")
            box.prop(s, "sdf_padding")
        elif s.optimize_mode not in ("MESH", "CURVE") and (obj is None or obj.type == "MESH"):
            if obj is not None:
                box.prop_search(s, "mask_vertex_group", obj, "vertex_groups")
            box.prop(s, "mask_image")
        for t in s.targets:
            row = box.row()
            row.prop(t, "camera", text="")
            row.prop(t, "image", text="")
            row.prop(t, "light_collection", text="", icon="LIGHT")  # empty: all lights
        box.operator(optimize_ops.LIMN_OT_target_add.bl_idname, icon="ADD")
        box.prop(s, "iterations")
        if s.optimize_mode == "SDF":  # its own step (voxels), smoothing and redistancing; no Large Steps
            box.prop(s, "sdf_learning_rate")
            box.prop(s, "sdf_smoothing")
            box.prop(s, "sdf_redistance_every")
        else:
            box.prop(s, "learning_rate")
            box.prop(s, "large_steps_lambda")
        running = optimize_ops._running_on(s)
        if running is not None:
            row = box.row()
            row.label(text=f"Running: {running.status_text or 'starting'}", icon="TIME")
            row.operator(optimize_ops.LIMN_OT_stop.bl_idname, icon="CANCEL").job = running.label
        box.operator(optimize_ops.LIMN_OT_optimize.bl_idname, icon="MOD_SMOOTH")


_classes = (LimnPreferences, optimize_ops.LimnTarget, LimnSettings, render_ops.LIMN_OT_render, render_ops.LIMN_OT_export,
            optimize_ops.LIMN_OT_target_add, optimize_ops.LIMN_OT_optimize, optimize_ops.LIMN_OT_stop, LIMN_PT_render)


# ---- what stops the jobs (jobs.py): file load, undo, add-on disable, Python's exit; save writes ------
@bpy.app.handlers.persistent
def _limn_load_pre(*_args):
    """Before any file load (File > New, Open, Revert, a script): the jobs' data is going away.
    Blender then cancels the modal operators (cancel()), which report; the jobs are forgotten
    here too, for jobs that scripts started."""
    jobs.stop_all("a file is being loaded (File > New, Open, Revert or a script)")
    for job in jobs.running():
        job.forget()


@bpy.app.handlers.persistent
def _limn_undo_pre(*_args):
    """Undo / redo replaces the datablocks an optimisation writes into: it stops, writing nothing more."""
    jobs.stop_all("undo or redo during the run", kinds=(optimize_ops.OptimizeJob,))


@bpy.app.handlers.persistent
def _limn_save_pre(*_args):
    """Saving during an optimisation saves its latest state: written into the object now (a
    heightfield image is packed). A render that is still running saves nothing of itself."""
    for job in jobs.running():
        if isinstance(job, optimize_ops.OptimizeJob):
            it = job.write_latest()
            if it is not None:
                jobs.log(f"limn: the file is saved with the state of iteration {it + 1} of the {job.label}")


_HANDLERS = (("load_pre", _limn_load_pre), ("undo_pre", _limn_undo_pre), ("redo_pre", _limn_undo_pre),
             ("save_pre", _limn_save_pre))


def _remove_handlers():
    """Removes this add-on's handlers, also those of an earlier load of the module (by name)."""
    names = {f.__name__ for _, f in _HANDLERS}
    for event, _ in _HANDLERS:
        handlers = getattr(bpy.app.handlers, event)
        for f in list(handlers):
            if getattr(f, "__name__", "") in names and getattr(f, "__module__", "") == __name__:
                handlers.remove(f)


def register():
    for c in _classes:
        bpy.utils.register_class(c)
    _remove_handlers()
    for event, f in _HANDLERS:
        getattr(bpy.app.handlers, event).append(f)
    jobs.register()
    bpy.types.Scene.limn = bpy.props.PointerProperty(type=LimnSettings)
    bpy.types.Object.limn_heightfield = bpy.props.BoolProperty(
        name="limn heightfield", default=False,
        description="Render and optimise this mesh as a limn heightfield (a plane with an image Displace modifier, "
                    "or a regular grid mesh)")


def unregister():
    jobs.unregister()  # stops and waits for every running job first
    _remove_handlers()
    del bpy.types.Object.limn_heightfield
    del bpy.types.Scene.limn
    for c in reversed(_classes):
        bpy.utils.unregister_class(c)
