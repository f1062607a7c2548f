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
    limn_blender.optimize(plane, [(camera, image), ...], mode="HEIGHTFIELD", mask_image=img)"""
from __future__ import annotations

import threading
import time

import bpy
import numpy as np

from . import exporter, heightfield
from .render_ops import _limn, end_worker, start_modal


def _target_pixels(target, width: int, height: int, limn) -> np.ndarray:
    if isinstance(target, str):
        img = limn.read_image(bpy.path.abspath(target))
    else:  # an image datablock (stored bottom row first, RGBA)
        w, h = target.size
        px = np.empty(w * h * 4, dtype=np.float32)
        target.pixels.foreach_get(px)
        img = px.reshape(h, w, 4)[::-1, :, :3].copy()
        if not target.is_float:  # byte images hold sRGB-encoded colours
            img = np.where(img <= 0.04045, img / 12.92, ((img + 0.055) / 1.055) ** 2.4).astype(np.float32)
    if img.shape[:2] != (height, width):
        raise ValueError(f"target image is {img.shape[1]}x{img.shape[0]}, the render resolution is {width}x{height}")
    return img


MODES = ("AUTO", "MESH", "HEIGHTFIELD")


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
    """Returns "MESH" or "HEIGHTFIELD" for the object and the chosen mode ("AUTO", "MESH", "HEIGHTFIELD")."""
    if mode not in MODES:
        raise ValueError(f"optimisation mode must be one of {', '.join(MODES)} (got {mode!r})")
    if mode != "AUTO":
        return mode
    marked = getattr(obj, "limn_heightfield", False)
    return "HEIGHTFIELD" if marked or heightfield.has_image_displace(obj) else "MESH"


class Problem:
    """The optimisation problem built from the Blender scene (main thread only): the limn scene and
    target per camera, the parameter `name`, the Large-Steps `faces`, the `mask` (or None) and
    write_back(x) for the mesh vertices or the heightfield's heights."""

    def __init__(self, obj, targets, spp: int, mode: str = "AUTO", mask_vertex_group: str = "", mask_image=None):
        if obj is None or obj.type != "MESH":
            raise ValueError("choose a mesh object to optimise")
        if not targets:
            raise ValueError("give at least one (camera, target image) pair")
        targets = [_unpack_target(i, t) for i, t in enumerate(targets)]
        for i, (cam, image, lights) in enumerate(targets):
            _check_light_setup(i, cam, image, lights)
        self.mode = resolve_mode(obj, mode)
        if self.mode == "MESH" and getattr(obj, "limn_heightfield", False):
            raise ValueError(f"object '{obj.name}' is marked as a limn heightfield; choose the heightfield mode or "
                             "clear the mark to optimise its vertices")
        if self.mode == "MESH" and (mask_vertex_group or mask_image is not None):
            raise ValueError(f"object '{obj.name}' is optimised as mesh vertices; masks (vertex group, mask image) "
                             "are for the heightfield mode")
        self.limn = _limn()
        self.obj = obj
        # Heights and mask first: a non-grid mesh, a bad Displace set-up or mask fails before any export.
        self.source = heightfield.Source(obj) if self.mode == "HEIGHTFIELD" else None
        self.mask = self.source.mask(mask_vertex_group, mask_image) if self.source else None
        scene = bpy.context.scene
        saved_camera = scene.camera
        self.views = []
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
                lscene = self.limn.load_dict(desc, source=f"blender '{scene.name}' camera '{cam.name}'{lit}")
                r = scene.render
                w, h = int(r.resolution_x * r.resolution_percentage / 100), int(r.resolution_y * r.resolution_percentage / 100)
                self.views.append((lscene, _target_pixels(target, w, h, self.limn)))
        finally:
            scene.camera = saved_camera
        if self.source is not None:
            src = self.source
            self.name = f"{obj.name}.heights"
            self.faces = self.limn.optim.grid_faces(src.rows, src.columns)
            return
        self.faces = shape["faces"]
        self.name = f"{obj.name}.vertex_positions"
        n = len(obj.data.vertices)
        welded = self.views[0][0].params[self.name]
        if len(shape["vertex_positions"]) != n or len(welded) != n:
            raise ValueError(f"object '{obj.name}': its modifiers change the vertices or it has coincident vertices "
                             f"({n} in the mesh, {len(welded)} rendered); apply or remove them before optimising")
        self.world = np.array([list(row) for row in obj.matrix_world], dtype=np.float64)

    def write_back(self, x: np.ndarray, final: bool = True) -> None:
        """Stores the parameter's value in Blender: world-space vertices into the mesh, or heights
        into the displacement image (packed when `final`) / the grid's z."""
        if self.source is not None:
            self.source.write_back(x, final=final)
            return
        inv = np.linalg.inv(self.world)
        local = x.astype(np.float64) @ inv[:3, :3].T + inv[:3, 3]
        self.obj.data.vertices.foreach_set("co", local.astype(np.float32).ravel())
        self.obj.data.update()


def optimize(obj, targets, iterations: int = 50, spp: int = 8, lr: float = 0.01, lambda_: float = 20.0,
             progress=None, mode: str = "AUTO", mask_vertex_group: str = "", mask_image=None) -> dict:
    """Blocking optimisation; writes the result into the mesh (or the heightfield's image / grid).
    progress(iteration, loss) may return False to stop. Returns {"losses": [...], "seconds": ...,
    "cancelled": ..., "mode": "MESH" | "HEIGHTFIELD"}."""
    problem = Problem(obj, targets, spp, mode, mask_vertex_group, mask_image)

    def callback(it, loss, x):
        return None if progress is None else progress(it, loss)

    t0 = time.perf_counter()
    result = problem.limn.optim.fit(problem.views, problem.name, iterations=iterations, lr=lr, lambda_=lambda_, spp=spp,
                                    faces=problem.faces, mask=problem.mask, callback=callback)
    problem.write_back(problem.views[0][0].params[problem.name])
    return {"losses": result.losses, "seconds": time.perf_counter() - t0, "cancelled": result.cancelled,
            "mode": problem.mode}


class OptimizeJob:
    """The background optimisation behind the modal operator. start() runs limn.optim.fit on a
    worker thread (which never touches bpy); poll(), on the main thread, reports progress and
    writes the latest vertices (or heights) into Blender every `write_every` iterations and when the
    run ends; cancel() stops after the current iteration, keeping the last state."""

    def __init__(self, problem: Problem, iterations: int, spp: int, lr: float, lambda_: float, write_every: int = 5):
        self.problem, self.iterations, self.write_every = problem, iterations, write_every
        self._settings = (spp, lr, lambda_)
        self._lock = threading.Lock()
        self._state = {"it": -1, "loss": float("nan"), "x": None, "done": False, "error": None}
        self._cancel = False
        self._written = -1
        self.writes = 0  # how often poll() wrote the result (progress shown in the viewport)
        self._thread = None

    def start(self) -> None:
        spp, lr, lambda_ = self._settings
        state, problem = self._state, self.problem

        def callback(it, loss, x):
            with self._lock:
                state["it"], state["loss"], state["x"] = it, loss, x.copy()
            return not self._cancel

        def work():
            try:
                problem.limn.optim.fit(problem.views, problem.name, iterations=self.iterations, spp=spp, lr=lr,
                                       lambda_=lambda_, faces=problem.faces, mask=problem.mask, callback=callback)
                with self._lock:
                    state["x"] = problem.views[0][0].params[problem.name].copy()
            except Exception as e:  # reported by poll() on the main thread
                state["error"] = e
            state["done"] = True

        self._thread = threading.Thread(target=work, daemon=True)
        self._thread.start()

    def cancel(self) -> None:
        self._cancel = True

    def poll(self) -> dict:
        """{"status": "running" | "finished" | "cancelled" | "error", "iteration", "loss", "message"}."""
        with self._lock:
            it, loss, x, done, error = (self._state[k] for k in ("it", "loss", "x", "done", "error"))
        if x is not None and (done or it - self._written >= self.write_every):
            self.problem.write_back(x, final=done)
            self._written = it
            self.writes += 1
        status = "running" if not done else ("error" if error is not None else ("cancelled" if self._cancel else "finished"))
        message = (f"limn: {error}" if error is not None else
                   f"limn: iteration {it + 1}/{self.iterations}, loss {loss:.6f}" +
                   ("" if done else " (Esc to cancel)") + (", cancelled" if done and self._cancel else ""))
        return {"status": status, "iteration": it, "loss": loss, "message": message}


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


def _mode_inputs(s) -> dict:
    """The panel's mode and masks as keyword arguments of Problem / optimize (the panel hides the
    masks in mesh mode, so they are not passed then)."""
    if s.optimize_mode == "MESH":
        return {"mode": "MESH"}
    return {"mode": s.optimize_mode, "mask_vertex_group": s.mask_vertex_group, "mask_image": s.mask_image}


class LIMN_OT_optimize(bpy.types.Operator):
    """Optimise the chosen mesh (its vertices, or its heights as a limn heightfield) so that limn's renders match the target images"""
    bl_idname = "limn.optimize"
    bl_label = "Optimise with limn"
    bl_options = {"REGISTER", "UNDO"}

    def _inputs(self, context):
        s = context.scene.limn
        targets = [(t.camera, t.image, t.light_collection) for t in s.targets if t.camera is not None and t.image is not None]
        return s, targets

    def execute(self, context):
        s, targets = self._inputs(context)
        if bpy.app.background or not context.window_manager.windows:
            def report(it, loss):
                if it % 5 == 0 or it == s.iterations - 1:
                    print(f"limn: iteration {it + 1}/{s.iterations}  loss {loss:.6f}", flush=True)
            try:
                out = optimize(s.optimize_object, targets, s.iterations, s.spp, s.learning_rate, s.large_steps_lambda, report,
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
        except (ValueError, RuntimeError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        self._job = OptimizeJob(problem, s.iterations, s.spp, s.learning_rate, s.large_steps_lambda)
        self._job.start()
        return start_modal(self, context, 0.2)

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC":
            job.cancel()
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        status = job.poll()
        context.window_manager.progress_update(int(100 * (status["iteration"] + 1) / job.iterations))
        if context.area:
            context.area.header_text_set(status["message"])
        if status["status"] == "running":
            return {"RUNNING_MODAL"}
        end_worker(self, context)
        if status["status"] == "error":
            self.report({"ERROR"}, status["message"])
            return {"CANCELLED"}
        self.report({"INFO"}, status["message"])
        return {"FINISHED"}
