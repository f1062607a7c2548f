"""Finds the limn Python package for the add-on and explains exactly what is wrong when it cannot.

Looked for, in order: an importable ``limn`` (e.g. installed into Blender's Python or on
PYTHONPATH), the directory named by the environment variable LIMN_PYTHONPATH, the add-on
preference "limn module folder", and the copy bundled inside the add-on (``vendor/``)."""
from __future__ import annotations

import importlib
import os
import sys
import sysconfig

_ADDON_DIR = os.path.dirname(os.path.abspath(__file__))
_VENDOR_DIR = os.path.join(_ADDON_DIR, "vendor")


class LimnNotFound(RuntimeError):
    pass


def _candidates(extra_dir: str | None) -> list[tuple[str, str | None]]:
    out: list[tuple[str, str | None]] = [("already importable", None)]
    env = os.environ.get("LIMN_PYTHONPATH")
    if env:
        out.append(("LIMN_PYTHONPATH", env))
    if extra_dir:
        out.append(("add-on preference", extra_dir))
    out.append(("bundled with the add-on", _VENDOR_DIR))
    return out


def _diagnose(folder: str) -> str:
    pkg = os.path.join(folder, "limn")
    if not os.path.isdir(pkg):
        return f"no folder 'limn' in {folder}"
    suffix = sysconfig.get_config_var("EXT_SUFFIX") or ".so"
    cores = [f for f in os.listdir(pkg) if f.startswith("_core")]
    if not cores:
        return f"{pkg} has no compiled module _core*.so (build limn with ./bootstrap.sh)"
    if not any(f.endswith(suffix) for f in cores):
        return (f"{pkg} holds {', '.join(cores)}, but this Blender runs Python "
                f"{sys.version_info.major}.{sys.version_info.minor} and needs a module ending in '{suffix}'")
    return ""


def import_limn(extra_dir: str | None = None):
    """Returns the limn module or raises LimnNotFound with every place tried and why it failed."""
    reasons = []
    for label, folder in _candidates(extra_dir):
        if folder is not None:
            if not os.path.isdir(folder):
                reasons.append(f"{label}: folder {folder} does not exist")
                continue
            problem = _diagnose(folder)
            if problem:
                reasons.append(f"{label}: {problem}")
                continue
            if folder not in sys.path:
                sys.path.insert(0, folder)
        try:
            module = importlib.import_module("limn")
            importlib.import_module("limn._core")
            return module
        except ImportError as e:
            reasons.append(f"{label}: import failed: {e}")
            sys.modules.pop("limn", None)
            if folder is not None and folder in sys.path:
                sys.path.remove(folder)
    raise LimnNotFound("limn could not be imported into Blender's Python "
                       f"({sys.executable}, Python {sys.version.split()[0]}):\n  " + "\n  ".join(reasons))
