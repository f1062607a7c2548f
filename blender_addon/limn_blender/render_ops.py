"""Rendering with limn from Blender: a plain function for scripts and an operator for the UI.

In the UI the render runs on a worker thread (the C++ call releases the GIL) while a modal timer
shows progress; Esc cancels. In background mode (blender -b) timers never fire, so the operator
renders in execute(), blocking, and prints progress."""
from __future__ import annotations

import threading
import time

import bpy
import numpy as np

from . import exporter
from .limn_loader import LimnNotFound, import_limn


def _limn(context=None):
    prefs = None
    try:
        prefs = (context or bpy.context).preferences.addons[__package__].preferences
    except (KeyError, AttributeError):
        pass
    return import_limn(getattr(prefs, "module_path", "") or None)


def start_modal(operator, context, interval: float):
    """Makes `operator` modal with a timer every `interval` seconds and a progress bar; its modal()
    polls the work it started on a thread of its own."""
    wm = context.window_manager
    operator._timer = wm.event_timer_add(interval, window=context.window)
    wm.progress_begin(0, 100)
    wm.modal_handler_add(operator)
    return {"RUNNING_MODAL"}


def end_worker(operator, context) -> None:
    """Undoes start_modal's timer, progress bar and header text."""
    wm = context.window_manager
    wm.event_timer_remove(operator._timer)
    wm.progress_end()
    if context.area:
        context.area.header_text_set(None)


def image_to_blender(pixels: np.ndarray, name: str):
    """Stores a (H, W, 3) linear float image in a float Blender image datablock (created or resized)."""
    h, w = pixels.shape[:2]
    img = bpy.data.images.get(name)
    if img is None or tuple(img.size) != (w, h) or not img.is_float:
        if img is not None:
            bpy.data.images.remove(img)
        img = bpy.data.images.new(name, width=w, height=h, alpha=True, float_buffer=True)
    rgba = np.ones((h, w, 4), dtype=np.float32)
    rgba[..., :3] = pixels[::-1]  # Blender stores rows bottom to top
    img.pixels.foreach_set(rgba.ravel())
    img.update()
    return img


def load_blender_scene(scene=None, spp: int = 64, max_depth: int | None = None):
    """Exports the Blender scene and loads it into limn. Returns (limn.Scene, export warnings)."""
    limn = _limn()
    desc, warnings = exporter.export_scene(scene, spp=spp, max_depth=max_depth)
    for w in warnings:
        print(f"limn: {w}")
    return limn.load_dict(desc, source=f"blender scene '{(scene or bpy.context.scene).name}'"), warnings


def render(scene=None, spp: int = 64, seed: int = 0, image_name: str = "limn render", max_depth: int | None = None,
           progress=None):
    """Renders the scene with limn (blocking) into the image datablock `image_name`; returns it."""
    lscene, _ = load_blender_scene(scene, spp=spp, max_depth=max_depth)
    pixels = lscene.render(spp=spp, seed=seed, progress=progress)
    return image_to_blender(pixels, image_name)


class LIMN_OT_render(bpy.types.Operator):
    """Render the active camera's view with limn into the image 'limn render'"""
    bl_idname = "limn.render"
    bl_label = "Render with limn"

    _timer = None
    _thread = None

    def _settings(self, context):
        return context.scene.limn

    def execute(self, context):
        s = self._settings(context)
        try:
            lscene, _ = load_blender_scene(context.scene, spp=s.spp, max_depth=s.max_depth or None)
        except (LimnNotFound, ValueError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        if bpy.app.background or not context.window_manager.windows:
            last = [-1.0]

            def report(fraction):
                if fraction - last[0] >= 0.1 or fraction >= 1.0:
                    last[0] = fraction
                    print(f"limn: rendering {100 * fraction:5.1f}%", flush=True)

            t0 = time.perf_counter()
            pixels = lscene.render(spp=s.spp, seed=s.seed, progress=report)
            image_to_blender(pixels, s.image_name)
            self.report({"INFO"}, f"limn: rendered {pixels.shape[1]}x{pixels.shape[0]} at {s.spp} spp in "
                                  f"{time.perf_counter() - t0:.2f} s into image '{s.image_name}'")
            return {"FINISHED"}
        return self._start_worker(context, lscene, s)

    def invoke(self, context, event):
        return self.execute(context)

    def _start_worker(self, context, lscene, s):
        self._state = {"fraction": 0.0, "cancel": False, "result": None, "error": None}
        state = self._state

        def progress(fraction):
            state["fraction"] = fraction
            return not state["cancel"]

        def work():
            try:
                state["result"] = lscene.render(spp=s.spp, seed=s.seed, progress=progress)
            except Exception as e:  # reported on the main thread
                state["error"] = e

        self._thread = threading.Thread(target=work, daemon=True)  # never touches bpy
        self._thread.start()
        return start_modal(self, context, 0.1)

    def modal(self, context, event):
        if event.type == "ESC":
            self._state["cancel"] = True
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        wm = context.window_manager
        wm.progress_update(int(100 * self._state["fraction"]))
        if context.area:
            context.area.header_text_set(f"limn: {100 * self._state['fraction']:.0f}% (Esc to cancel)")
        if self._thread.is_alive():
            return {"RUNNING_MODAL"}
        end_worker(self, context)
        if self._state["error"] is not None:
            self.report({"WARNING" if self._state["cancel"] else "ERROR"}, f"limn: {self._state['error']}")
            return {"CANCELLED"}
        image_to_blender(self._state["result"], self._settings(context).image_name)
        self.report({"INFO"}, f"limn: render finished into image '{self._settings(context).image_name}'")
        return {"FINISHED"}


class LIMN_OT_export(bpy.types.Operator):
    """Write the scene as a limn JSON description (meshes as PLY/OBJ files beside it)"""
    bl_idname = "limn.export"
    bl_label = "Export limn scene"

    directory: bpy.props.StringProperty(subtype="DIR_PATH")

    def execute(self, context):
        try:
            _limn(context)
            desc, warnings = exporter.export_scene(context.scene, spp=context.scene.limn.spp,
                                                   max_depth=context.scene.limn.max_depth or None)
            path = exporter.write_scene(desc, bpy.path.abspath(self.directory or "//limn_export"))
        except (LimnNotFound, ValueError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        for w in warnings:
            self.report({"WARNING"}, w)
        self.report({"INFO"}, f"limn: wrote {path}")
        return {"FINISHED"}
