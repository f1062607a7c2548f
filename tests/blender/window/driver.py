"""Runs one scenario of the window tests inside Blender with a real window (on an Xvfb display :N):

    DISPLAY=:N blender --factory-startup -noaudio \
        --python tests/blender/window/driver.py -- SCENARIO OUTDIR

The scenario is a generator (scenarios.py) stepped by one persistent bpy.app.timers function, so
every operator runs from Blender's event loop as a click does: INVOKE_DEFAULT inside
context.temp_override(window, area, region) of the Properties editor showing the Render tab (where
the limn panel is). Facts go to OUTDIR/result.json (written after every step, so a crash leaves
what was seen up to then); lines starting with "driver:" go to stdout. The scenario ends Blender
itself (wm.quit_blender); the test that started Blender checks the exit code, the output and the
files."""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(HERE)))
sys.path.insert(0, os.path.dirname(HERE))  # tests/blender: scene_builder
sys.path.insert(0, HERE)
sys.path.insert(0, os.environ.get("LIMN_ADDON_DIR", os.path.join(ROOT, "build", "addon")))

import harness  # noqa: E402

harness.main()
