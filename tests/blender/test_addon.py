"""The Blender add-on, headless, in Debian's Blender 3.4 and in the bpy module (Blender 4.5 LTS)."""
from __future__ import annotations

import math
import os
import re
import time

import bpy  # first: with the bpy module, addon_utils becomes importable only after bpy
import addon_utils
import numpy as np
import pytest

import scene_builder


@pytest.fixture
def addon():
    """A fresh copy of the test scene with the add-on enabled; returns the add-on module."""
    scene_builder.build_sphere_over_plane()
    addon_utils.enable("limn_blender", default_set=True)
    import limn_blender
    return limn_blender


@pytest.fixture
def limn(addon):
    from limn_blender.render_ops import _limn
    return _limn()


def test_addon_registers(addon):
    assert hasattr(bpy.types.Scene, "limn")
    assert hasattr(bpy.ops.limn, "render") and hasattr(bpy.ops.limn, "export")
    here = os.path.dirname(addon.__file__)
    assert os.path.exists(os.path.join(here, "blender_manifest.toml"))  # 4.2+ extension metadata
    assert addon.bl_info["blender"] <= (3, 4, 0)                         # legacy add-on metadata


def test_limn_is_found(limn):
    assert hasattr(limn, "load_dict")
    if bpy.app.version < (4, 0, 0):
        # Debian's Blender cannot see the project's venv: the copy bundled with the add-on is used.
        assert "vendor" in limn.__file__


def test_export_contents(addon):
    desc, warnings = addon.export_scene(spp=8)
    assert {"ball", "floor", "lamp", "sensor", "world", "integrator"} <= set(desc)
    assert desc["sensor"]["film"] == {"type": "hdrfilm", "width": 64, "height": 48}
    assert desc["sensor"]["fov"] == pytest.approx(math.degrees(2 * math.atan(18 / 35)), rel=1e-4)
    assert desc["ball"]["vertex_positions"].shape == (32 * 15 + 2, 3)
    assert desc["ball"]["face_normals"] is False            # shade_smooth
    np.testing.assert_allclose(desc["ball"]["vertex_positions"].mean(0), [0, 0, 1.0], atol=1e-5)
    radiance = desc["lamp"]["emitter"]["radiance"]
    assert radiance[0] == pytest.approx(400.0 / (4 * 1.5 ** 2))  # Cycles' convention, docs/blender.md
    assert desc["ball"]["bsdf"]["bsdf"]["reflectance"][:3] == pytest.approx([0.8, 0.2, 0.1])
    assert desc["world"]["radiance"] == pytest.approx([0.05, 0.06, 0.08])
    assert warnings == []


def test_modifiers_are_applied(addon):
    ball = bpy.data.objects["ball"]
    ball.modifiers.new("subdivide", "SUBSURF").levels = 1
    desc, _ = addon.export_scene(spp=8)
    assert desc["ball"]["vertex_positions"].shape[0] > 32 * 15 + 2


def test_render_matches_the_written_json(addon, limn, tmp_path):
    desc, _ = addon.export_scene(spp=8)
    from_dict = limn.load_dict(desc).render(seed=1)
    path = addon.write_scene(desc, str(tmp_path))
    from_file = limn.load(path).render(seed=1)
    np.testing.assert_array_equal(from_dict, from_file)


def test_render_matches_a_hand_written_scene(addon, limn):
    """The exported scene against the same scene written by hand from the bpy script's numbers
    (exact sphere instead of the UV sphere): checks camera, light and material conversion."""
    desc, _ = addon.export_scene(spp=64)
    exported = limn.load_dict(desc).render(seed=3)
    a = math.radians(65.0)
    forward, up = [0, math.sin(a), -math.cos(a)], [0, math.cos(a), math.sin(a)]
    origin = [0.0, -6.0, 3.0]
    hand = {
        "type": "scene", "integrator": {"type": "path", "max_depth": desc["integrator"]["max_depth"]},
        "sensor": {"type": "perspective", "fov": math.degrees(2 * math.atan(18 / 35)), "fov_axis": "x",
                   "to_world": {"look_at": {"origin": origin, "target": [o + f for o, f in zip(origin, forward)], "up": up}},
                   "film": {"type": "hdrfilm", "width": 64, "height": 48},
                   "sampler": {"type": "independent", "sample_count": 64}},
        "floor": {"type": "rectangle", "to_world": {"scale": 3},
                  "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": 0.6}}},
        "ball": {"type": "sphere", "center": [0, 0, 1], "radius": 0.8,
                 "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": [0.8, 0.2, 0.1]}}},
        "lamp": {"type": "rectangle",
                 "to_world": [{"scale": [0.75, 0.75, 1]}, {"rotate": {"axis": [1, 0, 0], "angle": 180}}, {"translate": [1, -1, 4]}],
                 "bsdf": {"type": "diffuse", "reflectance": 0.0},
                 "emitter": {"type": "area", "radiance": 400.0 / (4 * 1.5 ** 2)}},
        "world": {"type": "constant", "radiance": [0.05, 0.06, 0.08]},
    }
    reference = limn.load_dict(hand).render(spp=64, seed=4)
    assert abs(exported.mean() / reference.mean() - 1) < 0.03
    # Blurred per-region agreement (the UV sphere's facets differ from the exact sphere).
    blocks = lambda im: im.reshape(6, 8, 8, 8, 3).mean(axis=(1, 3))
    assert np.abs(blocks(exported) - blocks(reference)).max() < 0.1 * reference.max()


def test_operator_in_background_mode(addon):
    bpy.context.scene.limn.spp = 4
    assert bpy.ops.limn.render() == {"FINISHED"}
    img = bpy.data.images[bpy.context.scene.limn.image_name]
    assert tuple(img.size) == (64, 48) and img.is_float
    px = np.empty(64 * 48 * 4, np.float32)
    img.pixels.foreach_get(px)
    assert px.reshape(48, 64, 4)[..., :3].mean() > 0.01


def test_plain_render_function(addon):
    img = addon.render(spp=4, image_name="scripted")
    assert img.name == "scripted" and tuple(img.size) == (64, 48)


def test_export_operator_writes_json(addon, tmp_path):
    assert bpy.ops.limn.export(directory=str(tmp_path)) == {"FINISHED"}
    assert (tmp_path / "scene.json").exists()
    assert (tmp_path / "meshes" / "ball.obj").exists()  # it has texture coordinates: OBJ keeps them


def test_clear_errors(addon):
    bpy.context.scene.camera = None
    with pytest.raises(ValueError, match="no active camera"):
        addon.export_scene()
    # An operator that reports an error raises RuntimeError from bpy.ops in scripts, with its message.
    with pytest.raises(RuntimeError, match="no active camera"):
        bpy.ops.limn.render()


def test_spot_lights_are_exported_as_limn_spots(addon, limn):
    bpy.ops.object.light_add(type="SPOT", location=(0.5, 0, 3))  # points along its local -Z: down
    spot = bpy.context.object
    spot.name = "spot"
    spot.data.energy, spot.data.spot_size, spot.data.spot_blend = 100.0, math.radians(60), 0.2
    spot.data.shadow_soft_size = 0.0
    desc, warnings = addon.export_scene(spp=4)
    s = desc["spot"]
    assert s["type"] == "spot"
    assert s["cutoff_angle"] == pytest.approx(30.0) and s["beam_width"] == pytest.approx(24.0)
    assert s["intensity"][0] == pytest.approx(100.0 / (4 * math.pi))
    m = np.array(s["to_world"])
    np.testing.assert_allclose(m[:3, 2], [0, 0, -1], atol=1e-6)   # limn's spot looks along its +z
    np.testing.assert_allclose(m[:3, 3], [0.5, 0, 3], atol=1e-6)
    assert any("spot blend" in w for w in warnings)                # the approximation is reported
    limn.load_dict(desc).render(spp=1)


def test_unsupported_things_are_reported(addon):
    bpy.ops.object.light_add(type="AREA", location=(0, 0, 3))
    bpy.context.object.data.shape = "DISK"
    _, warnings = addon.export_scene()
    assert any("disk area light exported as a rectangle" in w for w in warnings)


def test_loader_explains_what_is_wrong(addon, tmp_path):
    from limn_blender import limn_loader
    assert "no folder 'limn'" in limn_loader._diagnose(str(tmp_path))
    (tmp_path / "limn").mkdir()
    assert "no compiled module" in limn_loader._diagnose(str(tmp_path))
    (tmp_path / "limn" / "_core.cpython-27-x86_64-linux-gnu.so").write_text("")
    message = limn_loader._diagnose(str(tmp_path))
    assert "this Blender runs Python" in message and "cpython-27" in message


def _render_target(addon, limn, camera):
    bpy.context.scene.camera = camera
    desc, _ = addon.export_scene(spp=32)
    return limn.load_dict(desc).render(spp=64, seed=5)


def _ball_targets(addon, limn, width=32, height=24):
    """width x height targets from two cameras of the ball grown 1.25 times (flat shading); the
    ball is left as it was. Returns (ball, [(camera, image)], original vertices)."""
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = width, height
    ball = bpy.data.objects["ball"]
    bpy.ops.object.shade_flat()  # smooth shading has a silhouette term limn does not sample yet
    cam2_data = bpy.data.cameras.new("cam2")
    cam2 = bpy.data.objects.new("cam2", cam2_data)
    scene.collection.objects.link(cam2)
    cam2.location = (5.5, 0.0, 2.5)
    cam2.rotation_euler = (math.radians(68), 0.0, math.radians(90))
    cams = [bpy.data.objects["camera"], cam2]
    original = np.empty(len(ball.data.vertices) * 3, np.float32)
    ball.data.vertices.foreach_get("co", original)
    ball.data.vertices.foreach_set("co", original * 1.25)
    ball.data.update()
    targets = [(c, _render_target(addon, limn, c)) for c in cams]
    scene.camera = cams[0]
    ball.data.vertices.foreach_set("co", original)
    ball.data.update()
    target_images = []
    for i, (c, img) in enumerate(targets):
        im = bpy.data.images.new(f"target{i}", width, height, float_buffer=True)
        rgba = np.ones((height, width, 4), np.float32)
        rgba[..., :3] = img[::-1]
        im.pixels.foreach_set(rgba.ravel())
        target_images.append((c, im))
    return ball, target_images, original


def test_optimisation_moves_the_mesh_towards_the_target(addon, limn):
    """Targets rendered from a larger ball; starting from the original ball, the loss must fall
    and the vertices move outwards. The result is written into the mesh."""
    scene = bpy.context.scene
    ball, target_images, original = _ball_targets(addon, limn)
    out = addon.optimize(ball, target_images, iterations=25, spp=8, lr=0.03, lambda_=5.0)
    print(f"blender optimisation: loss {out['losses'][0]:.5f} -> {min(out['losses'][-5:]):.5f} in {out['seconds']:.1f} s")
    after = np.empty_like(original)
    ball.data.vertices.foreach_get("co", after)
    r0 = np.linalg.norm(original.reshape(-1, 3), axis=1).mean()
    r1 = np.linalg.norm(after.reshape(-1, 3), axis=1).mean()
    assert min(out["losses"][-5:]) < 0.8 * out["losses"][0], out["losses"]
    assert r1 > r0 * 1.05, (r0, r1)   # a fifth of the way to 1.25 r0 at least
    print(f"blender optimisation: mean radius {r0:.3f} -> {r1:.3f} (target {1.25 * r0:.3f})")

    # The operator runs the same loop in background mode, as one undo step.
    s = scene.limn
    s.optimize_object = ball
    for c, im in target_images:
        t = s.targets.add()
        t.camera, t.image = c, im
    s.iterations, s.spp = 3, 4
    assert bpy.ops.limn.optimize() == {"FINISHED"}

    # The UI path: the modal operator polls an OptimizeJob on timer events (timers do not fire in
    # -b mode, so the test polls it the same way). It writes the mesh while running and at the end,
    # and a cancel keeps the last state.
    Job = addon.optimize_ops.OptimizeJob
    ball.data.vertices.foreach_set("co", original)
    ball.data.update()
    job = Job(addon.optimize_ops.Problem(ball, target_images, 8), iterations=12, spp=8, lr=0.03, lambda_=5.0, write_every=2)
    job.start()
    seen = []
    while True:
        status = job.poll()
        seen.append(status["status"])
        if status["status"] != "running":
            break
        time.sleep(0.02)
    assert status["status"] == "finished", status
    assert status["iteration"] == 11 and "iteration 12/12" in status["message"]
    assert job.writes >= 3, job.writes  # during the run and at the end
    final = np.empty_like(original)
    ball.data.vertices.foreach_get("co", final)
    assert np.linalg.norm(final.reshape(-1, 3), axis=1).mean() > r0 * 1.02

    ball.data.vertices.foreach_set("co", original)
    ball.data.update()
    job = Job(addon.optimize_ops.Problem(ball, target_images, 8), iterations=200, spp=8, lr=0.03, lambda_=5.0)
    job.start()
    while job.poll()["iteration"] < 2:
        time.sleep(0.02)
    job.cancel()
    while (status := job.poll())["status"] == "running":
        time.sleep(0.02)
    assert status["status"] == "cancelled" and status["iteration"] < 199, status
    moved = np.empty_like(original)
    ball.data.vertices.foreach_get("co", moved)
    assert not np.allclose(moved, original)  # the last good state was written back


def test_optimise_operator_reports_bad_input(addon):
    s = bpy.context.scene.limn
    s.optimize_object = bpy.data.objects["ball"]
    with pytest.raises(RuntimeError, match="at least one"):
        bpy.ops.limn.optimize()


# ---- robustness: jobs, saved images, refused targets ------------------------------------------------
def _vertices(obj_or_mesh):
    mesh = getattr(obj_or_mesh, "data", obj_or_mesh)
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    return co


def _run_until(job, iteration, timeout=60.0):
    """Polls `job` (as the modal operator's timer does) until it reached `iteration` or ended."""
    t0 = time.perf_counter()
    while (status := job.poll())["status"] == "running" and status["iteration"] < iteration:
        assert time.perf_counter() - t0 < timeout, status
        time.sleep(0.02)
    return status


def _poll_to_end(job, timeout=60.0):
    t0 = time.perf_counter()
    while (status := job.poll())["status"] == "running":
        assert time.perf_counter() - t0 < timeout, status
        time.sleep(0.02)
    return status


def test_render_is_packed_and_survives_save_and_reopen(addon, tmp_path):
    """A limn render is packed into the .blend (OpenEXR, full float): after save and reopen it
    has the same pixels, so it still works as an optimisation target."""
    img = addon.render(spp=4, image_name="limn target")
    assert img.packed_file is not None
    saved = np.empty(64 * 48 * 4, np.float32)
    img.pixels.foreach_get(saved)
    s = bpy.context.scene.limn
    t = s.targets.add()
    t.camera, t.image = bpy.data.objects["camera"], img
    path = str(tmp_path / "saved.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    img = bpy.data.images["limn target"]
    assert bpy.context.scene.limn.targets[0].image == img and tuple(img.size) == (64, 48)
    after = np.empty_like(saved)
    img.pixels.foreach_get(after)
    np.testing.assert_array_equal(after, saved)


def test_blank_targets_are_refused(addon, limn):
    """A target without pixels or with one colour everywhere (what an unpacked generated image is
    after a reopen) is refused, naming the image; an unpacked generated target draws a warning."""
    ball, targets, _ = _ball_targets(addon, limn)
    cam = targets[0][0]
    black = bpy.data.images.new("black", 32, 24, float_buffer=True)
    with pytest.raises(ValueError, match=r"target image 'black' is constant \(every pixel is \(0, 0, 0\)\)"):
        addon.optimize(ball, [targets[1], (cam, black)], iterations=1)
    missing = bpy.data.images.new("missing", 32, 24)
    missing.source, missing.filepath = "FILE", str(addon.__file__) + ".nothing.png"
    missing.reload()
    with pytest.raises(ValueError, match=r"target image 'missing' has no pixels \(file '.*nothing.png' missing\?\)"):
        addon.optimize(ball, [(cam, missing)], iterations=1)
    s = bpy.context.scene.limn
    s.optimize_object = ball
    t = s.targets.add()
    t.camera, t.image = cam, black
    with pytest.raises(RuntimeError, match=r"target image 'black' is constant"):
        bpy.ops.limn.optimize()
    problem = addon.optimize_ops.Problem(ball, targets, 4)
    assert any("target image 'target0' is a generated image that is not packed" in w for w in problem.warnings)
    targets[0][1].pack()
    targets[1][1].pack()
    assert addon.optimize_ops.Problem(ball, targets, 4).warnings == []


def test_one_job_per_object(addon, limn):
    """A second job on the same object (or its mesh) is refused, by OptimizeJob.start and by the
    operator, with the running job's progress in the message; the object is free again after."""
    ball, targets, _ = _ball_targets(addon, limn)
    Job, Problem = addon.optimize_ops.OptimizeJob, addon.optimize_ops.Problem
    job = Job(Problem(ball, targets, 4), iterations=500, spp=4, lr=0.03, lambda_=5.0)
    job.start()
    _run_until(job, 1)
    with pytest.raises(addon.jobs.JobBusy, match=r"limn: optimisation of 'ball' is running \(iteration \d+/500"):
        Job(Problem(ball, targets, 4), iterations=5, spp=4, lr=0.03, lambda_=5.0).start()
    s = bpy.context.scene.limn
    s.optimize_object = ball
    for c, im in targets:
        t = s.targets.add()
        t.camera, t.image = c, im
    with pytest.raises(RuntimeError, match=r"object 'ball' is already being optimised \(iteration \d+/500"):
        bpy.ops.limn.optimize()
    job.cancel("test")
    assert _poll_to_end(job)["status"] == "cancelled"
    assert addon.jobs.busy(job.keys) is None
    s.iterations, s.spp = 1, 4
    assert bpy.ops.limn.optimize() == {"FINISHED"}


@pytest.mark.parametrize("how", ["remove", "unlink", "rename", "edit_mode"])
def test_job_stops_when_its_object_goes(addon, limn, how):
    """Deleted (freed, or only unlinked from the scene: an orphan), renamed or in Edit Mode: the
    job stops promptly with a message naming the object and writes nothing into it any more."""
    ball, targets, _ = _ball_targets(addon, limn)
    job = addon.optimize_ops.OptimizeJob(addon.optimize_ops.Problem(ball, targets, 4), iterations=500, spp=4,
                                         lr=0.03, lambda_=5.0, write_every=1)
    job.start()
    _run_until(job, 3)
    mesh = ball.data
    if how == "remove":
        bpy.data.objects.remove(ball)
        expected = "object 'ball' was deleted"
    elif how == "unlink":
        for c in ball.users_collection:
            c.objects.unlink(ball)
        expected = r"object 'ball' was deleted \(it is in no scene any more\)"
    elif how == "rename":
        ball.name = "renamed"
        expected = "object 'ball' was renamed to 'renamed'"
    else:
        bpy.context.view_layer.objects.active = ball
        bpy.ops.object.mode_set(mode="EDIT")
        expected = "object 'ball' entered Edit Mode"
    before = _vertices(mesh)
    t0 = time.perf_counter()
    status = _poll_to_end(job)
    seconds = time.perf_counter() - t0
    assert status["status"] == "stopped" and not job.alive, status
    assert re.search(f"limn: optimisation of 'ball' stopped: {expected}", status["message"]), status["message"]
    assert seconds < 5.0, seconds
    if how == "edit_mode":
        bpy.ops.object.mode_set(mode="OBJECT")
    np.testing.assert_array_equal(_vertices(mesh), before)   # nothing written after
    assert addon.jobs.running() == []


def test_cancel_stops_inside_an_iteration(addon, limn):
    """The C++ calls get the job's cancel flag as progress callback: a cancel during a long render
    stops within a 16 x 16 tile, not at the end of the iteration (48 tiles of 256 pixels at
    2000 spp: a render takes several seconds, a tile a fraction of one)."""
    ball, targets, _ = _ball_targets(addon, limn, 128, 96)
    job = addon.optimize_ops.OptimizeJob(addon.optimize_ops.Problem(ball, targets, 4), iterations=3, spp=2000,
                                         lr=0.03, lambda_=5.0)
    job.start()
    time.sleep(0.5)
    seconds = job.stop("test")
    print(f"cancel inside an iteration at 128 x 96, 2000 spp: stopped in {seconds:.3f} s")
    assert not job.alive and seconds < 1.5, seconds
    status = _poll_to_end(job)
    assert status["status"] == "cancelled" and status["iteration"] == -1, status
    assert job.error is None


def test_file_load_and_disabling_the_addon_stop_jobs(addon, limn):
    """load_pre (File > New / Open, scripts) and unregister stop and join the running jobs."""
    import addon_utils
    ball, targets, _ = _ball_targets(addon, limn)
    for stopper in ("load", "disable"):
        job = addon.optimize_ops.OptimizeJob(addon.optimize_ops.Problem(ball, targets, 4), iterations=500, spp=4,
                                             lr=0.03, lambda_=5.0)
        job.start()
        _run_until(job, 1)
        t0 = time.perf_counter()
        if stopper == "load":
            bpy.ops.wm.read_homefile(use_empty=True)
        else:
            addon_utils.disable("limn_blender")
        seconds = time.perf_counter() - t0
        print(f"{stopper}: the job stopped within {seconds:.3f} s")
        assert not job.alive and job.discard and addon.jobs.busy(job.keys) is None
        assert "file is being loaded" in job.stop_reason if stopper == "load" else "disabled" in job.stop_reason
        assert seconds < 5.0
        if stopper == "load":
            scene_builder.build_sphere_over_plane()
            addon_utils.enable("limn_blender", default_set=True)
            ball, targets, _ = _ball_targets(addon, limn)
    addon_utils.enable("limn_blender", default_set=True)


def test_save_during_a_run_saves_the_latest_state(addon, limn, tmp_path):
    """save_pre writes the job's latest state into the mesh before the file is written."""
    ball, targets, original = _ball_targets(addon, limn)
    job = addon.optimize_ops.OptimizeJob(addon.optimize_ops.Problem(ball, targets, 4), iterations=500, spp=4,
                                         lr=0.03, lambda_=5.0, write_every=1000)
    job.start()
    _run_until(job, 3)                            # polled, but not written (write_every)
    np.testing.assert_array_equal(_vertices(ball), original)
    path = str(tmp_path / "running.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    saved = _vertices(ball)
    assert not np.array_equal(saved, original)
    job.cancel("test")
    _poll_to_end(job)
    bpy.ops.wm.open_mainfile(filepath=path)
    np.testing.assert_array_equal(_vertices(bpy.data.objects["ball"]), saved)


_EXIT_SCRIPT = """
import os, sys, time
sys.path[:0] = [{tests!r}, {addon_dir!r}]
import bpy, addon_utils, numpy as np, scene_builder
scene_builder.build_sphere_over_plane(160, 120)  # 80 tiles: a render of many short tiles
addon_utils.enable("limn_blender", default_set=True)
from limn_blender import export_scene, optimize_ops, render_ops
desc, _ = export_scene(spp=4)
img = bpy.data.images.new("t", 160, 120, float_buffer=True)
rgba = np.ones((120, 160, 4), np.float32)
rgba[..., :3] = 0.5 * render_ops._limn().load_dict(desc).render(spp=4)[::-1]
img.pixels.foreach_set(rgba.ravel())
problem = optimize_ops.Problem(bpy.data.objects["ball"], [(bpy.data.objects["camera"], img)], 4)
optimize_ops.OptimizeJob(problem, 100000, 4, 0.01, 5.0).start()
render_ops.RenderJob(render_ops.load_blender_scene(spp=4)[0], 2000, 0, "r").start()
time.sleep(1.0)
print("script ends with two jobs running", flush=True)
"""


def test_exit_with_jobs_running(addon, tmp_path):
    """A script that ends while jobs run: Blender 3.4 (-b) quits, the bpy module's Python exits.
    The jobs are stopped and joined before Python is finalised (unregister via addon_utils.
    disable_all in Blender, atexit in the module): exit code 0, no abort ("terminate called",
    "FATAL: exception not rethrown") or segmentation fault."""
    import subprocess
    import sys
    script = tmp_path / "exit_with_jobs.py"
    script.write_text(_EXIT_SCRIPT.format(tests=os.path.dirname(os.path.abspath(__file__)),
                                          addon_dir=os.path.dirname(os.path.dirname(addon.__file__))))
    if bpy.app.binary_path:  # inside the blender executable
        cmd = [bpy.app.binary_path, "-b", "--factory-startup", "-noaudio", "--python-exit-code", "1",
               "--python", str(script)]
    else:                    # the bpy module
        cmd = [sys.executable, str(script)]
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=120)
    print(p.stdout[-1500:])
    assert "script ends with two jobs running" in p.stdout
    assert p.returncode == 0, p.stdout[-1500:]
    assert not re.search(r"FATAL|terminate called|Segmentation fault|Aborted", p.stdout)
    assert "limn: optimisation of 'ball' stopped" in p.stdout and "limn: render into image 'r' stopped" in p.stdout
    seconds = float(re.search(r"limn: stopped 2 job\(s\) in ([0-9.]+) s", p.stdout).group(1))
    assert seconds < 3.0, seconds   # within a tile of the running renders


# ---- heightfields --------------------------------------------------------------------------------
def _heightfield_addon(kind):
    scene_builder.build_heightfield(kind)
    addon_utils.enable("limn_blender", default_set=True)
    import limn_blender
    from limn_blender.render_ops import _limn
    return limn_blender, _limn()


def _set_image(img, value):
    """Stores (rows, columns) values, row 0 the top row, in every colour channel of `img`."""
    rgba = np.ones((img.size[1], img.size[0], 4), np.float32)
    rgba[..., :3] = np.asarray(value, np.float32)[::-1, :, None]
    img.pixels.foreach_set(rgba.ravel())
    img.update()


def _image_values(img):
    px = np.empty(img.size[0] * img.size[1] * 4, np.float32)
    img.pixels.foreach_get(px)
    return px.reshape(img.size[1], img.size[0], 4)[::-1, :, 0]


def _grid_z(obj):
    co = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def _heightfield_targets(addon, limn, cameras, spp=64):
    """Renders of the current Blender scene (terrain as a heightfield) from each camera."""
    scene = bpy.context.scene
    out = []
    for cam in cameras:
        scene.camera = cam
        desc, _ = addon.export_scene(spp=spp, heightfields={"terrain"})
        out.append(limn.load_dict(desc).render(spp=spp, seed=11))
    scene.camera = cameras[0]
    return out


def _image_loss(addon, limn, cameras, targets):
    """Mean squared error of 32-spp renders against the targets (less noisy than fit's 4-spp losses)."""
    return float(np.mean([((r - t) ** 2).mean() for r, t in zip(_heightfield_targets(addon, limn, cameras, 32), targets)]))


def _float_image(name, pixels):
    h, w = pixels.shape[:2]
    img = bpy.data.images.new(name, w, h, float_buffer=True)
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = pixels[::-1]
    img.pixels.foreach_set(rgba.ravel())
    return img


def test_heightfield_export_of_a_displaced_plane_and_a_grid():
    """Orientation (image top row = far edge), size, height scale and placement; the heightfield
    renders like Blender's own displaced mesh; objects are converted only when marked or named."""
    addon, limn = _heightfield_addon("displace")
    obj = bpy.data.objects["terrain"]
    n = 17
    u = (np.arange(n) + 0.5) / n                 # Blender samples pixel j around u = (j + 1/2) / n
    X, Y = np.meshgrid(2 * u - 1, 1 - 2 * u)     # rows top first: y = +1 first
    bump = 0.3 * np.exp(-((X - 0.5) ** 2 + (Y - 0.4) ** 2) / 0.1)  # off-centre: catches flips
    img = obj.modifiers["displace"].texture.image
    _set_image(img, bump / 0.5 + 0.5)            # strength 0.5, mid-level 0.5
    obj.update_tag()
    desc, warnings = addon.export_scene(spp=16)
    assert desc["terrain"]["type"] == "mesh"     # not marked, not the optimisation target
    mesh_render = limn.load_dict(desc).render(spp=64, seed=1)
    obj.limn_heightfield = True
    desc, warnings = addon.export_scene(spp=16)
    hf = desc["terrain"]
    assert hf["type"] == "heightfield" and warnings == []
    assert hf["data"].shape == (n, n) and hf["size"] == pytest.approx([2, 2]) and hf["height_scale"] == pytest.approx(0.5)
    np.testing.assert_allclose(hf["data"] * hf["height_scale"], bump, atol=1e-6)
    assert np.unravel_index(np.argmax(hf["data"]), hf["data"].shape) == (5, 12)  # x = 0.5 -> column 12, y = 0.4 -> row 5
    hf_render = limn.load_dict(desc).render(spp=64, seed=1)
    blocks = lambda im: im.reshape(6, 4, 6, 4, 3).mean(axis=(1, 3))
    print(f"heightfield vs displaced mesh: mean {hf_render.mean():.4f} / {mesh_render.mean():.4f}, "
          f"largest 4x4-block difference {np.abs(blocks(hf_render) - blocks(mesh_render)).max():.4f}")
    assert abs(hf_render.mean() / mesh_render.mean() - 1) < 0.03
    assert np.abs(blocks(hf_render) - blocks(mesh_render)).max() < 0.1 * mesh_render.max()
    # Placement: translation, rotation about z, non-uniform scale (x, y into size, z into height_scale).
    obj.location, obj.rotation_euler, obj.scale = (0.5, -0.2, 0.1), (0, 0, math.radians(30)), (1.5, 0.5, 2.0)
    bpy.context.view_layer.update()
    hf = addon.export_scene(spp=16)[0]["terrain"]
    assert hf["size"] == pytest.approx([3.0, 1.0]) and hf["height_scale"] == pytest.approx(1.0)
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    np.testing.assert_allclose(hf["to_world"], [[c, -s, 0, 0.5], [s, c, 0, -0.2], [0, 0, 1, 0.1], [0, 0, 0, 1]], atol=1e-6)
    obj.modifiers["displace"].texture_coords = "LOCAL"
    with pytest.raises(ValueError, match=r"object 'terrain', modifier 'displace': texture coordinates must be UV \(got LOCAL\)"):
        addon.export_scene()

    # A grid mesh: heights are the vertices' z, exactly.
    addon, limn = _heightfield_addon("grid")
    obj = bpy.data.objects["terrain"]
    co = _grid_z(obj)
    co[:, 2] = 0.3 * np.exp(-((co[:, 0] - 0.5) ** 2 + (co[:, 1] - 0.4) ** 2) / 0.1)
    obj.data.vertices.foreach_set("co", co.ravel())
    obj.data.update()
    hf = addon.export_scene(spp=16, heightfields={"terrain"})[0]["terrain"]
    x = np.linspace(-1, 1, n)
    X, Y = np.meshgrid(x, -x)
    np.testing.assert_allclose(hf["data"], 0.3 * np.exp(-((X - 0.5) ** 2 + (Y - 0.4) ** 2) / 0.1), atol=1e-6)
    assert hf["size"] == pytest.approx([2, 2]) and hf["height_scale"] == 1.0


def test_heightfield_optimisation_of_a_displaced_plane():
    """Targets from a known bump in the displacement image; starting from a flat 8-bit image, the
    loss and the height error fall; the heights go into a new float image (packed, the texture
    points at it), the masked border stays at the mid-level; the background job does the same."""
    addon, limn = _heightfield_addon("displace")
    obj = bpy.data.objects["terrain"]
    tex = obj.modifiers["displace"].texture
    cams = [bpy.data.objects["cam_front"], bpy.data.objects["cam_side"]]
    truth = scene_builder.bumps(17)              # heights; strength 0.5 makes them 0.5 * truth high
    _set_image(tex.image, truth + 0.5)           # pixel = height + mid-level
    targets = _heightfield_targets(addon, limn, cams)
    flat = bpy.data.images.new("flat", 17, 17)   # an 8-bit image: 128 / 255, nearly the mid-level
    _set_image(flat, np.full((17, 17), 0.5))
    tex.image = flat
    mask = np.zeros((17, 17))
    mask[1:-1, 1:-1] = 1.0                       # the border is held fixed
    mask_img = _float_image("mask", np.repeat(mask[:, :, None], 3, axis=2))
    target_imgs = [(c, _float_image(f"target_{c.name}", t)) for c, t in zip(cams, targets)]
    start = (_image_values(flat) - 0.5).astype(np.float32)
    loss0 = _image_loss(addon, limn, cams, targets)
    rms = lambda h: float(np.sqrt(((h - truth) ** 2).mean()))

    out = addon.optimize(obj, target_imgs, iterations=40, spp=4, lr=0.1, lambda_=3.0, mask_image=mask_img)
    img = tex.image
    assert out["mode"] == "HEIGHTFIELD"          # detected: the target has an image Displace modifier
    assert img is not flat and img.is_float and img.packed_file is not None
    assert img.size[:] == (17, 17) and img.colorspace_settings.name == "Non-Color"
    np.testing.assert_array_equal(_image_values(flat) - 0.5, start)  # the 8-bit image is left alone
    heights = _image_values(img) - 0.5           # the inverse mapping
    loss1 = _image_loss(addon, limn, cams, targets)
    L = out["losses"]
    print(f"displaced plane: loss {np.mean(L[:3]):.5f} -> {np.mean(L[-5:]):.5f} (32 spp: {loss0:.5f} -> {loss1:.5f}), "
          f"height RMS error {rms(start):.3f} -> {rms(heights):.3f}, {out['seconds']:.1f} s")
    assert np.mean(L[-5:]) < 0.9 * np.mean(L[:3]), L
    assert loss1 < 0.6 * loss0, (loss0, loss1)
    assert rms(heights) < 0.5 * rms(start)
    np.testing.assert_array_equal(heights[mask == 0], start[mask == 0])
    # The written image is what the next export reads, and Blender's modifier sees it.
    obj.limn_heightfield = True
    np.testing.assert_allclose(addon.export_scene(spp=4)[0]["terrain"]["data"], heights, atol=1e-6)
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    assert max(v.co.z for v in evaluated.data.vertices) > 0.2

    # The UI's background job: progress, write-back while running and at the end (packed again).
    before = heights.copy()
    job = addon.optimize_ops.OptimizeJob(addon.optimize_ops.Problem(obj, target_imgs, 4, mask_image=mask_img),
                                         iterations=4, spp=4, lr=0.1, lambda_=3.0, write_every=2)
    job.start()
    while (status := job.poll())["status"] == "running":
        time.sleep(0.02)
    assert status["status"] == "finished" and "iteration 4/4" in status["message"], status
    assert job.writes >= 2 and tex.image is img and img.packed_file is not None
    assert not np.array_equal(_image_values(img) - 0.5, before)


def test_heightfield_optimisation_of_a_grid_mesh():
    """The operator in heightfield mode on a flat grid mesh, targets from a known bump in the
    vertices' z; a vertex group holds the border fixed. Loss and height error fall; the vertices'
    z are the result (x, y untouched); one undo brings the flat grid back."""
    addon, limn = _heightfield_addon("grid")
    obj = bpy.data.objects["terrain"]
    cams = [bpy.data.objects["cam_front"], bpy.data.objects["cam_side"]]
    n = 17
    co = _grid_z(obj)
    source = addon.heightfield.Source(obj)
    truth = 0.5 * scene_builder.bumps(n)         # z of the grid, rows x columns
    co_true = co.copy()
    co_true[source.order, 2] = truth.ravel()
    obj.data.vertices.foreach_set("co", co_true.ravel())
    obj.data.update()
    targets = _heightfield_targets(addon, limn, cams)
    obj.data.vertices.foreach_set("co", co.ravel())  # back to flat
    obj.data.update()
    border = (np.abs(co[:, 0]) > 0.99) | (np.abs(co[:, 1]) > 0.99)
    group = obj.vertex_groups.new(name="inner")
    group.add([int(i) for i in np.flatnonzero(~border)], 1.0, "REPLACE")
    loss0 = _image_loss(addon, limn, cams, targets)

    s = bpy.context.scene.limn
    s.optimize_object, s.optimize_mode, s.mask_vertex_group = obj, "HEIGHTFIELD", "inner"
    for c, t in zip(cams, targets):
        target = s.targets.add()
        target.camera, target.image = c, _float_image(f"target_{c.name}", t)
    s.iterations, s.spp, s.learning_rate, s.large_steps_lambda = 40, 4, 0.05, 3.0
    t0 = time.perf_counter()
    bpy.ops.ed.undo_push(message="before limn")
    assert bpy.ops.limn.optimize("EXEC_DEFAULT", True) == {"FINISHED"}  # True: push an undo step, as the UI does
    seconds = time.perf_counter() - t0
    after = _grid_z(obj)
    heights = after[source.order, 2].reshape(n, n)
    loss1 = _image_loss(addon, limn, cams, targets)
    rms = lambda h: float(np.sqrt(((h - truth) ** 2).mean()))
    print(f"grid mesh: loss (32 spp) {loss0:.5f} -> {loss1:.5f}, height RMS error {rms(np.zeros_like(truth)):.3f} -> "
          f"{rms(heights):.3f}, {seconds:.1f} s")
    assert loss1 < 0.6 * loss0, (loss0, loss1)
    assert rms(heights) < 0.5 * rms(np.zeros_like(truth))
    np.testing.assert_array_equal(after[:, :2], co[:, :2])  # only z moves
    assert (after[border, 2] == 0).all() and np.abs(after[~border, 2]).max() > 0.1
    bpy.ops.ed.undo()                             # the whole run is one undo step
    np.testing.assert_array_equal(_grid_z(bpy.data.objects["terrain"]), co)


def test_heightfield_mode_refuses_what_is_not_a_heightfield(addon):
    """A UV sphere is not a grid; an unevenly spaced grid is not regular; the errors name the object."""
    ball = bpy.data.objects["ball"]
    s = bpy.context.scene.limn
    s.optimize_object, s.optimize_mode = ball, "HEIGHTFIELD"
    t = s.targets.add()
    t.camera, t.image = bpy.data.objects["camera"], bpy.data.images.new("target", 64, 48, float_buffer=True)
    with pytest.raises(RuntimeError, match=r"object 'ball' is not a regular grid in its local x, y: its 482 vertices"):
        bpy.ops.limn.optimize()
    with pytest.raises(ValueError, match=r"object 'ball' is not a regular grid"):
        addon.optimize(ball, [(t.camera, t.image)], mode="HEIGHTFIELD")
    ball.limn_heightfield = True                  # marked objects are converted by every export
    with pytest.raises(ValueError, match=r"object 'ball' is not a regular grid"):
        addon.export_scene()
    with pytest.raises(ValueError, match=r"object 'ball' is marked as a limn heightfield; choose the heightfield mode"):
        addon.optimize(ball, [(t.camera, t.image)], mode="MESH")
    ball.limn_heightfield = False
    with pytest.raises(ValueError, match=r"object 'ball' is optimised as mesh vertices; masks"):
        addon.optimize(ball, [(t.camera, t.image)], mask_image=t.image)  # "AUTO": a sphere is a mesh
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=4, y_subdivisions=4, size=2.0)
    grid = bpy.context.active_object
    grid.name = "uneven"
    co = _grid_z(grid)
    co[np.isclose(co[:, 0], 0.5), 0] = 0.6        # one column moved
    grid.data.vertices.foreach_set("co", co.ravel())
    with pytest.raises(ValueError, match=r"object 'uneven' is not a regular grid: its x values are not evenly spaced"):
        addon.heightfield.Source(grid)
    co[np.isclose(co[:, 0], 0.6), 0] = 0.5        # regular again; the mask names a group it lacks
    grid.data.vertices.foreach_set("co", co.ravel())
    s.optimize_object, s.mask_vertex_group = grid, "missing"
    with pytest.raises(RuntimeError, match=r"object 'uneven' has no vertex group 'missing'"):
        bpy.ops.limn.optimize()


def test_heightfield_write_back_into_an_openexr_file_image(tmp_path):
    """A float OpenEXR height image is written in place (same datablock, packed); heights round-trip."""
    addon, limn = _heightfield_addon("displace")
    obj = bpy.data.objects["terrain"]
    tex = obj.modifiers["displace"].texture
    path = str(tmp_path / "heights.exr")
    limn.write_image(path, np.full((9, 13, 3), 0.5, np.float32))  # 13 columns x 9 rows
    tex.image = img = bpy.data.images.load(path)
    source = addon.heightfield.Source(obj)
    assert (source.rows, source.columns) == (9, 13) and source.warnings == []
    h = np.linspace(-0.3, 0.4, 9 * 13, dtype=np.float32).reshape(9, 13)
    source.write_back(h)
    assert tex.image is img and img.packed_file is not None
    np.testing.assert_allclose(_image_values(img), h + 0.5, atol=1e-6)
    np.testing.assert_allclose(addon.heightfield.Source(obj).heights, h, atol=1e-6)
    obj.modifiers["displace"].strength = -0.5     # negative strength: heights flip sign, height_scale stays > 0
    flipped = addon.heightfield.Source(obj)
    np.testing.assert_allclose(flipped.heights, -h, atol=1e-6)
    assert flipped.height_scale == pytest.approx(0.5)


# ---- light set-ups per target ----------------------------------------------------------------------
def _collection(name, *objects, parent=None):
    coll = bpy.data.collections.new(name)
    for o in objects:
        coll.objects.link(o)
    if parent is not None:
        parent.children.link(coll)
    return coll


def _add_light(kind, name, location, energy):
    bpy.ops.object.light_add(type=kind, location=location)
    light = bpy.context.active_object
    light.name = light.data.name = name
    light.data.energy = energy
    return light


def test_light_setup_exports_only_its_lights(addon):
    """A view's light collection: only the light objects in it (or in its child collections) are
    exported; other lights are left out; the world and emissive meshes stay."""
    lamp = bpy.data.objects["lamp"]
    fill = _add_light("POINT", "fill", (-2.0, -2.0, 3.0), 200.0)
    sun = _add_light("SUN", "sun", (0.0, 0.0, 5.0), 2.0)
    ball_bsdf = next(n for n in bpy.data.materials["ball_mat"].node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    _socket = addon.exporter._socket
    _socket(ball_bsdf, "Emission Color", "Emission").default_value = (1.0, 0.5, 0.2, 1.0)
    ball_bsdf.inputs["Emission Strength"].default_value = 2.0
    key = _collection("key", lamp)
    _collection("key_child", sun, parent=key)      # child collections count
    evening = _collection("evening", fill)
    everything, _ = addon.export_scene(spp=4)
    assert {"lamp", "fill", "sun", "world"} <= set(everything)
    desc, warnings = addon.export_scene(spp=4, light_collection=key)
    assert {"lamp", "sun", "world", "ball", "floor", "sensor"} <= set(desc) and "fill" not in desc
    assert desc["ball"]["emitter"]["radiance"] == pytest.approx([2.0, 1.0, 0.4])  # emissive meshes are not lights
    desc, _ = addon.export_scene(spp=4, light_collection=evening)
    assert "fill" in desc and "lamp" not in desc and "sun" not in desc and "world" in desc
    assert desc["fill"]["type"] == "point"
    # Problem exports each target with its own light set-up (a pair keeps all lights).
    cam = bpy.data.objects["camera"]
    img = _float_image("t", np.random.default_rng(0).random((48, 64, 3), dtype=np.float32))  # not constant
    seen = []
    real = addon.exporter.export_scene

    def spy(*args, **kwargs):
        d, w = real(*args, **kwargs)
        seen.append(sorted(k for k in ("lamp", "fill", "sun") if k in d))
        return d, w
    addon.exporter.export_scene = spy
    try:
        addon.optimize_ops.Problem(bpy.data.objects["ball"], [(cam, img, key), (cam, img, evening), (cam, img)], 4)
    finally:
        addon.exporter.export_scene = real
    assert seen == [["lamp", "sun"], ["fill"], ["fill", "lamp", "sun"]]


def test_light_setup_errors(addon):
    """A light collection without light objects is refused, naming the target and the collection,
    from the script API and from the operator; a bad entry names the target."""
    cam, ball = bpy.data.objects["camera"], bpy.data.objects["ball"]
    img = bpy.data.images.new("target", 64, 48, float_buffer=True)
    props = _collection("props", bpy.data.objects["floor"])  # a mesh, no lights
    with pytest.raises(ValueError, match=r"target 2 \(camera 'camera', image 'target'\): light collection 'props' "
                                         r"holds no light objects"):
        addon.optimize(ball, [(cam, img), (cam, img, props)], iterations=1)
    with pytest.raises(ValueError, match=r"target 1: the light set-up must be a Blender collection"):
        addon.optimize(ball, [(cam, img, "props")], iterations=1)
    with pytest.raises(ValueError, match=r"target 1: give \(camera, image\) or \(camera, image, light collection\)"):
        addon.optimize(ball, [(cam,)], iterations=1)
    hidden = _collection("hidden", bpy.data.objects["lamp"])
    bpy.data.objects["lamp"].hide_render = True
    with pytest.raises(ValueError, match=r"light collection 'hidden' \(lamp\) are all disabled in renders"):
        addon.optimize(ball, [(cam, img, hidden)], iterations=1)
    bpy.data.objects["lamp"].hide_render = False
    s = bpy.context.scene.limn
    s.optimize_object = ball
    t = s.targets.add()
    t.camera, t.image, t.light_collection = cam, img, props
    with pytest.raises(RuntimeError, match=r"light collection 'props' holds no light objects"):
        bpy.ops.limn.optimize()


def test_heightfield_optimisation_under_two_light_setups():
    """The heightfield paper's set-up: one camera, the field under a morning and an evening light,
    one target each (rendered from a known field under that light only). The loss falls."""
    addon, limn = _heightfield_addon("grid")
    obj = bpy.data.objects["terrain"]
    cam = bpy.data.objects["cam_front"]
    morning_lamp = bpy.data.objects["lamp"]
    evening_lamp = _add_light("AREA", "evening_lamp", (-2.0, 0.5, 1.2), 60.0)
    evening_lamp.data.size = 1.0
    scene_builder._look_at(evening_lamp, (0, 0, 0))
    morning, evening = _collection("morning", morning_lamp), _collection("evening", evening_lamp)
    n = 17
    co = _grid_z(obj)
    source = addon.heightfield.Source(obj)
    truth = 0.5 * scene_builder.bumps(n)
    co_true = co.copy()
    co_true[source.order, 2] = truth.ravel()
    obj.data.vertices.foreach_set("co", co_true.ravel())
    obj.data.update()
    def render(lights, spp):
        desc, _ = addon.export_scene(spp=spp, heightfields={"terrain"}, light_collection=lights)
        return limn.load_dict(desc).render(spp=spp, seed=11)

    renders = {"morning": render(morning, 64), "evening": render(evening, 64)}
    # Mean squared error of 32-spp renders against the targets (fit's 4-spp losses are noisy).
    image_loss = lambda: float(np.mean([((render(c, 32) - renders[k]) ** 2).mean()
                                        for k, c in (("morning", morning), ("evening", evening))]))
    # The two light set-ups give clearly different images.
    assert np.abs(renders["morning"] - renders["evening"]).mean() > 0.2 * renders["morning"].mean()
    obj.data.vertices.foreach_set("co", co.ravel())  # back to flat
    obj.data.update()
    border = (np.abs(co[:, 0]) > 0.99) | (np.abs(co[:, 1]) > 0.99)
    group = obj.vertex_groups.new(name="inner")
    group.add([int(i) for i in np.flatnonzero(~border)], 1.0, "REPLACE")
    loss0 = image_loss()
    targets = [(cam, _float_image("target_morning", renders["morning"]), morning),
               (cam, _float_image("target_evening", renders["evening"]), evening)]
    out = addon.optimize(obj, targets, iterations=20, spp=4, lr=0.05, lambda_=3.0, mode="HEIGHTFIELD",
                         mask_vertex_group="inner")
    L = out["losses"]
    heights = _grid_z(obj)[source.order, 2].reshape(n, n)
    loss1 = image_loss()
    rms = lambda h: float(np.sqrt(((h - truth) ** 2).mean()))
    print(f"two light set-ups: loss {np.mean(L[:3]):.5f} -> {np.mean(L[-5:]):.5f} (32 spp: {loss0:.5f} -> "
          f"{loss1:.5f}), height RMS error {rms(np.zeros_like(truth)):.3f} -> {rms(heights):.3f}, {out['seconds']:.1f} s")
    assert out["mode"] == "HEIGHTFIELD" and len(L) == 20
    assert np.mean(L[-5:]) < np.mean(L[:3]), L
    assert loss1 < 0.7 * loss0, (loss0, loss1)
    assert rms(heights) < 0.7 * rms(np.zeros_like(truth))


# ---- SDF mode: voxelise a mesh, optimise the grid, marching cubes back (issue 37) ---------------------
def _mesh_volume_centroid(obj):
    """Enclosed volume, centroid (object space) and closedness of the object's mesh (bmesh)."""
    import bmesh
    bm = bmesh.new()
    bm.from_mesh(obj.data)
    closed = all(e.is_manifold for e in bm.edges) and len(bm.faces) > 0
    bmesh.ops.triangulate(bm, faces=bm.faces[:])
    tris = np.array([[tuple(l.vert.co) for l in f.loops] for f in bm.faces], dtype=np.float64)
    bm.free()
    vol6 = np.einsum("ij,ij->i", tris[:, 0], np.cross(tris[:, 1], tris[:, 2]))
    return vol6.sum() / 6, (vol6[:, None] * tris.sum(axis=1)).sum(0) / (4 * vol6.sum()), closed


def test_sdf_optimisation_reaches_the_larger_ball(addon, limn):
    """The ball is voxelised into a limn SDF (16 samples across), optimised with the SDF mode's
    defaults (learning rate 0.1 voxel per iteration, gradient smoothing lambda 10 voxels^2,
    redistancing every 5 iterations) towards renders of the ball grown 1.25 times, and written
    back by marching cubes: after 25 iterations its volume is within 15 % of the target's, the
    mesh is closed and its centroid stays on the ball's centre. The mode before smoothing and
    redistancing (lr 0.05 world units, raw gradient) stopped at 2.78 to 2.86 of 4.12 (0.67-0.69),
    which fails the volume check. Then the operator from the panel's settings is one undo step."""
    ball, target_images, original = _ball_targets(addon, limn)
    v0, c0, closed0 = _mesh_volume_centroid(ball)
    assert closed0
    v_target = 1.25 ** 3 * v0
    out = addon.optimize(ball, target_images, iterations=25, spp=8, mode="SDF", sdf_resolution=16, sdf_padding=0.3)
    assert out["mode"] == "SDF" and out["sdf_shape"] == (16, 16, 16)
    v1, c1, closed1 = _mesh_volume_centroid(ball)
    losses = out["losses"]
    print(f"blender SDF optimisation: loss {losses[0]:.5f} -> {min(losses[-5:]):.5f} in {out['seconds']:.1f} s; "
          f"volume {v0:.3f} -> {v1:.3f} (target {v_target:.3f}, {v1 / v_target:.3f}), centroid {np.round(c1, 4)}, "
          f"voxel {out['voxel']:.3f}, {len(ball.data.vertices)} vertices")
    assert closed1, "the marching-cubes mesh is not closed"
    # Arrival: within 15 % of the target volume, i.e. the mean radius within 5 % (0.05, 0.3 voxel).
    # Measured 1.078 and 1.084 (Blender 3.4) and 1.081 (bpy 4.5) of the target; the same loop outside Blender
    # (limn.optim.fit on the exported problem) 0.97 to 1.04 from iteration 15 to 30: it arrives by
    # iteration 15 and then wanders with the 8-spp noise, which cannot tell radii 0.3 voxel apart
    # (8-spp loss 0.066 at the target against 0.085 at 0.1 smaller). Marching cubes of the exact
    # target-sized 16^3 grid gives 4.055 of 4.122 (-1.6 %).
    assert abs(v1 / v_target - 1) < 0.15, (v0, v1, v_target)
    assert out["redistanced"] == 5  # every 5 of the 25 steps
    assert min(losses[-5:]) < 0.7 * losses[0], losses
    # The cameras look down from 65-68 degrees, so the lower half is seen less; within 0.1, 60 % of
    # a 0.17 voxel.
    assert np.abs(c1 - c0).max() < 0.1, (c0, c1)

    # The operator (background mode: blocking) from the panel's settings, as one undo step; a mesh
    # without faces is refused naming the object.
    s = bpy.context.scene.limn
    s.optimize_object, s.optimize_mode, s.sdf_resolution, s.sdf_padding = ball, "SDF", 12, 0.3
    for c, im in target_images:
        t = s.targets.add()
        t.camera, t.image = c, im
    s.iterations, s.spp = 2, 4
    before = _vertices(ball)
    bpy.ops.ed.undo_push(message="before limn")
    assert bpy.ops.limn.optimize("EXEC_DEFAULT", True) == {"FINISHED"}  # True: push an undo step, as the UI does
    assert len(ball.data.vertices) * 3 != len(before) and _mesh_volume_centroid(ball)[2]
    bpy.ops.ed.undo()                             # the whole run, marching cubes included, is one undo step
    ball = bpy.data.objects["ball"]
    np.testing.assert_array_equal(_vertices(ball), before)
    ball.data.clear_geometry()
    with pytest.raises(RuntimeError, match="object 'ball'"):
        bpy.ops.limn.optimize()


def test_sdf_mode_in_the_ui_path_and_its_errors(addon, limn):
    """The worker-thread path (OptimizeJob, polled as the modal operator does): voxelising
    happens on the worker, the mesh is rewritten while running and at the end, a cancel keeps the
    last state; an open mesh, modifiers and a bad resolution are refused naming the object."""
    ball, target_images, original = _ball_targets(addon, limn)
    n0 = len(ball.data.vertices)
    Job = addon.optimize_ops.OptimizeJob
    problem = addon.optimize_ops.Problem(ball, target_images, 4, mode="SDF", sdf_resolution=12, sdf_padding=0.3)
    assert problem.views == []  # not voxelised yet: that is the worker's first step
    job = Job(problem, iterations=4, spp=4, lr=0.05, lambda_=0.0, write_every=2)
    job.start()
    status = _poll_to_end(job, timeout=300)
    assert status["status"] == "finished", status
    assert job.writes >= 2, job.writes
    assert len(ball.data.vertices) != n0 and _mesh_volume_centroid(ball)[2]

    job = Job(addon.optimize_ops.Problem(ball, target_images, 4, mode="SDF", sdf_resolution=12, sdf_padding=0.3),
              iterations=200, spp=4, lr=0.05, lambda_=0.0)
    job.start()
    while job.poll()["iteration"] < 1:
        time.sleep(0.02)
    job.cancel()
    status = _poll_to_end(job, timeout=120)
    assert status["status"] == "cancelled" and status["iteration"] < 199, status

    # Errors, each naming the object.
    with pytest.raises(ValueError, match=r"resolution must be within \[2, 1024\].*got 1\)"):
        addon.optimize(ball, target_images, mode="SDF", sdf_resolution=1)
    with pytest.raises(ValueError, match=r"object 'ball': SDF smoothing must be >= 0 \(got -1"):
        addon.optimize(ball, target_images, mode="SDF", sdf_smoothing=-1.0)
    with pytest.raises(ValueError, match=r"object 'ball': SDF redistance interval must be an integer >= 0 \(got 2.5"):
        addon.optimize(ball, target_images, mode="SDF", sdf_redistance_every=2.5)
    mod = ball.modifiers.new("sub", "SUBSURF")
    with pytest.raises(ValueError, match="object 'ball': its modifiers \\(sub\\)"):
        addon.optimize(ball, target_images, mode="SDF")
    ball.modifiers.remove(mod)
    import bmesh
    bm = bmesh.new()
    bm.from_mesh(ball.data)
    bm.faces.ensure_lookup_table()
    bmesh.ops.delete(bm, geom=[bm.faces[0]], context="FACES_ONLY")
    bm.to_mesh(ball.data)
    bm.free()
    with pytest.raises(ValueError, match="object 'ball'.*not closed and consistently oriented"):
        addon.optimize(ball, target_images, iterations=1, mode="SDF", sdf_resolution=8)
    with pytest.raises(ValueError, match="masks"):
        addon.optimize(ball, target_images, mode="SDF", mask_image=target_images[0][1])
