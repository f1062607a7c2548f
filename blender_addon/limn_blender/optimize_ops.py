"""Shape optimisation from Blender: move a mesh object's vertices until limn's renders from the
given cameras match target images, then write the vertices back (one undo step).

Script use (also headless):
    limn_blender.optimize(obj, [(camera, image_or_path), ...], iterations=50)
In the UI (Properties > Render > limn > Optimise) the loop runs on a worker thread (the C++ calls
release the GIL); a timer shows progress and the loss, writes the mesh back every few iterations
and at the end, and Esc cancels, keeping the last state. In background mode the operator runs the
same loop blocking and prints progress."""
from __future__ import annotations

import time

import bpy
import numpy as np

from . import exporter
from .render_ops import _limn, end_worker, start_worker


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


class Problem:
    """The optimisation problem built from the Blender scene (main thread only)."""

    def __init__(self, obj, targets, spp: int):
        if obj is None or obj.type != "MESH":
            raise ValueError("choose a mesh object to optimise")
        if not targets:
            raise ValueError("give at least one (camera, target image) pair")
        self.limn = _limn()
        self.obj = obj
        scene = bpy.context.scene
        saved_camera = scene.camera
        self.views = []
        try:
            for cam, target in targets:
                if cam is None or cam.type != "CAMERA":
                    raise ValueError(f"'{getattr(cam, 'name', cam)}' is not a camera")
                scene.camera = cam
                desc, _ = exporter.export_scene(scene, spp=spp)
                if obj.name not in desc:
                    raise ValueError(f"object '{obj.name}' was not exported as one shape (hidden, or several materials?)")
                shape = desc[obj.name]
                lscene = self.limn.load_dict(desc, source=f"blender '{scene.name}' camera '{cam.name}'")
                r = scene.render
                w, h = int(r.resolution_x * r.resolution_percentage / 100), int(r.resolution_y * r.resolution_percentage / 100)
                self.views.append((lscene, _target_pixels(target, w, h, self.limn)))
        finally:
            scene.camera = saved_camera
        self.faces = shape["faces"]
        self.name = f"{obj.name}.vertex_positions"
        n = len(obj.data.vertices)
        welded = self.views[0][0].params[self.name]
        if len(shape["vertex_positions"]) != n or len(welded) != n:
            raise ValueError(f"object '{obj.name}': its modifiers change the vertices or it has coincident vertices "
                             f"({n} in the mesh, {len(welded)} rendered); apply or remove them before optimising")
        self.world = np.array([list(row) for row in obj.matrix_world], dtype=np.float64)

    def write_back(self, world_positions: np.ndarray) -> None:
        inv = np.linalg.inv(self.world)
        local = world_positions.astype(np.float64) @ inv[:3, :3].T + inv[:3, 3]
        self.obj.data.vertices.foreach_set("co", local.astype(np.float32).ravel())
        self.obj.data.update()


def optimize(obj, targets, iterations: int = 50, spp: int = 8, lr: float = 0.01, lambda_: float = 20.0,
             progress=None) -> dict:
    """Blocking optimisation; writes the result into the mesh. progress(iteration, loss) may return
    False to stop. Returns {"losses": [...], "seconds": ...}."""
    problem = Problem(obj, targets, spp)

    def callback(it, loss, x):
        return None if progress is None else progress(it, loss)

    t0 = time.perf_counter()
    result = problem.limn.optim.fit(problem.views, problem.name, iterations=iterations, lr=lr, lambda_=lambda_, spp=spp,
                                    faces=problem.faces, callback=callback)
    problem.write_back(problem.views[0][0].params[problem.name])
    return {"losses": result.losses, "seconds": time.perf_counter() - t0, "cancelled": result.cancelled}


class LimnTarget(bpy.types.PropertyGroup):
    camera: bpy.props.PointerProperty(name="Camera", type=bpy.types.Object, poll=lambda self, o: o.type == "CAMERA")
    image: bpy.props.PointerProperty(name="Target", type=bpy.types.Image)


class LIMN_OT_target_add(bpy.types.Operator):
    """Add a (camera, target image) pair"""
    bl_idname = "limn.target_add"
    bl_label = "Add target"

    def execute(self, context):
        t = context.scene.limn.targets.add()
        t.camera = context.scene.camera
        return {"FINISHED"}


class LIMN_OT_optimize(bpy.types.Operator):
    """Optimise the chosen mesh so that limn's renders match the target images"""
    bl_idname = "limn.optimize"
    bl_label = "Optimise with limn"
    bl_options = {"REGISTER", "UNDO"}

    def _inputs(self, context):
        s = context.scene.limn
        targets = [(t.camera, t.image) for t in s.targets if t.camera is not None and t.image is not None]
        return s, targets

    def execute(self, context):
        s, targets = self._inputs(context)
        if bpy.app.background or not context.window_manager.windows:
            def report(it, loss):
                if it % 5 == 0 or it == s.iterations - 1:
                    print(f"limn: iteration {it + 1}/{s.iterations}  loss {loss:.6f}", flush=True)
            try:
                out = optimize(s.optimize_object, targets, s.iterations, s.spp, s.learning_rate, s.large_steps_lambda, report)
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
            self._problem = Problem(s.optimize_object, targets, s.spp)
        except (ValueError, RuntimeError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        self._state = {"it": 0, "loss": float("nan"), "x": None, "cancel": False, "done": False, "error": None}
        state, problem = self._state, self._problem
        settings = (s.iterations, s.spp, s.learning_rate, s.large_steps_lambda)

        def callback(it, loss, x):
            state["it"], state["loss"], state["x"] = it, loss, x.copy()
            return not state["cancel"]

        def work():  # never touches bpy
            try:
                problem.limn.optim.fit(problem.views, problem.name, iterations=settings[0], spp=settings[1], lr=settings[2],
                                       lambda_=settings[3], faces=problem.faces, callback=callback)
                state["x"] = problem.views[0][0].params[problem.name].copy()
            except Exception as e:
                state["error"] = e
            state["done"] = True

        self._iterations = s.iterations
        self._last_write = -1
        return start_worker(self, context, work, 0.2)

    def modal(self, context, event):
        state = self._state
        if event.type == "ESC":
            state["cancel"] = True
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        context.window_manager.progress_update(int(100 * (state["it"] + 1) / self._iterations))
        if context.area:
            context.area.header_text_set(f"limn: iteration {state['it'] + 1}/{self._iterations}, loss {state['loss']:.6f} (Esc to cancel)")
        if state["x"] is not None and state["it"] - self._last_write >= 5:  # show progress in the viewport
            self._problem.write_back(state["x"])
            self._last_write = state["it"]
        if not state["done"]:
            return {"RUNNING_MODAL"}
        end_worker(self, context)
        if state["x"] is not None:
            self._problem.write_back(state["x"])
        if state["error"] is not None:
            self.report({"ERROR"}, f"limn: {state['error']}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"limn: optimisation {'cancelled' if state['cancel'] else 'finished'}, loss {state['loss']:.6f}")
        return {"FINISHED"}
