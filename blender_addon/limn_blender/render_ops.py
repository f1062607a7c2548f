"""Rendering with limn from Blender: a plain function for scripts and an operator for the UI.

In the UI the render runs on a worker thread (the C++ call releases the GIL) while a modal timer
shows progress; Esc cancels. In background mode (blender -b) timers never fire, so the operator
renders in execute(), blocking, and prints progress."""
from __future__ import annotations

import threading
import time

import bpy
import numpy as np

from . import exporter, jobs
from .limn_loader import LimnNotFound, import_limn


def _limn(context=None):
    prefs = None
    try:
        prefs = (context or bpy.context).preferences.addons[__package__].preferences
    except (KeyError, AttributeError):
        pass
    return import_limn(getattr(prefs, "module_path", "") or None)


def start_modal(operator, context, interval: float):
    """Makes `operator` modal with a timer every `interval` seconds and a progress indicator; its
    modal() polls the job it started on a thread of its own."""
    wm = context.window_manager
    operator._timer = wm.event_timer_add(interval, window=context.window)
    wm.progress_begin(0, 100)
    wm.modal_handler_add(operator)
    timer, area = operator._timer, context.area
    operator._job.release_ui = lambda: _release_ui(wm, timer, area)  # if the add-on is disabled while it runs
    return {"RUNNING_MODAL"}


def _release_ui(wm, timer, area) -> None:
    """What end_worker undoes, for an operator that Blender dropped without calling cancel() (the
    add-on was disabled while it ran: Blender frees the operator and leaves the rest to us)."""
    try:
        wm.event_timer_remove(timer)
        wm.progress_end()
        area.header_text_set(None)
    except (ReferenceError, AttributeError, RuntimeError):
        pass


def end_worker(operator, context) -> None:
    """Undoes start_modal's timer, progress indicator and header text (also while Blender quits or
    loads a file, when parts of the context may be gone)."""
    wm = context.window_manager
    timer, operator._timer = getattr(operator, "_timer", None), None
    if operator._job is not None:
        operator._job.release_ui = None
    try:
        if timer is not None:
            wm.event_timer_remove(timer)
        wm.progress_end()
        if context.area:
            context.area.header_text_set(None)
    except (ReferenceError, AttributeError, RuntimeError):
        pass
    redraw_panels(context)


def redraw_panels(context) -> None:
    """Redraws the Properties editors (the limn panel shows the running jobs)."""
    screen = getattr(context, "screen", None)
    for area in (screen.areas if screen is not None else ()):
        if area.type == "PROPERTIES":
            area.tag_redraw()


def image_to_blender(pixels: np.ndarray, name: str):
    """Stores a (H, W, 3) linear float image in a float Blender image datablock (created or
    resized) and packs it into the .blend (as OpenEXR), so that saving the file keeps it."""
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
    img.pack()  # a generated image that is not packed comes back black after save and reopen
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


class RenderJob(jobs.Job):
    """A render on a worker thread; `fraction` is its progress, `result` the image when it ends."""

    def __init__(self, lscene, spp: int, seed: int, image_name: str):
        super().__init__(keys={("render image", image_name)})
        self.label = f"render into image '{image_name}'"
        self.lscene, self.spp, self.seed, self.image_name = lscene, spp, seed, image_name
        self.fraction = 0.0
        self.result = None

    def _progress(self, fraction):
        self.fraction = fraction
        return self.keep_going()

    def work(self):
        self.result = self.lscene.render(spp=self.spp, seed=self.seed, progress=self._progress)


class LIMN_OT_render(bpy.types.Operator):
    """Render the active camera's view with limn into the image 'limn render'"""
    bl_idname = "limn.render"
    bl_label = "Render with limn"

    _timer = None
    _job = None

    def _settings(self, context):
        return context.scene.limn

    def execute(self, context):
        s = self._settings(context)
        running = jobs.busy({("render image", s.image_name)})
        if running is not None:
            self.report({"ERROR"}, str(jobs.JobBusy(running)))
            return {"CANCELLED"}
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
        self._job = RenderJob(lscene, s.spp, s.seed, s.image_name)
        self._job.start()
        return start_modal(self, context, 0.1)

    def invoke(self, context, event):
        return self.execute(context)

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            job.cancel("Esc pressed")
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        percent = 100 * job.fraction
        job.status_text = f"{percent:.0f}%"
        context.window_manager.progress_update(int(percent))
        if context.area:
            context.area.header_text_set(f"limn: rendering {percent:.0f}% (Esc to cancel)")
        redraw_panels(context)
        if job.alive:
            return {"RUNNING_MODAL"}
        job.forget()
        end_worker(self, context)
        if job.cancelled:  # also when the render ended just as it was cancelled: not written then
            message = f"limn: {job.label} stopped: {job.stop_reason}"
            jobs.log(message)
            self.report({"WARNING"}, message)
            return {"CANCELLED"}
        if job.error is not None:
            self.report({"ERROR"}, f"limn: {job.error}")
            return {"CANCELLED"}
        image_to_blender(job.result, job.image_name)
        self.report({"INFO"}, f"limn: render finished into image '{job.image_name}' (packed into the .blend)")
        return {"FINISHED"}

    def cancel(self, context):
        """Blender ends the operator: on quit, file load or closing its window. Stops the worker
        and waits for it; the image is left as it was."""
        job = self._job
        if job is not None:
            job.stop(job.stop_reason or "Blender ended the operator (quit, file load or window closed)")
            job.forget()
            job.announce()
        end_worker(self, context)


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
