"""The add-on in Debian's Blender 3.4 with a real window (Xvfb, Mesa llvmpipe): quitting, loading a
new file, deleting the object and a second Optimise while a limn job runs, and a limn render kept
as the optimisation target through save and reopen.

    .venv/bin/python -m pytest -q tests/blender/window        (./test.sh runs it)

The module starts one Xvfb; each test starts `blender --factory-startup --python driver.py --
SCENARIO OUT` on it as a subprocess with a timeout; the scenario (scenarios.py) drives the modal operators from
bpy.app.timers with INVOKE_DEFAULT, the path a click takes, and ends Blender with
wm.quit_blender. The test checks the exit code, Blender's output and the facts the scenario wrote
(OUT/result.json). Set LIMN_WINDOW_SCREENSHOTS=1 to keep screenshots (imagemagick's import) of
the second-Optimise scenario in OUT. Runs in this Python (no bpy needed); skipped when Blender or
Xvfb is missing."""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import time

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
BLENDER = os.environ.get("LIMN_BLENDER", "blender")

pytestmark = pytest.mark.skipif(shutil.which(BLENDER) is None or shutil.which("Xvfb") is None,
                                reason="needs Blender and Xvfb (Debian packages blender, xvfb)")

CRASH = re.compile(r"FATAL|Segmentation fault|Aborted|core dumped|Traceback|Error: Not freed memory|"
                   r"terminate called", re.IGNORECASE)


@pytest.fixture(scope="module")
def display():
    """An X server (Xvfb, 1280 x 800, 24 bits) for the module's tests; its display name. Started
    here rather than with xvfb-run, so that each test sees Blender's own exit code; -displayfd
    lets Xvfb pick a free display number."""
    read, write = os.pipe()
    server = subprocess.Popen(["Xvfb", "-displayfd", str(write), "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
                              pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write)
    with os.fdopen(read) as f:
        number = f.readline().strip()
    if not number:
        server.kill()
        pytest.fail("Xvfb did not start")
    yield f":{number}"
    server.terminate()
    server.wait(timeout=30)


def run_scenario(name: str, tmp_path, display: str, timeout: float = 150.0):
    """Runs one scenario in a window; returns (exit code, output, facts, seconds)."""
    out = tmp_path / name
    out.mkdir()
    cmd = [BLENDER, "--factory-startup", "-noaudio", "--python", os.path.join(HERE, "driver.py"), "--", name, str(out)]
    t0 = time.time()
    try:
        p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=timeout,
                           env={**os.environ, "DISPLAY": display})
        code, output = p.returncode, p.stdout
    except subprocess.TimeoutExpired as e:
        code, output = "timeout", (e.stdout or b"").decode(errors="replace") if isinstance(e.stdout, bytes) else (e.stdout or "")
    seconds = time.time() - t0
    (out / "output.txt").write_text(output)
    try:
        facts = json.loads((out / "result.json").read_text())
    except (OSError, ValueError):
        facts = {}
    print(f"{name}: exit {code} after {seconds:.1f} s; facts {facts}")
    print(output[-3000:])
    return code, output, facts, seconds


def assert_clean_exit(code, output, facts, expected=0):
    assert "error" not in facts, facts["error"]
    assert code == expected, f"Blender exited with {code} (-6: abort, -11: segmentation fault; 134 and 139 in a shell)\n{output[-2000:]}"
    assert not CRASH.search(output), CRASH.search(output).group(0)


def test_quit_mid_render(tmp_path, display):
    code, output, facts, _ = run_scenario("quit_mid_render", tmp_path, display)
    assert facts.get("invoke") == "{'RUNNING_MODAL'}" and facts.get("workers_at_quit") == 1, facts
    assert facts.get("image_before_quit") is False, "the render ended before the quit: make it longer"
    assert_clean_exit(code, output, facts)
    assert re.search(r"limn: render .*stopped", output), "no message about the stopped render"


def test_quit_mid_optimise(tmp_path, display):
    code, output, facts, _ = run_scenario("quit_mid_optimise", tmp_path, display)
    assert facts.get("invoke") == "{'RUNNING_MODAL'}" and facts.get("moved_before_quit"), facts
    assert facts.get("workers_at_quit") == 1, facts
    assert_clean_exit(code, output, facts)
    assert re.search(r"limn: optimisation of 'ball' stopped", output), "no message about the stopped optimisation"


def test_ctrl_q_dont_save_mid_optimise(tmp_path, display):
    """Real keys (xdotool): Ctrl+Q, then D (the accelerator of "Don't Save") in "Save changes
    before closing?", while an optimisation runs."""
    if shutil.which("xdotool") is None:
        pytest.skip("needs xdotool (Debian package xdotool)")
    code, output, facts, _ = run_scenario("ctrl_q_mid_optimise", tmp_path, display)
    assert facts.get("moved_before_quit") and facts.get("workers_with_dialog") == 1, facts
    assert "still_running_after_dont_save" not in facts, "Blender did not quit"
    assert_clean_exit(code, output, facts)
    assert re.search(r"limn: optimisation of 'ball' stopped", output), "no message about the stopped optimisation"


def test_new_file_mid_optimise(tmp_path, display):
    code, output, facts, _ = run_scenario("new_file_mid_optimise", tmp_path, display)
    assert facts.get("moved_before_new") and facts.get("workers_before_new") == 1, facts
    assert facts.get("workers_stopped"), f"the worker still ran {facts.get('stop_seconds', 0):.1f} s after File > New"
    print(f"File > New: the worker stopped {facts['stop_seconds']:.2f} s after read_homefile was called "
          f"(which took {facts['read_homefile_seconds']:.2f} s)")
    assert facts["stop_seconds"] < 3.0, facts
    assert re.search(r"limn: optimisation of 'ball' stopped: .*file", output), "no message about the stopped run"
    assert_clean_exit(code, output, facts)


def test_delete_object_mid_optimise(tmp_path, display):
    code, output, facts, _ = run_scenario("delete_mid_optimise", tmp_path, display)
    assert facts.get("moved_before_delete") and facts.get("delete") == "{'FINISHED'}", facts
    assert facts.get("in_scene_after_delete") is False, facts
    assert facts.get("orphan_written") is False, "the run wrote into the deleted object"
    assert facts.get("workers_stopped") and facts["stop_seconds"] < 3.0, facts
    assert re.search(r"limn: .*object 'ball' was deleted", output), "no message about the deleted object"
    assert_clean_exit(code, output, facts)


def test_second_optimise_is_refused(tmp_path, display):
    code, output, facts, _ = run_scenario("second_optimise", tmp_path, display)
    assert facts.get("first") == "{'RUNNING_MODAL'}", facts
    assert facts.get("second", "").find("already being optimised") >= 0, f"second Optimise: {facts.get('second')}"
    assert facts.get("workers_after_second") == 1, facts
    assert facts.get("all_finished") and facts.get("moved"), facts
    assert_clean_exit(code, output, facts)


def test_save_and_reopen_keeps_the_target(tmp_path, display):
    code, output, facts, _ = run_scenario("save_and_reopen", tmp_path, display)
    assert facts.get("rendered") and facts.get("size") == [64, 48] and facts.get("mean", 0) > 0.01, facts
    assert facts.get("reopened") and facts.get("target_is_image"), facts
    assert facts.get("same_pixels"), (f"after reopening, the target is {facts.get('size_after')} with mean "
                                      f"{facts.get('mean_after')} (saved: {facts.get('size')}, mean {facts.get('mean')})")
    assert_clean_exit(code, output, facts)


def test_escape_key_cancels_and_keeps_the_last_state(tmp_path, display):
    """Esc pressed on the keyboard (xdotool) during an optimisation: it stops and keeps its state."""
    if shutil.which("xdotool") is None:
        pytest.skip("needs xdotool (Debian package xdotool)")
    code, output, facts, _ = run_scenario("escape_mid_optimise", tmp_path, display)
    assert facts.get("invoke") == "{'RUNNING_MODAL'}" and facts.get("moved_before_escape"), facts
    # The key reaches the modal operator after about 1 s here (X input through Blender's event loop).
    print(f"Esc: seen by the job after {facts.get('escape_seen_seconds', float('nan')):.2f} s, worker ended after "
          f"{facts.get('stop_seconds', float('nan')):.2f} s")
    assert facts.get("workers_stopped") and facts["stop_seconds"] < 5.0, facts
    assert facts.get("kept"), facts
    assert re.search(r"limn: iteration \d+/400, loss [0-9.]+, cancelled \(Esc pressed\)", output), output[-1500:]
    # Blender 3.4 exits with its global break flag, which any Esc press sets: 1 (also without limn).
    assert_clean_exit(code, output, facts, expected=1)


def test_curve_object_optimised_from_the_panel(tmp_path, display):
    """The modal operator on a curve object: it writes the spline while running, ends, and one undo
    brings the start back."""
    code, output, facts, _ = run_scenario("curve_optimise", tmp_path, display)
    assert facts.get("invoke") == "{'RUNNING_MODAL'}", facts
    assert facts.get("moved_while_running") and facts.get("ended"), facts
    assert facts.get("count") == 6 and facts.get("still_a_curve") and facts.get("moved_at_end", 0) > 1e-3, facts
    assert facts.get("undo_restored"), facts
    assert_clean_exit(code, output, facts)


def test_sdf_optimised_from_the_panel(tmp_path, display):
    """SDF mode from the panel (modal operator, worker thread) on the ball, 8 iterations at the
    panel's SDF defaults: the mesh is rewritten (marching cubes) while the worker runs, the run
    ends, the result is closed, flat shaded, keeps its material and has grown towards the target
    (volume 1.25^3 times the ball's), Blender quits cleanly, and one undo brings the ball back."""
    # About a minute on an idle 2-core machine; 8 minutes were not enough at a load average of 30.
    code, output, facts, seconds = run_scenario("sdf_optimise", tmp_path, display, timeout=900.0)
    assert facts.get("invoke") == "{'RUNNING_MODAL'}", facts
    assert facts.get("panel") == {"learning_rate": pytest.approx(0.1), "smoothing": pytest.approx(10.0),
                                  "redistance_every": 5}, facts
    assert facts.get("written_while_running") and facts.get("ended"), facts
    v0, v1, target = facts["volume_before"], facts["volume_after"], facts["volume_target"]
    print(f"SDF from the panel: volume {v0:.3f} -> {v1:.3f} (target {target:.3f}), {facts['vertices_before']} -> "
          f"{facts['vertices_after']} vertices, {seconds:.0f} s")
    assert facts.get("closed_before") and facts.get("closed_after") and facts.get("flat"), facts
    assert facts.get("material") == "ball_mat", facts
    # 8 iterations at 4 spp: a quarter of the way at least (measured outside Blender at 8 spp: 0.3 of
    # the way after 5 iterations, 0.7 after 10); the headless test checks arrival (25 iterations).
    assert v0 + 0.25 * (target - v0) < v1 < 1.15 * target, facts
    assert facts.get("undo_restored"), facts
    assert_clean_exit(code, output, facts)
