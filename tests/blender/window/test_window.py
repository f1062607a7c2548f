"""The add-on in Debian's Blender 3.4 with a real window (Xvfb, Mesa llvmpipe): quitting, loading a
new file, deleting the object and a second Optimise while a limn job runs, and a limn render kept
as the optimisation target through save and reopen.

    .venv/bin/python -m pytest -q tests/blender/window        (./test.sh runs it)

Each test starts `xvfb-run blender --factory-startup --python driver.py -- SCENARIO OUT` as a
subprocess with a timeout; the scenario (scenarios.py) drives the modal operators from
bpy.app.timers with INVOKE_DEFAULT, the path a click takes, and ends Blender with
wm.quit_blender. The test checks the exit code, Blender's output and the facts the scenario wrote
(OUT/result.json). Set LIMN_WINDOW_SCREENSHOTS=1 to keep screenshots (imagemagick's import) of
the second-Optimise scenario in OUT. Runs in this Python (no bpy needed); skipped when Blender or
xvfb-run is missing."""
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

pytestmark = pytest.mark.skipif(shutil.which(BLENDER) is None or shutil.which("xvfb-run") is None,
                                reason="needs Blender and xvfb-run (Debian packages blender, xvfb)")

CRASH = re.compile(r"FATAL|Segmentation fault|Aborted|core dumped|Traceback|Error: Not freed memory|"
                   r"terminate called", re.IGNORECASE)


def run_scenario(name: str, tmp_path, timeout: float = 150.0):
    """Runs one scenario in a window; returns (exit code, output, facts, seconds)."""
    out = tmp_path / name
    out.mkdir()
    cmd = ["xvfb-run", "-a", "-s", "-screen 0 1280x800x24", BLENDER, "--factory-startup", "-noaudio",
           "--python", os.path.join(HERE, "driver.py"), "--", name, str(out)]
    t0 = time.time()
    try:
        p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=timeout)
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


def assert_clean_exit(code, output, facts):
    assert "error" not in facts, facts["error"]
    assert code == 0, f"Blender exited with {code} (134: abort, 139: segmentation fault)\n{output[-2000:]}"
    assert not CRASH.search(output), CRASH.search(output).group(0)


def test_quit_mid_render(tmp_path):
    code, output, facts, _ = run_scenario("quit_mid_render", tmp_path)
    assert facts.get("invoke") == "{'RUNNING_MODAL'}" and facts.get("workers_at_quit") == 1, facts
    assert facts.get("image_before_quit") is False, "the render ended before the quit: make it longer"
    assert_clean_exit(code, output, facts)
    assert re.search(r"limn: render .*stopped", output), "no message about the stopped render"


def test_quit_mid_optimise(tmp_path):
    code, output, facts, _ = run_scenario("quit_mid_optimise", tmp_path)
    assert facts.get("invoke") == "{'RUNNING_MODAL'}" and facts.get("moved_before_quit"), facts
    assert facts.get("workers_at_quit") == 1, facts
    assert_clean_exit(code, output, facts)
    assert re.search(r"limn: optimisation of 'ball' stopped", output), "no message about the stopped optimisation"


def test_new_file_mid_optimise(tmp_path):
    code, output, facts, _ = run_scenario("new_file_mid_optimise", tmp_path)
    assert facts.get("moved_before_new") and facts.get("workers_before_new") == 1, facts
    assert facts.get("workers_stopped"), f"the worker still ran {facts.get('stop_seconds', 0):.1f} s after File > New"
    print(f"File > New: the worker stopped {facts['stop_seconds']:.2f} s after read_homefile was called "
          f"(which took {facts['read_homefile_seconds']:.2f} s)")
    assert facts["stop_seconds"] < 3.0, facts
    assert re.search(r"limn: optimisation of 'ball' stopped: .*file", output), "no message about the stopped run"
    assert_clean_exit(code, output, facts)


def test_delete_object_mid_optimise(tmp_path):
    code, output, facts, _ = run_scenario("delete_mid_optimise", tmp_path)
    assert facts.get("moved_before_delete") and facts.get("delete") == "{'FINISHED'}", facts
    assert facts.get("in_scene_after_delete") is False, facts
    assert facts.get("orphan_written") is False, "the run wrote into the deleted object"
    assert facts.get("workers_stopped") and facts["stop_seconds"] < 3.0, facts
    assert re.search(r"limn: .*object 'ball' was deleted", output), "no message about the deleted object"
    assert_clean_exit(code, output, facts)


def test_second_optimise_is_refused(tmp_path):
    code, output, facts, _ = run_scenario("second_optimise", tmp_path)
    assert facts.get("first") == "{'RUNNING_MODAL'}", facts
    assert facts.get("second", "").find("already being optimised") >= 0, f"second Optimise: {facts.get('second')}"
    assert facts.get("workers_after_second") == 1, facts
    assert facts.get("all_finished") and facts.get("moved"), facts
    assert_clean_exit(code, output, facts)


def test_save_and_reopen_keeps_the_target(tmp_path):
    code, output, facts, _ = run_scenario("save_and_reopen", tmp_path)
    assert facts.get("rendered") and facts.get("size") == [64, 48] and facts.get("mean", 0) > 0.01, facts
    assert facts.get("reopened") and facts.get("target_is_image"), facts
    assert facts.get("same_pixels"), (f"after reopening, the target is {facts.get('size_after')} with mean "
                                      f"{facts.get('mean_after')} (saved: {facts.get('size')}, mean {facts.get('mean')})")
    assert_clean_exit(code, output, facts)
