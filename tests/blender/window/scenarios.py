"""The window tests' scenarios, run inside Blender by driver.py. Each is a generator that gets the
driver module `d`; it yields how many seconds to wait before its next step (None: 0.05 s), so
Blender's event loop (timers, modal operators, redraws) runs in between, as for an artist. Facts
go to result.json through d.record(); when a generator ends, the driver quits Blender.

The scenarios observe only what any version of the add-on shows (threads, images, vertices,
operator results), so that they also run against the add-on before the robustness work."""
import threading
import time

import bpy
import numpy as np


def _setup(d, width=64, height=48):
    """The add-on tests' sphere over a plane in a fresh empty file, the add-on enabled (a
    generator: the file is read in one timer step, the scene built in the next)."""
    import addon_utils
    import scene_builder
    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield 0.2
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    with bpy.context.temp_override(window=window, area=area, region=area.regions[-1]):
        scene_builder.build_sphere_over_plane(width, height, reset=False)
    addon_utils.enable("limn_blender", default_set=True)
    import limn_blender
    return limn_blender


def _workers(before):
    """Threads that the add-on started (alive, not there before)."""
    return [t for t in threading.enumerate() if t.ident not in before and t.is_alive()]


def _vertices(mesh):
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    return co


def _optimisation(d, addon, iterations):
    """The sphere-over-plane scene at 32 x 24 with two targets rendered from a ball 1.25 times
    larger (flat shading), set in the panel's settings; returns the ball."""
    from limn_blender.render_ops import _limn
    limn = _limn()
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 32, 24
    ball = bpy.data.objects["ball"]
    for p in ball.data.polygons:
        p.use_smooth = False
    original = _vertices(ball.data)
    ball.data.vertices.foreach_set("co", original * 1.25)
    ball.data.update()
    cam2 = bpy.data.objects.new("cam2", bpy.data.cameras.new("cam2"))
    scene.collection.objects.link(cam2)
    cam2.location, cam2.rotation_euler = (5.5, 0.0, 2.5), (np.radians(68), 0.0, np.radians(90))
    s = scene.limn
    for i, cam in enumerate([bpy.data.objects["camera"], cam2]):
        scene.camera = cam
        desc, _ = addon.export_scene(spp=16)
        px = limn.load_dict(desc).render(spp=16, seed=5)
        img = bpy.data.images.new(f"target{i}", 32, 24, float_buffer=True)
        rgba = np.ones((24, 32, 4), np.float32)
        rgba[..., :3] = px[::-1]
        img.pixels.foreach_set(rgba.ravel())
        img.pack()
        t = s.targets.add()
        t.camera, t.image = cam, img
    scene.camera = bpy.data.objects["camera"]
    ball.data.vertices.foreach_set("co", original)
    ball.data.update()
    s.optimize_object = ball
    s.iterations, s.spp, s.learning_rate, s.large_steps_lambda = iterations, 4, 0.03, 5.0
    return ball


def _wait_for(condition, timeout):
    """Yields until condition() holds (returns True) or timeout seconds pass (returns False)."""
    t0 = time.time()
    while time.time() - t0 < timeout:
        if condition():
            return True
        yield 0.1
    return False


# ---- quitting while a job runs -------------------------------------------------------------------
def quit_mid_render(d):
    yield from _setup(d, 160, 120)
    s = bpy.context.scene.limn
    s.spp = 1024                      # about 10-20 s on 2 cores: still running when Blender quits
    before = {t.ident for t in threading.enumerate()}
    d.record(invoke=str(d.call(bpy.ops.limn.render)))
    yield 1.5
    d.record(workers_at_quit=len(_workers(before)), image_before_quit=s.image_name in bpy.data.images)
    # the generator ends: the driver quits Blender (wm.quit_blender, as File > Quit > Don't Save)


def quit_mid_optimise(d):
    addon = yield from _setup(d)
    ball = _optimisation(d, addon, iterations=400)
    start = _vertices(ball.data)
    before = {t.ident for t in threading.enumerate()}
    d.record(invoke=str(d.call(bpy.ops.limn.optimize)))
    moved = yield from _wait_for(lambda: not np.array_equal(_vertices(ball.data), start), 30)
    d.record(moved_before_quit=moved, workers_at_quit=len(_workers(before)))


# ---- File > New while a job runs ------------------------------------------------------------------
def new_file_mid_optimise(d):
    addon = yield from _setup(d)
    ball = _optimisation(d, addon, iterations=400)
    start = _vertices(ball.data)
    before = {t.ident for t in threading.enumerate()}
    d.record(invoke=str(d.call(bpy.ops.limn.optimize)))
    moved = yield from _wait_for(lambda: not np.array_equal(_vertices(ball.data), start), 30)
    d.record(moved_before_new=moved, workers_before_new=len(_workers(before)))
    t0 = time.time()
    bpy.ops.wm.read_homefile()         # File > New > General, "Don't Save"
    d.record(read_homefile_seconds=time.time() - t0)
    del ball                           # belongs to the old file
    stopped = yield from _wait_for(lambda: not _workers(before), 20)
    d.record(workers_stopped=stopped, stop_seconds=time.time() - t0)
    yield 0.5


# ---- the optimised object is deleted mid-run ------------------------------------------------------
def delete_mid_optimise(d):
    addon = yield from _setup(d)
    ball = _optimisation(d, addon, iterations=400)
    mesh = ball.data
    start = _vertices(mesh)
    before = {t.ident for t in threading.enumerate()}
    d.record(invoke=str(d.call(bpy.ops.limn.optimize)))
    moved = yield from _wait_for(lambda: not np.array_equal(_vertices(mesh), start), 30)
    d.record(moved_before_delete=moved)
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    region = next(r for r in area.regions if r.type == "WINDOW")
    for o in bpy.context.view_layer.objects:
        o.select_set(o is ball)
    bpy.context.view_layer.objects.active = ball
    with bpy.context.temp_override(window=window, area=area, region=region):
        d.record(delete=str(bpy.ops.object.delete("INVOKE_DEFAULT", use_global=False, confirm=False)))
    t0 = time.time()
    at_delete = _vertices(mesh)
    d.record(in_scene_after_delete="ball" in bpy.context.scene.objects)
    stopped = yield from _wait_for(lambda: not _workers(before), 20)
    d.record(workers_stopped=stopped, stop_seconds=time.time() - t0)
    yield 2.0                          # long enough for an old job's next write-backs
    d.record(orphan_written=not np.array_equal(_vertices(mesh), at_delete))


# ---- a second Optimise on the same object ----------------------------------------------------------
def second_optimise(d):
    addon = yield from _setup(d)
    ball = _optimisation(d, addon, iterations=60)
    bpy.context.scene.render.engine = "BLENDER_WORKBENCH"  # fewer render panels: limn's is in view
    with bpy.context.temp_override(**d.properties_override()):
        bpy.ops.screen.screen_full_area()  # the Properties editor fills the window (for the screenshots)
    yield 0.3
    with bpy.context.temp_override(**d.properties_override()):
        for _ in range(10):               # to the limn panel, the last one
            bpy.ops.view2d.scroll_down(page=True)
    yield 0.3
    start = _vertices(ball.data)
    before = {t.ident for t in threading.enumerate()}
    d.record(first=str(d.call(bpy.ops.limn.optimize)))
    moved = yield from _wait_for(lambda: not np.array_equal(_vertices(ball.data), start), 30)
    yield 0.5
    d.screenshot("optimising")         # the panel and header during the run
    d.record(second=str(d.call(bpy.ops.limn.optimize)), workers_after_second=len(_workers(before)))
    finished = yield from _wait_for(lambda: not _workers(before), 120)
    yield 0.5                          # the modal operator's last timer tick
    d.screenshot("finished")
    d.record(all_finished=finished, moved=not np.array_equal(_vertices(ball.data), start))


# ---- save and reopen: a limn render used as the target ----------------------------------------------
def save_and_reopen(d):
    import os
    yield from _setup(d)
    s = bpy.context.scene.limn
    s.spp, s.image_name = 16, "limn target"
    before = {t.ident for t in threading.enumerate()}
    d.record(render=str(d.call(bpy.ops.limn.render)))
    done = yield from _wait_for(lambda: "limn target" in bpy.data.images and not _workers(before), 60)
    yield 0.5
    img = bpy.data.images["limn target"]
    saved = np.empty(img.size[0] * img.size[1] * 4, np.float32)
    img.pixels.foreach_get(saved)
    t = s.targets.add()
    t.camera, t.image = bpy.data.objects["camera"], img
    s.optimize_object = bpy.data.objects["ball"]
    d.record(rendered=done, size=list(img.size), mean=float(saved.mean()), packed=img.packed_file is not None)
    path = os.path.join(d.OUT, "saved.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    del img, t
    bpy.ops.wm.open_mainfile(filepath=path)
    yield 0.5
    s = bpy.context.scene.limn
    img = bpy.data.images.get("limn target")
    target = s.targets[0].image if len(s.targets) else None
    d.record(reopened=img is not None, target_is_image=target is not None and target == img)
    if img is not None:
        size_ok = tuple(img.size) == tuple(d.RESULT["size"])
        px = np.zeros_like(saved)
        if size_ok:
            img.pixels.foreach_get(px)
        d.record(size_after=list(img.size), mean_after=float(px.mean()),
                 same_pixels=bool(size_ok and np.allclose(px, saved, atol=1e-6, rtol=0)))


# ---- Esc from the keyboard (xdotool: real X input) ---------------------------------------------------
def escape_mid_optimise(d):
    import subprocess
    addon = yield from _setup(d)
    ball = _optimisation(d, addon, iterations=400)
    start = _vertices(ball.data)
    before = {t.ident for t in threading.enumerate()}
    d.record(invoke=str(d.call(bpy.ops.limn.optimize)))
    moved = yield from _wait_for(lambda: not np.array_equal(_vertices(ball.data), start), 30)
    # The pointer over Blender's window (no window manager: keys go to the window under it).
    subprocess.run(["xdotool", "mousemove", "400", "300"], check=True, timeout=10)
    yield 0.2
    t0 = time.time()
    subprocess.run(["xdotool", "key", "Escape"], check=True, timeout=10)
    jobs = getattr(addon, "jobs", None)    # the add-on's job registry, where there is one
    if jobs is not None:
        yield from _wait_for(lambda: any(j.cancelled for j in jobs.running()) or not jobs.running(), 20)
        d.record(escape_seen_seconds=time.time() - t0)
    stopped = yield from _wait_for(lambda: not _workers(before), 20)
    yield 0.5                          # the modal operator's last tick writes the last state
    d.record(moved_before_escape=moved, workers_stopped=stopped, stop_seconds=time.time() - t0,
             kept=not np.array_equal(_vertices(ball.data), start))


def ctrl_q_mid_optimise(d):
    """Ctrl+Q from the keyboard while an optimisation runs, then "Don't Save" in the dialog."""
    import subprocess
    addon = yield from _setup(d)
    ball = _optimisation(d, addon, iterations=400)
    start = _vertices(ball.data)
    before = {t.ident for t in threading.enumerate()}
    d.record(invoke=str(d.call(bpy.ops.limn.optimize)))
    moved = yield from _wait_for(lambda: not np.array_equal(_vertices(ball.data), start), 30)
    d.record(moved_before_quit=moved, workers_at_quit=len(_workers(before)))
    bpy.ops.ed.undo_push(message="an edit")  # unsaved changes: Ctrl+Q asks whether to save
    subprocess.run(["xdotool", "mousemove", "640", "400"], check=True, timeout=10)
    yield 0.2
    subprocess.run(["xdotool", "key", "ctrl+q"], check=True, timeout=10)
    yield 2.0                          # "Save changes before closing?": Don't Save, Cancel, Save
    d.screenshot("quit_dialog")
    d.record(workers_with_dialog=len(_workers(before)), quit_at=time.time())
    subprocess.run(["xdotool", "key", "d"], check=True, timeout=10)  # the dialog's accelerator of Don't Save
    yield 60                           # Blender quits; the driver's own quit is not reached
    d.record(still_running_after_dont_save=True)


# ---- a curve object optimised from the panel ----------------------------------------------------------
def curve_optimise(d):
    """The modal operator on a NURBS curve object (round bevel): progress while it runs (the spline's
    points change while the worker is alive), the end, and one undo step that brings the start back."""
    addon = yield from _setup(d, 48, 36)
    from limn_blender.render_ops import _limn
    limn = _limn()
    scene = bpy.context.scene
    bpy.data.objects.remove(bpy.data.objects["ball"])
    pts = np.array([[-1.6, 0.0, 0.9], [-0.9, 0.2, 1.3], [-0.2, -0.1, 0.8], [0.5, 0.1, 1.2], [1.2, 0.0, 0.9], [1.8, 0.1, 1.1]])
    import scene_builder
    fibre = scene_builder.add_curve("fibre", "NURBS", pts + [0, 0, 0.25], [1.4] * 6, 0.12)  # the target's curve
    desc, _ = addon.export_scene(spp=16)
    px = limn.load_dict(desc).render(spp=16, seed=5)
    img = bpy.data.images.new("target", 48, 36, float_buffer=True)
    rgba = np.ones((36, 48, 4), np.float32)
    rgba[..., :3] = px[::-1]
    img.pixels.foreach_set(rgba.ravel())
    img.pack()
    for p, co in zip(fibre.data.splines[0].points, pts):
        p.co, p.radius = (*co, 1.0), 1.0
    s = scene.limn
    t = s.targets.add()
    t.camera, t.image = bpy.data.objects["camera"], img
    s.optimize_object = fibre
    s.iterations, s.spp, s.learning_rate = 40, 4, 0.01
    bpy.ops.ed.undo_push(message="before limn")

    def points():
        return np.array([(*p.co[:3], p.radius) for p in bpy.data.objects["fibre"].data.splines[0].points])

    start = points()
    before = {t.ident for t in threading.enumerate()}
    d.record(invoke=str(d.call(bpy.ops.limn.optimize)))
    moved = yield from _wait_for(lambda: not np.array_equal(points(), start), 60)
    d.record(moved_while_running=bool(moved and _workers(before)))
    ended = yield from _wait_for(lambda: not _workers(before), 120)
    yield 0.5                          # the modal operator's last tick writes the result
    end = points()
    d.record(ended=ended, count=len(end), moved_at_end=float(np.abs(end - start).max()),
             still_a_curve=bpy.data.objects["fibre"].type == "CURVE")
    d.call(bpy.ops.ed.undo)
    yield 0.5
    d.record(undo_restored=bool(np.allclose(points(), start, atol=1e-6)))


# ---- a signed-distance grid optimised from the panel (SDF mode) ---------------------------------------
def _volume_closed(mesh):
    """Enclosed volume and closedness (every edge shared by two faces) of a mesh (bmesh)."""
    import bmesh
    bm = bmesh.new()
    bm.from_mesh(mesh)
    closed = len(bm.faces) > 0 and all(e.is_manifold for e in bm.edges)
    bmesh.ops.triangulate(bm, faces=bm.faces[:])
    tris = np.array([[tuple(l.vert.co) for l in f.loops] for f in bm.faces], dtype=np.float64).reshape(-1, 3, 3)
    bm.free()
    return float(np.einsum("ij,ij->i", tris[:, 0], np.cross(tris[:, 1], tris[:, 2])).sum() / 6), closed


def sdf_optimise(d):
    """The modal operator in SDF mode with the panel's SDF defaults (learning rate, smoothing,
    redistancing), 16 samples across: the mesh is rewritten by marching cubes while the worker runs
    and at the end, the result is a closed mesh grown towards the 1.25 times larger target ball, one
    undo brings the original mesh back. Screenshots (LIMN_WINDOW_SCREENSHOTS=1) of the viewport and
    the panel during and after the run."""
    addon = yield from _setup(d)
    ball = _optimisation(d, addon, iterations=8)
    s = bpy.context.scene.limn
    s.optimize_mode, s.sdf_resolution, s.sdf_padding = "SDF", 16, 0.3
    d.record(panel={"learning_rate": s.sdf_learning_rate, "smoothing": s.sdf_smoothing,
                    "redistance_every": s.sdf_redistance_every})
    # The Properties editor scrolled to the limn panel (the last one; Workbench has few render panels
    # above it), the 3D view looking at the ball.
    bpy.context.scene.render.engine = "BLENDER_WORKBENCH"
    yield 0.3
    with bpy.context.temp_override(**d.properties_override()):
        for _ in range(10):
            bpy.ops.view2d.scroll_down(page=True)
    yield 0.3
    window = bpy.context.window_manager.windows[0]
    view = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    view.spaces.active.shading.type = "SOLID"
    for o in bpy.context.view_layer.objects:
        o.select_set(o is ball)
    bpy.context.view_layer.objects.active = ball
    with bpy.context.temp_override(window=window, area=view, region=next(r for r in view.regions if r.type == "WINDOW")):
        bpy.ops.view3d.view_selected()
    bpy.ops.ed.undo_push(message="before limn")
    mesh = ball.data
    n0, (v0, closed0) = len(mesh.vertices), _volume_closed(mesh)
    start = _vertices(mesh)
    d.record(vertices_before=n0, volume_before=v0, closed_before=closed0, volume_target=1.25 ** 3 * v0)
    yield 0.5
    d.screenshot("sdf_before")
    before = {t.ident for t in threading.enumerate()}
    d.record(invoke=str(d.call(bpy.ops.limn.optimize)))
    written = yield from _wait_for(lambda: len(bpy.data.objects["ball"].data.vertices) != n0, 300)
    d.record(written_while_running=bool(written and _workers(before)))
    yield 0.5
    d.screenshot("sdf_running")
    ended = yield from _wait_for(lambda: not _workers(before), 600)
    yield 0.5                          # the modal operator's last tick writes the result
    mesh = bpy.data.objects["ball"].data
    v1, closed1 = _volume_closed(mesh)
    d.record(ended=ended, vertices_after=len(mesh.vertices), volume_after=v1, closed_after=closed1,
             flat=not any(p.use_smooth for p in mesh.polygons), material=mesh.materials[0].name if mesh.materials else "")
    d.screenshot("sdf_finished")
    # The panel with the SDF settings: the Properties editor filling the window, scrolled to its end.
    with bpy.context.temp_override(**d.properties_override()):
        bpy.ops.screen.screen_full_area()
    yield 0.3
    with bpy.context.temp_override(**d.properties_override()):
        for _ in range(10):
            bpy.ops.view2d.scroll_down(page=True)
    yield 0.3
    d.screenshot("sdf_panel")
    d.call(bpy.ops.ed.undo)
    yield 0.5
    back = bpy.data.objects["ball"].data
    d.record(undo_restored=len(back.vertices) == n0 and bool(np.array_equal(_vertices(back), start)))
