"""Shape optimisation from Blender: move a mesh object's vertices until limn's renders from the
given cameras match target images, then write the vertices back (one undo step).

Script use (also headless):
    limn_blender.optimize(obj, [(camera, image_or_path), ...], iterations=50)
A target may also name a light set-up, a Blender collection: (camera, image, collection). Only the
light objects (type LIGHT) in that collection (or its child collections) light that target's
render; with no collection (None, or a pair) every light of the scene does. Meshes with emissive
materials and the world light every target. So one camera can have several targets, e.g. the same
field under a morning and an evening light:
    limn_blender.optimize(obj, [(cam, morning_img, morning), (cam, evening_img, evening)])
In the UI (Properties > Render > limn > Optimise) the loop runs on a worker thread (the C++ calls
release the GIL); a timer shows progress and the loss, writes the mesh back every few iterations
and at the end, and Esc cancels, keeping the last state. In background mode the operator runs the
same loop blocking and prints progress.

Heightfield mode optimises the heights of a limn heightfield instead (heightfield.py): a plane with
an image Displace modifier (the heights go back into the image, a float image packed into the
.blend) or a regular grid mesh (the heights go back into the vertices' z). Mode "AUTO" picks it for
objects marked as limn heightfields and for meshes with an image Displace modifier. A vertex group
(grid meshes) or a mask image can hold heights fixed where they are zero.
    limn_blender.optimize(plane, [(camera, image), ...], mode="HEIGHTFIELD", mask_image=img)

SDF mode (sdf.py) voxelises a closed mesh into a limn signed-distance grid (`sdf_resolution`
samples along its longest side), optimises the grid's values and writes the result back into the
mesh by marching cubes (its vertices and faces are replaced; one undo step restores them). Its
learning rate is in voxels per iteration (default sdf.LEARNING_RATE), the gradient is smoothed
(`sdf_smoothing`, voxels^2) and the grid redistanced every `sdf_redistance_every` iterations.
    limn_blender.optimize(obj, [(camera, image), ...], mode="SDF", sdf_resolution=32)

Curve mode optimises the control points and radii of a curve object's limn fibre curves
(curves.py): a legacy Curve with a round bevel (NURBS, poly and Bezier splines) or a hair Curves
object. Mode "AUTO" picks it for both object types. The result goes back into the same object
type with the same point counts. Radii are clamped after every step to at least 1/100 of the
smallest starting radius (curves.RADIUS_FLOOR); Large Steps (lambda) is not used for curves.
    limn_blender.optimize(curve_obj, [(camera, image), ...])"""
from __future__ import annotations

import threading
import time

import bpy
import numpy as np

from . import curves, exporter, heightfield, jobs, sdf
from .render_ops import _limn, end_worker, redraw_panels, start_modal


def _target_pixels(target, width: int, height: int, limn) -> np.ndarray:
    """The target as (H, W, 3) linear floats. Refuses, naming the image, a target without pixels
    (e.g. a missing file) and a constant one (e.g. a generated image that was not packed and came
    back black after a save and reopen), which cannot guide the optimisation."""
    if isinstance(target, str):
        what = f"target image file '{target}'"
        img = limn.read_image(bpy.path.abspath(target))
    else:  # an image datablock (stored bottom row first, RGBA)
        what = f"target image '{target.name}'"
        w, h = target.size
        if w == 0 or h == 0:
            where = f" (file '{target.filepath}' missing?)" if target.source == "FILE" and not target.packed_file else ""
            raise ValueError(f"{what} has no pixels{where}; load or render it again")
        px = np.empty(w * h * target.channels, dtype=np.float32)
        target.pixels.foreach_get(px)
        px = px.reshape(h, w, target.channels)
        img = (px[::-1, :, :3] if target.channels >= 3 else np.repeat(px[::-1, :, :1], 3, axis=2)).copy()
        if not target.is_float:  # byte images hold sRGB-encoded colours
            img = np.where(img <= 0.04045, img / 12.92, ((img + 0.055) / 1.055) ** 2.4).astype(np.float32)
    if img.shape[:2] != (height, width):
        raise ValueError(f"{what} is {img.shape[1]}x{img.shape[0]}, the render resolution is {width}x{height}")
    if img.size and (img == img[0, 0]).all():
        c = ", ".join(f"{v:.3g}" for v in img[0, 0])
        raise ValueError(f"{what} is constant (every pixel is ({c})), so there is nothing to fit; if it was a "
                         "generated image that was not packed, it came back blank after a save: render or load "
                         "it again (limn packs its renders into the .blend)")
    return img


def _unsaved(image) -> bool:
    """A generated image that is not packed: its pixels are not saved with the .blend."""
    return not isinstance(image, str) and image.source == "GENERATED" and image.packed_file is None


MODES = ("AUTO", "MESH", "HEIGHTFIELD", "SDF", "CURVE")
CURVE_TYPES = ("CURVE", "CURVES")
# What each object type's data is called in messages and in bpy.data.
_DATA = {"MESH": ("mesh", "meshes"), "CURVE": ("curve", "curves"), "CURVES": ("hair curves", "hair_curves")}


def data_key(obj) -> tuple[str, int]:
    """(kind, address) of the datablock an optimisation of `obj` writes (one job per datablock)."""
    return _DATA.get(obj.type, ("data", ""))[0], obj.data.as_pointer()


def _unpack_target(i: int, entry):
    """(camera, image, light collection or None) from a target entry: (camera, image) or
    (camera, image, collection)."""
    try:
        items = tuple(entry)
    except TypeError:
        items = ()
    if len(items) not in (2, 3):
        raise ValueError(f"target {i + 1}: give (camera, image) or (camera, image, light collection), got {entry!r}")
    cam, image = items[:2]
    lights = items[2] if len(items) == 3 else None
    if lights is not None and not isinstance(lights, bpy.types.Collection):
        raise ValueError(f"target {i + 1}: the light set-up must be a Blender collection or None "
                         f"(got {type(lights).__name__})")
    return cam, image, lights


def _check_light_setup(i: int, cam, image, lights) -> None:
    """A chosen light collection must hold at least one light object that renders."""
    if lights is None:
        return
    found = exporter.light_objects(lights)
    if any(not o.hide_render for o in found):
        return
    what = f"target {i + 1} (camera '{getattr(cam, 'name', cam)}', image '{getattr(image, 'name', image)}')"
    if found:
        raise ValueError(f"{what}: the lights of light collection '{lights.name}' "
                         f"({', '.join(o.name for o in found)}) are all disabled in renders")
    raise ValueError(f"{what}: light collection '{lights.name}' holds no light objects; add lights to it "
                     "or clear the field to use all lights of the scene")


def resolve_mode(obj, mode: str) -> str:
    """Returns "MESH", "HEIGHTFIELD", "SDF" or "CURVE" for the object and the chosen mode (one of
    MODES; "AUTO" never picks "SDF")."""
    if mode not in MODES:
        raise ValueError(f"optimisation mode must be one of {', '.join(MODES)} (got {mode!r})")
    is_curve = obj.type in CURVE_TYPES
    if mode not in ("AUTO", "CURVE") and is_curve:
        raise ValueError(f"object '{obj.name}' is a {'hair curves' if obj.type == 'CURVES' else 'curve'} object; "
                         f"choose the curve mode (or Detect) to optimise its control points (got {mode})")
    if mode == "CURVE" and not is_curve:
        raise ValueError(f"object '{obj.name}' is a {obj.type.lower()} object; the curve mode optimises Curve and "
                         "hair Curves objects")
    if mode != "AUTO":
        return mode
    if is_curve:
        return "CURVE"
    marked = getattr(obj, "limn_heightfield", False)
    return "HEIGHTFIELD" if marked or heightfield.has_image_displace(obj) else "MESH"


class Problem:
    """The optimisation problem built from the Blender scene (main thread only): the limn scene and
    target per camera, the parameter `name`, the Large-Steps `faces`, the `mask` (or None), the
    `project` applied after each step (or None) and write_back(x) for the mesh vertices, the
    heightfield's heights, the SDF grid's values or the curves' control points. prepare() (any
    thread; SDF mode voxelises there) must run before the views are used."""

    def __init__(self, obj, targets, spp: int, mode: str = "AUTO", mask_vertex_group: str = "", mask_image=None,
                 sdf_resolution: int = 32, sdf_padding: float = 0.1, sdf_smoothing: float = sdf.SMOOTHING,
                 sdf_redistance_every: int = sdf.REDISTANCE_EVERY):
        if obj is None or obj.type not in ("MESH", *CURVE_TYPES):
            raise ValueError("choose a mesh, curve or hair curves object to optimise")
        if not targets:
            raise ValueError("give at least one (camera, target image) pair")
        targets = [_unpack_target(i, t) for i, t in enumerate(targets)]
        for i, (cam, image, lights) in enumerate(targets):
            _check_light_setup(i, cam, image, lights)
        self.mode = resolve_mode(obj, mode)
        if self.mode == "MESH" and getattr(obj, "limn_heightfield", False):
            raise ValueError(f"object '{obj.name}' is marked as a limn heightfield; choose the heightfield mode or "
                             "clear the mark to optimise its vertices")
        if self.mode in ("MESH", "SDF", "CURVE") and (mask_vertex_group or mask_image is not None):
            what = {"MESH": "mesh vertices", "SDF": "a signed-distance grid", "CURVE": "curve control points"}[self.mode]
            raise ValueError(f"object '{obj.name}' is optimised as {what}; masks (vertex group, mask image) "
                             "are for the heightfield mode")
        self.limn = _limn()
        self.obj = obj
        self.vertex_count = len(obj.data.vertices) if obj.type == "MESH" else 0
        self.project = self.gradient = None
        if self.mode == "CURVE":
            self._check_curve_object(obj)
        self.curves = curves.Source(obj) if self.mode == "CURVE" else None  # refuses what it cannot write back
        if self.curves is not None:  # refuses a transform the tubes cannot follow (non-uniform scale)
            self.curves.world_control(np.array([list(row) for row in obj.matrix_world]))
        self.warnings = [f"target image '{image.name}' is a generated image that is not packed: it is lost when "
                         "the file is saved (Image > Pack keeps it)" for _, image, _ in targets if _unsaved(image)]
        # Heights and mask first: a non-grid mesh, a bad Displace set-up or mask fails before any export.
        self.source = heightfield.Source(obj) if self.mode == "HEIGHTFIELD" else None
        self.mask = self.source.mask(mask_vertex_group, mask_image) if self.source else None
        # SDF: the world-space triangles now; voxelised in prepare() (on the worker thread).
        self.sdf = sdf.SdfSource(obj, sdf_resolution, sdf_padding, sdf_smoothing, sdf_redistance_every) \
            if self.mode == "SDF" else None
        self.prepare_fraction = 0.0
        scene = bpy.context.scene
        saved_camera = scene.camera
        self.views = []
        self._pending = []  # SDF: (description, source, target) per view, loaded in prepare()
        try:
            for cam, target, lights in targets:
                if cam is None or cam.type != "CAMERA":
                    raise ValueError(f"'{getattr(cam, 'name', cam)}' is not a camera")
                scene.camera = cam
                desc, _ = exporter.export_scene(scene, spp=spp, heightfields={obj.name} if self.source else (),
                                                light_collection=lights)
                if obj.name not in desc:
                    raise ValueError(f"object '{obj.name}' was not exported as one shape (hidden, or several materials?)")
                shape = desc[obj.name]
                lit = f" lights '{lights.name}'" if lights is not None else ""
                r = scene.render
                w, h = int(r.resolution_x * r.resolution_percentage / 100), int(r.resolution_y * r.resolution_percentage / 100)
                pixels = _target_pixels(target, w, h, self.limn)
                source = f"blender '{scene.name}' camera '{cam.name}'{lit}"
                if self.sdf is not None:
                    if "emitter" in shape:
                        raise ValueError(f"object '{obj.name}': its material emits light, and a limn SDF cannot be "
                                         "an area emitter")
                    if shape.get("type") != "mesh":
                        raise ValueError(f"object '{obj.name}' is exported as a limn {shape.get('type')}, not a mesh; "
                                         "clear its limn heightfield mark to optimise it as an SDF")
                    self._pending.append((desc, source, pixels))
                    continue
                self.views.append((self.limn.load_dict(desc, source=source), pixels))
        finally:
            scene.camera = saved_camera
        if self.sdf is not None:
            self.name = f"{obj.name}.data"
            self._shape_id = obj.name  # prepare() runs on the worker thread and must not read bpy
            self.faces = None  # no Large Steps on a mesh: the grid's own smoothing is the gradient hook
            self.gradient = lambda g: self.sdf.gradient(self.limn, g)
            self.project = lambda x: self.sdf.project(self.limn, x)
            self._refs = self._make_refs()
            return
        if self.source is not None:
            src = self.source
            self.name = f"{obj.name}.heights"
            self.faces = self.limn.optim.grid_faces(src.rows, src.columns)
            self._refs = self._make_refs()
            return
        self.world = np.array([list(row) for row in obj.matrix_world], dtype=np.float64)
        if self.curves is not None:
            if shape.get("type") != "bsplinecurve":
                raise ValueError(f"object '{obj.name}' was not exported as limn fibre curves")
            self.name = f"{obj.name}.control_points"
            self.faces = None
            self.counts = self.curves.counts()
            self.project = lambda x: self.curves.project(x, self.world)
            self.gradient = self.curves.gradient
            self.warnings += self.curves.warnings
            self._refs = self._make_refs()
            return
        self.faces = shape["faces"]
        self.name = f"{obj.name}.vertex_positions"
        n = len(obj.data.vertices)
        welded = self.views[0][0].params[self.name]
        if len(shape["vertex_positions"]) != n or len(welded) != n:
            raise ValueError(f"object '{obj.name}': its modifiers change the vertices or it has coincident vertices "
                             f"({n} in the mesh, {len(welded)} rendered); apply or remove them before optimising")
        self._refs = self._make_refs()

    def prepare(self, progress=None) -> None:
        """SDF mode: voxelises the mesh (progress(fraction) may return False to cancel: limn raises
        RenderCancelled) and loads the views with the grid in place of the mesh. Needs no bpy, so
        it runs on the worker thread; a no-op in the other modes and when already done."""
        if not self._pending:
            return
        def report(fraction):
            self.prepare_fraction = fraction
            return True if progress is None else progress(fraction)
        self.sdf.voxelise(self.limn, report)
        for desc, source, pixels in self._pending:
            desc = dict(desc)
            desc[self._shape_id] = self.sdf.shape(desc[self._shape_id])
            self.views.append((self.limn.load_dict(desc, source=source), pixels))
        self._pending = []

    def step_size(self, lr: float) -> float:
        """The optimiser's learning rate: SDF mode takes lr in voxels per iteration (after prepare())."""
        return self.sdf.step_size(lr) if self.sdf is not None else lr

    @staticmethod
    def _check_curve_object(obj) -> None:
        """Refuses a curve object whose render is not its own control points: a legacy curve that is
        not a round bevel tube (exported as a mesh), a hair object whose modifiers move its points."""
        if obj.type == "CURVE":
            why = curves.fibre_reason(obj)
            if why:
                raise ValueError(f"curve object '{obj.name}' is not rendered as limn fibre curves: {why}; limn "
                                 "optimises curves with a round bevel (bevel depth > 0) and no modifiers")
            if not getattr(obj.data, "use_radius", True):
                raise ValueError(f"curve object '{obj.name}': its option Radius (Geometry) is off, so Blender's tube "
                                 "ignores the point radii the optimisation writes; turn it on")
            return
        evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
        here = curves.Source(obj).control
        there = curves.Source(obj, evaluated).control
        if here.shape != there.shape or not np.array_equal(here, there):
            raise ValueError(f"hair object '{obj.name}': its modifiers change its points, so optimised points cannot "
                             "be written back into them; apply or disable the modifiers first")

    # ---- the datablocks the run writes: still there, still the same? ---------------------------------
    def _make_refs(self):
        """(bpy.data collection, name, address, kind) of what write_back writes into."""
        kind, coll = _DATA[self.obj.type]
        blocks = [("objects", self.obj, "object"), (coll, self.obj.data, kind)]
        if self.source is not None and self.source.kind == "displace":
            blocks += [("textures", self.source.texture, "texture"), ("images", self.source.image, "image")]
        return [(coll, b.name, b.as_pointer(), kind) for coll, b, kind in blocks]

    @property
    def keys(self) -> set:
        """What a job on this problem holds: no other job may write the same object, mesh or image."""
        return {(kind, ptr) for _, _, ptr, kind in self._refs}

    def check(self) -> str:
        """"" when the object (and its mesh, or displacement texture and image) the run writes are
        still the ones it started with, in a scene and in Object Mode; then the Python references
        are refreshed from bpy.data. Otherwise why not: deleted, renamed, replaced (undo, file
        load), in Edit Mode, another mesh or vertex count. Main thread only; never touches a stale
        reference (a deleted datablock's memory may be freed)."""
        found = {}
        for coll, name, ptr, kind in self._refs:
            blocks = getattr(bpy.data, coll)
            block = blocks.get(name)
            if block is None or block.as_pointer() != ptr:
                renamed = next((b for b in blocks if b.as_pointer() == ptr), None)
                if renamed is not None:
                    return f"{kind} '{name}' was renamed to '{renamed.name}'"
                return f"{kind} '{name}' was deleted" + (" or replaced (undo?)" if block is not None else "")
            found[kind] = block
        kind = _DATA[self.obj.type][0]
        obj, mesh = found["object"], found[kind]
        name = obj.name
        if not obj.users_scene:
            return f"object '{name}' was deleted (it is in no scene any more)"
        if obj.data is None or obj.data.as_pointer() != mesh.as_pointer():
            return f"object '{name}' uses another {kind} now"
        if obj.mode == "EDIT" or getattr(mesh, "is_editmode", False):
            return f"object '{name}' entered Edit Mode (its {kind} is not written while it is edited)"
        if self.curves is not None:
            self.obj = self.curves.obj = obj
            if self.curves.counts() != self.counts:
                return f"{kind} '{mesh.name}' has other point counts now than at the start (points added or deleted)"
            return ""
        if self.sdf is None and (self.source is None or self.source.kind == "grid") and len(mesh.vertices) != self.vertex_count:
            return f"mesh '{mesh.name}' has {len(mesh.vertices)} vertices now ({self.vertex_count} at the start)"
        if self.source is not None and self.source.kind == "displace":
            m = heightfield.displace_modifier(obj)
            tex = getattr(m, "texture", None)
            if tex is None or tex.as_pointer() != found["texture"].as_pointer() or tex.image is None \
                    or tex.image.as_pointer() != found["image"].as_pointer():
                return f"the Displace modifier of object '{name}' no longer uses texture '{found['texture'].name}' " \
                       f"with image '{found['image'].name}'"
            self.source.texture, self.source.image = found["texture"], found["image"]
        self.obj = obj
        if self.source is not None:
            self.source.obj = obj
        if self.sdf is not None:
            self.sdf.obj = obj
        return ""

    def write_back(self, x: np.ndarray, final: bool = True) -> None:
        """Stores the parameter's value in Blender: world-space vertices into the mesh, heights
        into the displacement image (packed when `final`) / the grid's z, or the SDF grid as the
        mesh its marching cubes give."""
        if self.sdf is not None:
            self.sdf.write_back(self.limn, x)
            self.vertex_count = len(self.obj.data.vertices)
            return
        if self.source is not None:
            self.source.write_back(x, final=final)
            self._refs = self._make_refs()  # a new "<name> (limn)" image may have replaced the texture's
            return
        if self.curves is not None:
            self.curves.write_back(np.asarray(x, dtype=np.float64).reshape(-1, 4), self.world)
            return
        inv = np.linalg.inv(self.world)
        local = x.astype(np.float64) @ inv[:3, :3].T + inv[:3, 3]
        self.obj.data.vertices.foreach_set("co", local.astype(np.float32).ravel())
        self.obj.data.update()


def optimize(obj, targets, iterations: int = 50, spp: int = 8, lr: float | None = None, lambda_: float = 20.0,
             progress=None, mode: str = "AUTO", mask_vertex_group: str = "", mask_image=None,
             sdf_resolution: int = 32, sdf_padding: float = 0.1, sdf_smoothing: float = sdf.SMOOTHING,
             sdf_redistance_every: int = sdf.REDISTANCE_EVERY) -> dict:
    """Blocking optimisation; writes the result into the mesh (or the heightfield's image / grid,
    the SDF's marching cubes into the mesh, or the control points into the curve object).
    lr: world units per iteration (default 0.01), in SDF mode voxels per iteration (default
    sdf.LEARNING_RATE). progress(iteration, loss) may return False to stop. Returns {"losses": [...],
    "seconds": ..., "cancelled": ..., "mode": "MESH" | "HEIGHTFIELD" | "SDF" | "CURVE"}; SDF mode
    adds "sdf_shape" (nz, ny, nx), "voxel" (world units) and "redistanced" (how often)."""
    problem = Problem(obj, targets, spp, mode, mask_vertex_group, mask_image, sdf_resolution, sdf_padding,
                      sdf_smoothing, sdf_redistance_every)
    if lr is None:
        lr = sdf.LEARNING_RATE if problem.sdf is not None else 0.01
    running = jobs.busy(problem.keys)
    if running is not None:  # a job in the UI writes the same object
        raise jobs.JobBusy(running)
    problem.prepare()

    def callback(it, loss, x):
        return None if progress is None else progress(it, loss)

    t0 = time.perf_counter()
    result = problem.limn.optim.fit(problem.views, problem.name, iterations=iterations, lr=problem.step_size(lr),
                                    lambda_=lambda_, spp=spp,
                                    faces=problem.faces, mask=problem.mask, callback=callback,
                                    project=problem.project, gradient=problem.gradient)
    problem.write_back(problem.views[0][0].params[problem.name])
    out = {"losses": result.losses, "seconds": time.perf_counter() - t0, "cancelled": result.cancelled,
           "mode": problem.mode}
    if problem.sdf is not None:
        out.update(sdf_shape=tuple(problem.sdf.data.shape), voxel=problem.sdf.voxel, redistanced=problem.sdf.redistanced)
    return out


class _Cancellable:
    """A limn.Scene whose render / render_forward / render_backward calls get `keep_going` as their
    progress callback, so that a cancel stops limn.optim.fit inside an iteration (limn raises
    RenderCancelled) and not only between iterations. Everything else is the scene's own."""

    def __init__(self, scene, keep_going):
        self._scene, self._keep_going = scene, keep_going

    def __getattr__(self, name):
        return getattr(self._scene, name)

    def render(self, *args, **kwargs):
        return self._scene.render(*args, progress=self._keep_going, **kwargs)

    def render_forward(self, *args, **kwargs):
        return self._scene.render_forward(*args, progress=self._keep_going, **kwargs)

    def render_backward(self, *args, **kwargs):
        return self._scene.render_backward(*args, progress=self._keep_going, **kwargs)


class OptimizeJob(jobs.Job):
    """The background optimisation behind the modal operator. start() runs limn.optim.fit on a
    worker thread (which never touches bpy); poll(), on the main thread, reports progress and
    writes the latest vertices (or heights) into Blender every `write_every` iterations and when the
    run ends; cancel() stops within a tile of the current render, keeping the last state.

    Only one job may write an object (its mesh, its displacement image): start() raises
    jobs.JobBusy otherwise. Before every write poll() checks that the object is still the one the
    run started with (Problem.check); if it was deleted, renamed, replaced or put in Edit Mode, the
    run stops and nothing more is written. A job cancelled with discard=True (file load, undo,
    quit) writes nothing either."""

    def __init__(self, problem: Problem, iterations: int, spp: int, lr: float, lambda_: float, write_every: int = 5):
        super().__init__(keys=problem.keys)
        self.label = f"optimisation of '{problem.obj.name}'"
        self.problem, self.iterations, self.write_every = problem, iterations, write_every
        self._settings = (spp, lr, lambda_)
        self._lock = threading.Lock()
        self._state = {"it": -1, "loss": float("nan"), "x": None}
        self._written = -1
        self.writes = 0  # how often poll() wrote the result (progress shown in the viewport)
        self._end = None  # the final poll() result, once the end was handled

    def work(self) -> None:
        spp, lr, lambda_ = self._settings
        state, problem = self._state, self.problem

        def callback(it, loss, x):
            with self._lock:
                state["it"], state["loss"], state["x"] = it, loss, x.copy()
            return self.keep_going()

        try:
            problem.prepare(self.keep_going)  # SDF: voxelise here, off the main thread
            views = [(_Cancellable(scene, self.keep_going), target) for scene, target in problem.views]
            problem.limn.optim.fit(views, problem.name, iterations=self.iterations, spp=spp, lr=problem.step_size(lr),
                                   lambda_=lambda_,
                                   faces=problem.faces, mask=problem.mask, callback=callback, project=problem.project,
                                   gradient=problem.gradient)
        except problem.limn.RenderCancelled:
            if not self.cancelled:
                raise
            return  # stopped inside an iteration: the last good state is the callback's
        if not self.cancelled:
            with self._lock:
                state["x"] = problem.views[0][0].params[problem.name].copy()

    def _write(self, x, it, final) -> str:
        """Writes x if the object is still valid; returns why not ("" when written)."""
        why = self.problem.check()
        if why:
            return why
        try:
            self.problem.write_back(x, final=final)
        except ValueError as e:  # SDF: a grid without a surface has no mesh to write
            if self.error is None:
                self.error = e
            return str(e)
        self._written = it
        self.writes += 1
        return ""

    def write_latest(self) -> int | None:
        """Writes the latest state now, packing a heightfield image (before a save); returns its
        iteration, or None when nothing was written. Main thread."""
        with self._lock:
            it, x = self._state["it"], self._state["x"]
        if x is None or self.discard or self._end is not None:
            return None
        return it if self._write(x, it, final=True) == "" else None

    def poll(self) -> dict:
        """{"status": "running" | "finished" | "cancelled" | "stopped" | "error", "iteration",
        "loss", "message"}. "stopped": the object went away (or a file load, undo or quit ended
        the run); nothing was written after that."""
        if self._end is not None:
            return self._end
        done = self._thread is not None and not self._thread.is_alive()
        with self._lock:
            it, loss, x = self._state["it"], self._state["loss"], self._state["x"]
        progress = f"iteration {it + 1}/{self.iterations}, loss {loss:.6f}"
        if it < 0 and self.problem.sdf is not None:
            progress = f"voxelising the mesh ({100 * self.problem.prepare_fraction:.0f} %)"
        self.status_text = progress
        why = "" if self.discard else self.problem.check()
        if why:  # never write into what the run no longer owns; stop the worker now
            self.stop(why, timeout=30)
            done = not self.alive
        if self.discard and not why:
            why = self.stop_reason
        if why:
            if not done:
                return {"status": "running", "iteration": it, "loss": loss, "message": f"limn: stopping ({why})"}
            message = (f"limn: {self.label} stopped: {why}; " +
                       (f"the state of iteration {self._written + 1} was the last written" if self.writes
                        else "nothing was written"))
            return self._finish("stopped", it, loss, message)
        if x is not None and (done or it - self._written >= self.write_every):
            self._write(x, it, final=done)
        if not done:
            return {"status": "running", "iteration": it, "loss": loss, "message": f"limn: {progress} (Esc to cancel)"}
        if self.error is not None:
            return self._finish("error", it, loss, f"limn: {self.error}")
        if self.cancelled:
            return self._finish("cancelled", it, loss, f"limn: {progress}, cancelled ({self.stop_reason}); "
                                                       "the last state is kept")
        return self._finish("finished", it, loss, f"limn: {progress}")

    def _finish(self, status, it, loss, message) -> dict:
        self._end = {"status": status, "iteration": it, "loss": loss, "message": message}
        self.forget()
        return self._end


class LimnTarget(bpy.types.PropertyGroup):
    camera: bpy.props.PointerProperty(name="Camera", type=bpy.types.Object, poll=lambda self, o: o.type == "CAMERA")
    image: bpy.props.PointerProperty(name="Target", type=bpy.types.Image)
    light_collection: bpy.props.PointerProperty(
        name="Lights", type=bpy.types.Collection,
        description="Light set-up of this target: only the light objects in this collection (and its child "
                    "collections) light its render; empty: all lights of the scene. Emissive meshes and the world "
                    "light every target")


class LIMN_OT_target_add(bpy.types.Operator):
    """Add a target: camera, target image and an optional light collection"""
    bl_idname = "limn.target_add"
    bl_label = "Add target"

    def execute(self, context):
        t = context.scene.limn.targets.add()
        t.camera = context.scene.camera
        return {"FINISHED"}


def _learning_rate(s) -> float:
    """The panel's learning rate for its mode: SDF mode has its own, in voxels per iteration."""
    return s.sdf_learning_rate if s.optimize_mode == "SDF" else s.learning_rate


def _mode_inputs(s) -> dict:
    """The panel's mode and masks as keyword arguments of Problem / optimize (the panel hides the
    masks in mesh mode, so they are not passed then)."""
    obj = s.optimize_object
    if s.optimize_mode == "SDF":
        return {"mode": "SDF", "sdf_resolution": s.sdf_resolution, "sdf_padding": s.sdf_padding,
                "sdf_smoothing": s.sdf_smoothing, "sdf_redistance_every": s.sdf_redistance_every}
    if s.optimize_mode in ("MESH", "CURVE") or (obj is not None and obj.type in CURVE_TYPES):
        return {"mode": s.optimize_mode}
    return {"mode": s.optimize_mode, "mask_vertex_group": s.mask_vertex_group, "mask_image": s.mask_image}


class LIMN_OT_optimize(bpy.types.Operator):
    """Optimise the chosen mesh (its vertices, or its heights as a limn heightfield) so that limn's renders match the target images"""
    bl_idname = "limn.optimize"
    bl_label = "Optimise with limn"
    bl_options = {"REGISTER", "UNDO"}

    _timer = None
    _job = None

    @classmethod
    def description(cls, context, properties):
        running = _running_on(getattr(context.scene, "limn", None))
        if running is not None:
            return (f"limn's {running.label} is running ({running.status_text}); a second one on the same object "
                    "is refused: press Esc or Stop first")
        return cls.__doc__

    def _inputs(self, context):
        s = context.scene.limn
        targets = [(t.camera, t.image, t.light_collection) for t in s.targets if t.camera is not None and t.image is not None]
        return s, targets

    def execute(self, context):
        s, targets = self._inputs(context)
        running = _running_on(s)
        if running is not None:
            self.report({"ERROR"}, f"limn: object '{s.optimize_object.name}' is already being optimised "
                                   f"({running.status_text or 'starting'}); press Esc or Stop in the limn panel first")
            return {"CANCELLED"}
        if bpy.app.background or not context.window_manager.windows:
            def report(it, loss):
                if it % 5 == 0 or it == s.iterations - 1:
                    print(f"limn: iteration {it + 1}/{s.iterations}  loss {loss:.6f}", flush=True)
            try:
                out = optimize(s.optimize_object, targets, s.iterations, s.spp, _learning_rate(s), s.large_steps_lambda, report,
                               **_mode_inputs(s))
            except (ValueError, RuntimeError) as e:
                self.report({"ERROR"}, str(e))
                return {"CANCELLED"}
            self.report({"INFO"}, f"limn: loss {out['losses'][0]:.6f} -> {out['losses'][-1]:.6f} in {out['seconds']:.1f} s")
            return {"FINISHED"}
        return self._start(context, s, targets)

    def invoke(self, context, event):
        return self.execute(context)

    def _start(self, context, s, targets):
        try:
            problem = Problem(s.optimize_object, targets, s.spp, **_mode_inputs(s))
            self._job = OptimizeJob(problem, s.iterations, s.spp, _learning_rate(s), s.large_steps_lambda)
            self._job.start()
        except (ValueError, RuntimeError) as e:  # jobs.JobBusy is a ValueError
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        for w in problem.warnings:
            self.report({"WARNING"}, f"limn: {w}")
        return start_modal(self, context, 0.2)

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            job.cancel("Esc pressed")
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        status = job.poll()
        context.window_manager.progress_update(int(100 * (status["iteration"] + 1) / job.iterations))
        if context.area:
            context.area.header_text_set(status["message"])
        redraw_panels(context)
        if status["status"] == "running":
            return {"RUNNING_MODAL"}
        end_worker(self, context)
        if status["status"] in ("error", "stopped"):
            jobs.log(status["message"])
            self.report({"ERROR"}, status["message"])
            return {"CANCELLED"}
        self.report({"INFO"}, status["message"])
        return {"FINISHED"}  # one undo step, also after Esc (the last state is kept)

    def cancel(self, context):
        """Blender ends the operator: on quit, file load or closing its window. Stops the worker,
        waits for it and writes nothing more (the object belongs to a file that is going away)."""
        job = self._job
        if job is not None:
            job.cancel(job.stop_reason or "Blender ended the operator (quit, file load or window closed)", discard=True)
            job.join()
            job.forget()
            job.announce()
        end_worker(self, context)


def _running_on(s):
    """The running job that writes the object chosen in the panel settings `s`, or None."""
    obj = getattr(s, "optimize_object", None)
    if obj is None:
        return None
    keys = {("object", obj.as_pointer())}
    if obj.data is not None:
        keys.add(data_key(obj))
    return jobs.busy(keys)


class LIMN_OT_stop(bpy.types.Operator):
    """Stop limn's running renders and optimisations (an optimisation keeps its last state)"""
    bl_idname = "limn.stop"
    bl_label = "Stop"

    job: bpy.props.StringProperty(name="Job", description="Label of the job to stop; empty: all")

    @classmethod
    def poll(cls, context):
        return bool(jobs.running())

    def execute(self, context):
        stopped = [j for j in jobs.running() if not self.job or j.label == self.job]
        for j in stopped:
            j.cancel("Stop pressed")
        self.report({"INFO"}, f"limn: stopping {', '.join(j.label for j in stopped) or 'nothing'}")
        return {"FINISHED"}
