"""Assembles the Blender add-on with the compiled limn package inside it.

    python3 blender_addon/package.py --out build
gives build/addon/limn_blender/ (enable it from there, or copy it to Blender's add-on folder)
and build/limn_blender.zip (installable from Blender's preferences, as add-on or extension).
The limn package is taken from the Python running this script (the project's .venv)."""
from __future__ import annotations

import argparse
import os
import shutil
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="build")
    args = parser.parse_args()
    try:
        import limn
    except ImportError as e:
        print(f"package.py: limn is not importable from {sys.executable} ({e}); run ./bootstrap.sh first", file=sys.stderr)
        return 1
    dest = os.path.join(args.out, "addon", "limn_blender")
    if os.path.isdir(dest):
        shutil.rmtree(dest)
    shutil.copytree(os.path.join(HERE, "limn_blender"), dest, ignore=shutil.ignore_patterns("__pycache__", "vendor"))
    shutil.copytree(os.path.dirname(limn.__file__), os.path.join(dest, "vendor", "limn"),
                    ignore=shutil.ignore_patterns("__pycache__"))
    archive = shutil.make_archive(os.path.join(args.out, "limn_blender"), "zip", os.path.join(args.out, "addon"), "limn_blender")
    print(f"add-on folder: {os.path.abspath(dest)}")
    print(f"add-on zip:    {os.path.abspath(archive)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
