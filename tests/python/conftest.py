"""Shared helpers for the Python tests: small scene dictionaries and image statistics."""
from __future__ import annotations

import os

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENES = os.path.join(ROOT, "scenes")
HERE = os.path.dirname(os.path.abspath(__file__))


# ---- test power (tests/bench/test_power.py, docs/reports/test_power.md) ---------------------------
# LIMN_TERM_SCALE="boundary=0.8" scales that derivative term by k in every render_forward /
# render_backward call (term_scale.py; without the variable nothing changes). A render-level
# derivative test names the term(s) whose value it checks with @pytest.mark.term(...).
TERM_HOOK_VARIABLES = ("LIMN_TERM_SCALE", "LIMN_TERM_MEMO", "LIMN_SEED_OFFSET")
if any(os.environ.get(v) for v in TERM_HOOK_VARIABLES):
    import term_scale
    term_scale.install()
    site = os.path.join(HERE, "term_scale_site")  # the hook in subprocesses too (CLI demos)
    os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (site, HERE, os.environ.get("PYTHONPATH")) if p)


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "term(*names): a render-level derivative test of these terms (interior, primary, boundary); "
                   "tests/bench/test_power.py runs it with each term scaled by k (docs/reports/test_power.md)")


def pytest_collection_modifyitems(config, items):
    for item in items:
        for mark in item.iter_markers("term"):
            bad = [n for n in mark.args if n not in ("interior", "primary", "boundary")] or not mark.args
            if bad:
                raise pytest.UsageError(f"{item.nodeid}: @pytest.mark.term needs terms among interior, primary, "
                                        f"boundary (got {mark.args})")


def pytest_report_header(config):
    if any(os.environ.get(v) for v in TERM_HOOK_VARIABLES):
        return "limn term hook: " + ", ".join(f"{v}={os.environ[v]}" for v in TERM_HOOK_VARIABLES if os.environ.get(v))


def scene_json(folder: str, name: str) -> dict:
    """<folder>/<name>.json as a dict."""
    import json
    with open(os.path.join(folder, name + ".json")) as f:
        return json.load(f)


def load_in(folder: str, d: dict):
    """A scene dict whose files (meshes, images) are relative to `folder`."""
    import limn
    return limn.load_dict(d, base_dir=folder)


def camera(origin, target, up=(0, 0, 1), fov=40.0, width=32, height=32, spp=16):
    return {"type": "perspective", "fov": fov,
            "to_world": {"look_at": {"origin": list(origin), "target": list(target), "up": list(up)}},
            "film": {"type": "hdrfilm", "width": width, "height": height},
            "sampler": {"type": "independent", "sample_count": spp}}


def sphere_over_plane(width=32, height=32, spp=16):
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 4},
        "sensor": camera((0, -4, 2), (0, 0, 0.5), width=width, height=height, spp=spp),
        "floor": {"type": "rectangle", "to_world": {"scale": 3}, "bsdf": {"type": "diffuse", "reflectance": 0.5}},
        "ball": {"type": "sphere", "center": [0, 0, 0.7], "radius": 0.6,
                 "bsdf": {"type": "diffuse", "reflectance": [0.8, 0.3, 0.2]}},
        "light": {"type": "rectangle",
                  "to_world": [{"scale": 0.5}, {"rotate": {"axis": [1, 0, 0], "angle": 180}}, {"translate": [0.5, -0.5, 3]}],
                  "emitter": {"type": "area", "radiance": 20.0}},
        "sky": {"type": "constant", "radiance": 0.1},
    }


def mean_and_stderr(samples: np.ndarray):
    samples = np.asarray(samples, dtype=np.float64)
    return samples.mean(), samples.std(ddof=1) / np.sqrt(samples.size)


@pytest.fixture
def scene_dict():
    return sphere_over_plane()


def pixel_rays(origin, target, up, fov_x_deg, width, height, offsets=((0.5, 0.5),)):
    """Ray directions through pixel positions, written out from docs/scene-format.md's camera model
    (an independent check of the camera): camera +z looks at the target, +y is up, +x is image left."""
    origin, target, up = (np.asarray(v, dtype=np.float64) for v in (origin, target, up))
    fwd = target - origin
    fwd /= np.linalg.norm(fwd)
    left = np.cross(up, fwd)
    left /= np.linalg.norm(left)
    cam_up = np.cross(fwd, left)
    tx = np.tan(np.radians(fov_x_deg) / 2)
    ty = tx * height / width
    out = []
    for ox, oy in offsets:
        x = (np.arange(width) + ox) / width
        y = (np.arange(height) + oy) / height
        X, Y = np.meshgrid(x, y)
        d = ((1 - 2 * X)[..., None] * tx * left + (1 - 2 * Y)[..., None] * ty * cam_up + fwd)
        out.append(d / np.linalg.norm(d, axis=-1, keepdims=True))
    return out
