"""Runs the add-on tests with pytest inside Blender.

    blender -b --factory-startup -noaudio --python tests/blender/run.py -- [pytest args]   (Debian's 3.4)
    .venv/bin/python tests/blender/run.py [pytest args]                                   (bpy from PyPI)

The add-on is taken from build/addon (made by ./bootstrap.sh, with the compiled limn inside) unless
LIMN_ADDON_DIR names another folder."""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, HERE)
sys.path.insert(0, os.environ.get("LIMN_ADDON_DIR", os.path.join(ROOT, "build", "addon")))

import pytest  # noqa: E402

if "--" in sys.argv:
    args = sys.argv[sys.argv.index("--") + 1:]
elif sys.argv and sys.argv[0].endswith("run.py"):  # plain Python with the bpy module
    args = sys.argv[1:]
else:  # inside the blender executable, without extra arguments
    args = []
# tests/blender/window starts Blender in a window itself (run from a plain Python: ./test.sh).
sys.exit(pytest.main([HERE, "-q", "-p", "no:cacheprovider", "--rootdir", HERE, "--ignore", os.path.join(HERE, "window"),
                      *args]))
