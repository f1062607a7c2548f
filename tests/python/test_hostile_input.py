"""Hostile input battery: limn used as a hostile user would.

Well over 1000 generated cases (scene dictionaries and JSON files with wrong types, huge, tiny and
non-finite numbers, deep nesting, unknown keys and bad references; OBJ and PLY files (ASCII, binary
little and big endian) truncated, garbled, with huge counts and bad indices; images truncated, empty,
garbled or claiming huge sizes, as textures, environment maps and heightfields; transforms of 1e38,
1e300, 1e-300 and singular ones on every kind of object; the inputs that once crashed a fuzz target;
and the runtime calls: render / render_forward / render_backward with absurd thread and sample counts,
huge tangents and adjoints, update() after huge or NaN parameters and far translations, Adam with
lr=inf or betas=(1, 1)). Each case runs in a subprocess with a watchdog; cases are batched, and a
case whose batch crashed or hung is run again alone, so that the crash or hang is attributed to it.

Every outcome is classified:
  ok                   the call returned and every output (images, gradients, parameters) is finite
  clean error          ValueError / TypeError / KeyError whose message names the object and the field
  unclear error        any other exception, or a message that does not name them
  nonsense accepted    the input is nonsense and was accepted (or an unknown key was not warned about)
  valid input refused  the input is valid and was refused
  non-finite output    a finite input gave a NaN or infinite output
  crash                the process died (a signal)
  hang                 the case did not finish within the timeout

The tests assert that nothing but "ok" and "clean error" occurs. For the counts per class and the
failing cases (also against another build, e.g. the code before a change):

    .venv/bin/python tests/python/test_hostile_input.py [--area load|runtime] [--json out.json]
    PYTHONPATH=/path/to/other/site-packages .venv/bin/python tests/python/test_hostile_input.py
"""
from __future__ import annotations

import collections
import glob
import json
import math
import os
import select
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
import warnings
import zlib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
FUZZ_CORPUS = os.path.join(ROOT, "tests", "fuzz", "corpus")
CASE_TIMEOUT = 15.0      # seconds per case (loading or rendering a tiny scene takes milliseconds)
STARTUP_TIMEOUT = 120.0  # importing limn and generating the cases in a worker
JOBS = 2
CLEAN = ("ok", "clean error")
CLASSES = ("ok", "clean error", "unclear error", "nonsense accepted", "valid input refused", "non-finite output", "crash", "hang")


class Case:
    """One hostile input: `run(tmp)` performs it in folder `tmp` and returns the outputs to check.
    expect: "error" (nonsense: must be refused), "ok" (valid: must work), "either" (finite outputs or
    a clean error), "warn" (accepted with a warning that names `names`). `names`: fragments an error
    message (or the warning) must contain: the object and the field, or the file and the place."""

    __slots__ = ("id", "area", "expect", "names", "run")

    def __init__(self, id, area, expect, names, run):
        self.id, self.area, self.expect, self.names, self.run = id, area, expect, tuple(names), run


# ---- helpers ------------------------------------------------------------------------------------

def nest(depth: int):
    v = 0
    for _ in range(depth):
        v = [v]
    return v


def set_path(d: dict, path: tuple, value) -> None:
    for k in path[:-1]:
        d = d[k]
    d[path[-1]] = value


def base_scene() -> dict:
    """Every kind of object, tiny film: loading and a 1-spp render take milliseconds."""
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 45,
                   "to_world": {"look_at": {"origin": [0, -5, 2.5], "target": [0, 0, 0.5], "up": [0, 0, 1]}},
                   "film": {"type": "hdrfilm", "width": 8, "height": 8},
                   "sampler": {"type": "independent", "sample_count": 1}},
        "floor": {"type": "rectangle", "to_world": {"scale": 3}, "bsdf": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
        "ball": {"type": "sphere", "center": [0, 0, 0.7], "radius": 0.6,
                 "bsdf": {"type": "roughconductor", "material": "Cu", "alpha": 0.2, "distribution": "ggx"}},
        "glass": {"type": "dielectric", "int_ior": 1.5},
        "box": {"type": "cube", "to_world": [{"scale": 0.3}, {"translate": [1.2, 0.5, 0.3]}], "bsdf": {"type": "ref", "id": "glass"}},
        "tri": {"type": "mesh", "vertex_positions": np.array([[-1.5, 1, 0.2], [-0.5, 1, 0.2], [-1, 1.5, 1]], np.float32),
                "faces": np.array([[0, 1, 2]], np.int32)},
        "hf": {"type": "heightfield", "data": np.array([[0, 0.1, 0], [0.1, 0.3, 0.1], [0, 0.1, 0]], np.float32),
               "size": [1, 1], "height_scale": 1.0, "to_world": {"translate": [1, -1, 0]}},
        "light": {"type": "rectangle", "to_world": [{"scale": 0.5}, {"rotate": {"axis": [1, 0, 0], "angle": 180}}, {"translate": [0, 0, 3]}],
                  "emitter": {"type": "area", "radiance": 10.0}},
        "lamp": {"type": "point", "position": [2, -2, 3], "intensity": 5.0},
        "sun": {"type": "directional", "direction": [0.3, 0.2, -1], "irradiance": 1.0},
        "sky": {"type": "constant", "radiance": 0.1},
    }


def small_scene(**objects) -> dict:
    """A camera, a light and the objects under test."""
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": 45,
                    "to_world": {"look_at": {"origin": [0, -5, 2.5], "target": [0, 0, 0.5], "up": [0, 0, 1]}},
                    "film": {"type": "hdrfilm", "width": 8, "height": 8}},
         "sky": {"type": "constant", "radiance": 0.5}}
    d.update(objects)
    return d


def outputs_of(scene) -> list:
    """A loaded scene's parameters and, if its film is small, a 1-spp render."""
    out = [np.array(scene.params[n]) for n in scene.params]
    if scene.width * scene.height <= 64 * 64:
        out.append(scene.render(spp=1, seed=0))
    return out


def load_dict_case(make):
    def run(tmp):
        import limn
        return outputs_of(limn.load_dict(make(), base_dir=tmp))
    return run


def write(tmp, name, data) -> str:
    p = os.path.join(tmp, name)
    with open(p, "wb") as f:
        f.write(data if isinstance(data, bytes) else data.encode())
    return p


# ---- A. scene dictionaries: every field, every kind of bad value ---------------------------------

# (path in the scene, the names an error must contain, kind of value)
FIELDS = [
    (("ball", "radius"), ("ball", "radius"), "pos"),
    (("ball", "center"), ("ball", "center"), "vec3"),
    (("ball", "to_world"), ("ball", "to_world"), "transform"),
    (("ball", "bsdf", "alpha"), ("ball", "alpha"), "pos"),
    (("ball", "bsdf", "distribution"), ("ball", "distribution"), "enum"),
    (("ball", "bsdf", "material"), ("ball", "material"), "enum"),
    (("floor", "to_world"), ("floor", "to_world"), "transform"),
    (("floor", "face_normals"), ("floor", "face_normals"), "bool"),
    (("floor", "bsdf", "reflectance"), ("floor", "reflectance"), "colour"),
    (("glass", "int_ior"), ("glass", "int_ior"), "ior"),
    (("box", "to_world"), ("box", "to_world"), "transform"),
    (("tri", "vertex_positions"), ("tri", "vertex_positions"), "array"),
    (("tri", "faces"), ("tri", "faces"), "array"),
    (("tri", "corner_uvs"), ("tri", "corner_uvs"), "array"),
    (("tri", "allow_degenerate"), ("tri", "allow_degenerate"), "bool"),
    (("hf", "data"), ("hf", "data"), "array"),
    (("hf", "size"), ("hf", "size"), "size2"),
    (("hf", "height_scale"), ("hf", "height_scale"), "pos"),
    (("hf", "to_world"), ("hf", "to_world"), "transform"),
    (("sensor", "fov"), ("sensor", "fov"), "fov"),
    (("sensor", "fov_axis"), ("sensor", "fov_axis"), "enum"),
    (("sensor", "near_clip"), ("sensor", "near_clip"), "pos"),
    (("sensor", "far_clip"), ("sensor", "far_clip"), "pos"),
    (("sensor", "to_world"), ("sensor", "to_world"), "transform"),
    (("sensor", "film", "width"), ("film", "width"), "count"),
    (("sensor", "film", "height"), ("film", "height"), "count"),
    (("sensor", "sampler", "sample_count"), ("sampler", "sample_count"), "count"),
    (("integrator", "max_depth"), ("integrator", "max_depth"), "depth"),
    (("integrator", "rr_depth"), ("integrator", "rr_depth"), "count"),
    (("light", "emitter", "radiance"), ("light", "radiance"), "colour"),
    (("lamp", "position"), ("lamp", "position"), "vec3"),
    (("lamp", "intensity"), ("lamp", "intensity"), "colour"),
    (("sun", "direction"), ("sun", "direction"), "direction"),
    (("sun", "irradiance"), ("sun", "irradiance"), "colour"),
    (("sky", "radiance"), ("sky", "radiance"), "colour"),
]

# label -> a function making the value (made when the case runs: some are large)
VALUES = {
    "none": lambda: None, "string": lambda: "bogus", "true": lambda: True, "empty_list": lambda: [], "empty_dict": lambda: {},
    "list2": lambda: [1, 2], "list4": lambda: [1, 2, 3, 4], "typed_dict": lambda: {"type": 3},
    "ragged": lambda: [[1, 2], [3]], "ragged_depth": lambda: [[0, 0], [[0], [0]]],
    "neg": lambda: -1, "zero": lambda: 0, "half": lambda: 0.5, "1e38": lambda: 1e38, "3.4e38": lambda: 3.4e38,
    "1e300": lambda: 1e300, "-1e300": lambda: -1e300, "1e-300": lambda: 1e-300, "5e-324": lambda: 5e-324,
    "int_1e30": lambda: 10 ** 30, "int_2^64": lambda: 2 ** 64, "int_1e400": lambda: 10 ** 400,
    "nan": lambda: float("nan"), "inf": lambda: float("inf"), "-inf": lambda: -float("inf"),
    "np_float32_nan": lambda: np.float32("nan"), "np_0d": lambda: np.array(0.5), "np_0d_nan": lambda: np.array(np.nan),
    "np_inf_vec": lambda: np.array([np.inf, 0.0, 0.0]), "np_strings": lambda: np.array(["a", "b", "c"]),
    "np_complex": lambda: np.array([1j, 0, 0]), "deep_300": lambda: nest(300), "deep_100000": lambda: nest(100000),
    "lone_surrogate": lambda: "\udc80", "nul_char": lambda: "a\x00b", "long_string": lambda: "x" * 100000,
    "vec_nan": lambda: [0, float("nan"), 0], "vec_1e300": lambda: [1e300, 0, 0], "vec_1e38": lambda: [1e38, 1e38, 1e38],
    "vec_str": lambda: ["a", 1, 2], "vec_zero": lambda: [0, 0, 0], "vec_neg": lambda: [-1, -1, -1], "vec_1e-300": lambda: [1e-300, 0, 0],
}
# Values that are valid (or may be: "either") for a kind; every other value must be refused.
VALID = {
    "pos": {"half": "ok", "np_0d": "ok", "1e38": "either", "3.4e38": "either", "int_1e30": "either", "int_2^64": "either"},
    "vec3": {"vec_zero": "ok", "vec_neg": "ok", "vec_1e38": "either", "vec_1e-300": "either"},
    "direction": {"vec_neg": "ok", "vec_1e38": "either", "vec_1e-300": "either"},
    "colour": {"zero": "ok", "half": "ok", "np_0d": "ok", "vec_zero": "ok", "1e38": "either", "3.4e38": "either", "int_1e30": "either",
               "int_2^64": "either", "vec_1e38": "either", "1e-300": "either", "5e-324": "either", "vec_1e-300": "either"},
    "ior": {"half": "ok", "np_0d": "ok", "1e38": "either", "3.4e38": "either", "int_1e30": "either", "int_2^64": "either"},
    "bool": {"true": "ok"},
    "enum": {},
    "transform": {"empty_list": "either"},
    "array": {},
    "size2": {"list2": "ok"},
    "fov": {"half": "ok", "np_0d": "ok"},
    "count": {},
    "depth": {"neg": "ok", "zero": "ok"},
}


def dict_field_cases() -> list[Case]:
    cases = []
    for path, names, kind in FIELDS:
        for label, make_value in VALUES.items():
            expect = VALID[kind].get(label, "error")

            def make(path=path, make_value=make_value):
                d = base_scene()
                set_path(d, path, make_value())
                return d
            cases.append(Case(f"dict/{'.'.join(path)}={label}", "load", expect, names, load_dict_case(make)))
    return cases


def tri_positions(scale=1.0, dtype=np.float32):
    return (np.array([[-1.5, 1, 0.2], [-0.5, 1, 0.2], [-1, 1.5, 1]]) * scale).astype(dtype)


def dict_specific_cases() -> list[Case]:
    """Values that are wrong only for one field: shapes, indices, degenerate and huge meshes,
    heightfield sizes, unknown keys, bad references, structural mistakes."""
    specific = [
        # meshes from arrays
        (("tri", "vertex_positions"), ("tri", "vertex_positions"), "error", lambda: np.zeros((3, 2), np.float32)),
        (("tri", "vertex_positions"), ("tri", "vertex_positions"), "error", lambda: np.zeros((3, 3, 1), np.float32)),
        (("tri", "vertex_positions"), ("tri", "vertex"), "error", lambda: np.zeros((0, 3), np.float32)),
        (("tri", "vertex_positions"), ("tri", "degenerate"), "error", lambda: np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], np.float32)),
        (("tri", "vertex_positions"), ("tri", "vertex_positions"), "error", lambda: tri_positions(1e38)),
        (("tri", "vertex_positions"), ("tri", "vertex_positions"), "error", lambda: tri_positions(1e300, np.float64)),
        (("tri", "vertex_positions"), ("tri",), "either", lambda: tri_positions(1e18)),
        (("tri", "vertex_positions"), ("tri",), "error", lambda: tri_positions(1e-30)),
        (("tri", "vertex_positions"), ("tri",), "ok", lambda: tri_positions(1e-10)),
        (("tri", "vertex_positions"), ("tri",), "ok", lambda: tri_positions(1.0, np.float64)),
        (("tri", "vertex_positions"), ("tri",), "ok", lambda: tri_positions(1.0).astype(np.int32)),
        (("tri", "vertex_positions"), ("tri",), "ok", lambda: tri_positions(1.0).tolist()),
        (("tri", "vertex_positions"), ("tri", "vertex_positions"), "error", lambda: np.array([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]])),
        (("tri", "faces"), ("tri", "faces"), "error", lambda: np.array([[0, 1, 5]])),
        (("tri", "faces"), ("tri", "faces"), "error", lambda: np.array([[-1, 0, 1]])),
        (("tri", "faces"), ("tri", "faces"), "error", lambda: np.array([[0, 1, 2 ** 40]])),
        (("tri", "faces"), ("tri", "faces"), "error", lambda: np.array([[0.0, 1.0, 2.0]])),
        (("tri", "faces"), ("tri", "faces"), "error", lambda: np.array([[0, 1]])),
        (("tri", "faces"), ("tri", "faces"), "error", lambda: np.array([0, 1, 2])),
        (("tri", "faces"), ("tri", "faces"), "error", lambda: np.zeros((0, 3), np.int32)),
        (("tri", "vertex_positions"), ("tri", "vertex_positions"), "error", lambda: tri_positions(1e18) * np.float32(10)),
        (("tri", "faces"), ("tri", "degenerate"), "error", lambda: np.array([[0, 0, 1]])),
        (("tri", "faces"), ("tri",), "ok", lambda: np.array([[0, 1, 2]], np.uint64)),
        (("tri", "faces"), ("tri",), "either", lambda: np.array([[0, 1, 2], [0, 2, 1]])),
        (("tri", "faces"), ("tri", "faces"), "error", lambda: [[0, 1, 2], [0, 1]]),
        (("tri", "corner_uvs"), ("tri", "corner_uvs"), "error", lambda: np.zeros((1, 6), np.float32)),
        (("tri", "corner_uvs"), ("tri", "corner_uvs"), "error", lambda: np.zeros((2, 3, 2), np.float32)),
        (("tri", "corner_uvs"), ("tri", "corner_uvs"), "error", lambda: np.full((1, 3, 2), np.nan)),
        (("tri", "corner_uvs"), ("tri",), "ok", lambda: np.zeros((1, 3, 2), np.float32)),
        (("tri", "corner_uvs"), ("tri",), "either", lambda: np.full((1, 3, 2), 1e38, np.float32)),
        # heightfields from arrays
        (("hf", "data"), ("hf", "data"), "error", lambda: np.zeros((1, 5), np.float32)),
        (("hf", "data"), ("hf", "data"), "error", lambda: np.zeros((3, 3, 3), np.float32)),
        (("hf", "data"), ("hf", "data"), "error", lambda: np.zeros((0, 0), np.float32)),
        (("hf", "data"), ("hf", "data"), "error", lambda: np.full((3, 3), np.nan)),
        (("hf", "data"), ("hf", "data"), "error", lambda: np.full((3, 3), 1e300)),
        (("hf", "data"), ("hf",), "error", lambda: np.full((3, 3), 1e38, np.float32)),
        (("hf", "data"), ("hf", "data"), "error", lambda: np.zeros((5000, 5000), np.float32)),
        (("hf", "data"), ("hf",), "ok", lambda: np.zeros((2, 2), np.float32)),
        (("hf", "data"), ("hf",), "either", lambda: np.full((3, 3), 1e10, np.float32)),
        (("hf", "data"), ("hf",), "ok", lambda: [[0, 0.1], [0.2, 0.3]]),
        (("hf", "size"), ("hf", "size"), "error", lambda: [0, 1]),
        (("hf", "size"), ("hf", "size"), "error", lambda: [1e300, 1]),
        (("hf", "size"), ("hf",), "error", lambda: [1e30, 1e30]),
        (("hf", "size"), ("hf", "size"), "error", lambda: [-1, 1]),
        (("hf", "size"), ("hf",), "error", lambda: [1e-30, 1e-30]),
        # sensor
        (("sensor", "film", "width"), ("film", "width"), "ok", lambda: 1),
        (("sensor", "film", "width"), ("film", "width"), "error", lambda: 40000),
        (("sensor", "film", "width"), ("film", "width"), "error", lambda: 2 ** 31),
        (("sensor", "film", "width"), ("film", "width"), "error", lambda: 4294967552),
        (("sensor", "film", "height"), ("film", "height"), "either", lambda: 32768),
        (("sensor", "sampler", "sample_count"), ("sampler",), "either", lambda: 2 ** 30),
        (("sensor", "fov"), ("sensor", "fov"), "error", lambda: 180),
        (("sensor", "fov"), ("sensor", "fov"), "ok", lambda: 179.9),
        (("sensor", "fov"), ("sensor", "fov"), "either", lambda: 1e-30),
        (("sensor", "near_clip"), ("sensor", "near_clip"), "error", lambda: 2e4),
        (("integrator", "max_depth"), ("integrator", "max_depth"), "error", lambda: -2),
        (("integrator", "max_depth"), ("integrator",), "either", lambda: 2 ** 30),
        (("integrator", "type"), ("integrator", "volpath"), "error", lambda: "volpath"),
        # bsdfs and emitters
        (("ball", "bsdf"), ("ball", "bsdf"), "error", lambda: {"type": "plastic"}),
        (("ball", "bsdf"), ("ball", "alpha_u"), "error", lambda: {"type": "roughconductor", "alpha_u": 0.1, "alpha_v": 0.3}),
        (("ball", "bsdf"), ("ball", "eta"), "error", lambda: {"type": "conductor", "eta": [1, 1, -1]}),
        (("ball", "bsdf"), ("ball", "material"), "error", lambda: {"type": "conductor", "material": "Au", "eta": 1}),
        (("ball", "bsdf"), ("ball", "twosided"), "error", lambda: {"type": "twosided"}),
        (("ball", "bsdf"), ("ball", "twosided"), "error", lambda: {"type": "twosided", "a": {"type": "diffuse"}, "b": {"type": "diffuse"}}),
        (("ball", "bsdf"), ("ball", "id"), "error", lambda: {"type": "twosided", "a": {"type": "diffuse", "id": "inner"}}),
        (("ball", "bsdf"), ("ball", "transmissive"), "error", lambda: {"type": "twosided", "a": {"type": "dielectric"}}),
        (("ball", "bsdf"), ("ball", "twosided"), "error",
         lambda: {"type": "twosided", "a": {"type": "twosided", "b": {"type": "diffuse"}}}),
        (("ball", "bsdf"), ("ball", "int_ior"), "error", lambda: {"type": "dielectric", "int_ior": "unobtainium"}),
        (("ball", "bsdf"), ("ball", "ext_ior"), "error", lambda: {"type": "dielectric", "int_ior": 1.0, "ext_ior": 1.0}),
        (("ball", "bsdf"), ("ball", "bsdf"), "error", lambda: {"type": "rgb", "value": 1}),
        (("ball", "emitter"), ("ball", "point"), "error", lambda: {"type": "point"}),
        (("ball", "emitter"), ("ball", "radiance"), "error", lambda: {"type": "area", "radiance": -1}),
        (("hf", "emitter"), ("hf", "area"), "error", lambda: {"type": "area"}),
        (("floor", "bsdf", "reflectance"), ("floor", "reflectance"), "error", lambda: {"type": "rgb"}),
        (("floor", "bsdf", "reflectance"), ("floor", "reflectance"), "error", lambda: {"type": "rgb", "value": "x"}),
        (("floor", "bsdf", "reflectance"), ("floor", "reflectance"), "error", lambda: {"type": "checkerboard"}),
        (("floor", "bsdf", "reflectance"), ("floor", "filename"), "error", lambda: {"type": "bitmap"}),
        (("floor", "bsdf", "reflectance"), ("floor", "filename"), "error", lambda: {"type": "bitmap", "filename": "missing.png"}),
        (("floor", "bsdf", "reflectance"), ("floor", "filename"), "error", lambda: {"type": "bitmap", "filename": "."}),
        (("floor", "bsdf", "reflectance"), ("floor", "filename"), "error", lambda: {"type": "bitmap", "filename": ""}),
        (("sun", "direction"), ("sun", "direction"), "error", lambda: [1e-300, 1e-300, 1e-300]),
        # bad references
        (("ball", "bsdf"), ("ball", "nope"), "error", lambda: {"type": "ref", "id": "nope"}),
        (("ball", "bsdf"), ("ball", "floor"), "error", lambda: {"type": "ref", "id": "floor"}),
        (("ball", "bsdf"), ("ball", "id"), "error", lambda: {"type": "ref", "id": 5}),
        (("ball", "bsdf"), ("ball", "id"), "error", lambda: {"type": "ref"}),
        (("ball", "bsdf"), ("ball", "extra"), "warn", lambda: {"type": "ref", "id": "glass", "extra": 1}),
        (("floor", "bsdf2"), ("floor", "bsdf"), "error", lambda: {"type": "ref", "id": "glass"}),
        (("light", "emitter2"), ("light", "emitter"), "error", lambda: {"type": "area"}),
        (("sensor", "film2"), ("sensor", "film"), "error", lambda: {"type": "hdrfilm"}),
        (("sensor", "sampler2"), ("sensor", "sampler"), "error", lambda: {"type": "independent"}),
        (("sensor", "thing"), ("sensor", "diffuse"), "error", lambda: {"type": "diffuse"}),
        (("sensor", "film", "rfilter"), ("film", "tent"), "warn", lambda: {"type": "tent"}),  # known, not supported: box and gaussian are
        (("sensor", "film", "rfilter"), ("film", "diffuse"), "error", lambda: {"type": "diffuse"}),
        # unknown keys: accepted with a warning naming the object and the key
        (("ball", "colour"), ("ball", "colour"), "warn", lambda: [1, 0, 0]),
        (("floor", "bsdf", "roughness"), ("floor", "roughness"), "warn", lambda: 0.3),
        (("sensor", "film", "banding"), ("film", "banding"), "warn", lambda: 1),
        (("sensor", "sampler", "jitter"), ("sampler", "jitter"), "warn", lambda: True),
        (("light", "emitter", "power"), ("light", "power"), "warn", lambda: 3),
        (("sky", "scale"), ("sky", "scale"), "warn", lambda: 2),
        (("ball", "to_world"), ("ball", "orign"), "error", lambda: {"look_at": {"orign": [0, 0, 0], "target": [0, 0, 1]}}),
        (("ball", "to_world"), ("ball", "angel"), "error", lambda: {"rotate": {"axis": [0, 0, 1], "angle": 30, "angel": 3}}),
    ]
    cases = []
    for i, (path, names, expect, make_value) in enumerate(specific):
        def make(path=path, make_value=make_value):
            d = base_scene()
            set_path(d, path, make_value())
            return d
        cases.append(Case(f"dict-specific/{i:03d}:{'.'.join(path)}", "load", expect, names, load_dict_case(make)))

    # Structural mistakes at the top level.
    def structural(label, edit, expect, names):
        def make():
            d = base_scene()
            edit(d)
            return d
        cases.append(Case(f"dict-structure/{label}", "load", expect, names, load_dict_case(make)))

    structural("no_sensor", lambda d: d.pop("sensor"), "error", ("sensor",))
    structural("two_integrators", lambda d: d.update(integrator2={"type": "direct"}), "error", ("integrator",))
    structural("film_at_top", lambda d: d.update(film={"type": "hdrfilm"}), "error", ("film", "sensor"))
    structural("area_at_top", lambda d: d.update(glow={"type": "area"}), "error", ("glow", "area"))
    structural("unknown_type", lambda d: d.update(teapot={"type": "teapot"}), "error", ("teapot",))
    structural("type_not_string", lambda d: d.update(thing={"type": 5}), "error", ("thing", "type"))
    structural("value_not_object", lambda d: d.update(thing=5), "error", ("thing",))
    structural("top_type", lambda d: d.update(type="scenery"), "error", ("type", "scene"))
    structural("duplicate_id", lambda d: d["floor"].update(id="ball"), "error", ("ball", "duplicate"))
    structural("id_not_string", lambda d: d["floor"].update(id=5), "error", ("floor", "id"))
    structural("id_empty", lambda d: d["floor"].update(id=""), "error", ("floor", "id"))
    structural("id_control", lambda d: d["floor"].update(id="a\nb"), "error", ("floor", "id"))
    structural("key_control", lambda d: d.update({"bad\x01key": {"type": "sphere"}}), "error", ("key",))
    structural("key_int", lambda d: d.update({5: {"type": "sphere"}}), "error", ("5",))
    structural("key_surrogate", lambda d: d.update({"\udc80": {"type": "sphere"}}), "error", ("scene",))
    structural("nested_id_dup", lambda d: d["ball"]["bsdf"].update(id="floor"), "error", ("floor", "duplicate"))
    structural("self_reference", lambda d: d["ball"].update(me=d), "error", ("ball", "deeper"))
    structural("many_unknown_keys", lambda d: d["ball"].update({f"k{i}": i for i in range(5000)}), "warn", ("ball", "k0"))
    structural("many_objects", lambda d: d.update({f"s{i}": {"type": "sphere", "center": [i % 7, i % 5, -3], "radius": 0.1}
                                                   for i in range(2000)}), "ok", ())
    structural("control_base_scene", lambda d: None, "ok", ())  # the base scene itself loads and renders
    cases.append(Case("dict-structure/list_instead", "load", "error", ("dict",), lambda tmp: __import__("limn").load_dict([1, 2])))
    cases.append(Case("dict-structure/deep_top", "load", "error", ("deeper",),
                      lambda tmp: __import__("limn").load_dict({"type": "scene", "x": nest(100000)})))
    return cases


# ---- B. scene files --------------------------------------------------------------------------------

def valid_scene_text() -> str:
    d = small_scene(ball={"type": "sphere", "center": [0, 0, 0.7], "radius": 0.6},
                    floor={"type": "rectangle", "to_world": {"scale": 3}})
    return json.dumps(d, indent=1)


def load_file_case(text_or_bytes, name="hostile.json"):
    def run(tmp):
        import limn
        return outputs_of(limn.load(write(tmp, name, text_or_bytes)))
    return run


def file_cases() -> list[Case]:
    cases = []
    good = valid_scene_text()
    F = "hostile.json"

    def add(label, data, expect, names=(F, "line")):
        cases.append(Case(f"file/{label}", "load", expect, names, load_file_case(data)))

    add("valid", good, "ok", ())
    add("valid_bom", b"\xef\xbb\xbf" + good.encode(), "ok", ())
    add("empty", "", "error")
    add("whitespace", "  \n\t ", "error")
    add("null", "null", "error", (F,))
    add("list", "[1, 2]", "error", (F,))
    add("deep_300", '{"type": "scene", "x": ' + "[" * 300 + "]" * 300 + "}", "error")
    add("deep_100000", '{"type": "scene", "x": ' + "[" * 100000 + "]" * 100000 + "}", "error")
    add("deep_objects_100000", '{"a": ' * 100000 + "1" + "}" * 100000, "error")
    add("1e400", good.replace('"radius": 0.6', '"radius": 1e400'), "error")
    add("-1e400", good.replace('"radius": 0.6', '"radius": -1e400'), "error")
    add("1e-400", good.replace('"radius": 0.6', '"radius": 1e-400'), "error", (F, "ball", "radius"))
    add("int_400_digits", good.replace('"radius": 0.6', '"radius": 1' + "0" * 400), "error")
    add("NaN_literal", good.replace('"radius": 0.6', '"radius": NaN'), "error")
    add("Infinity_literal", good.replace('"radius": 0.6', '"radius": Infinity'), "error")
    add("bad_utf8_key", good.encode().replace(b'"ball"', b'"b\xffall"'), "error")
    add("bad_utf8_value", good.encode().replace(b'"sphere"', b'"sph\xc3\x28ere"'), "error")
    add("bad_utf8_outside", good.encode().replace(b'"radius": 0.6', b'"radius": 0.6\xff'), "error")
    add("overlong_utf8", good.encode().replace(b'"sphere"', b'"sph\xc0\xafere"'), "error")
    add("surrogate_escape", good.replace('"sphere"', '"sph\\ud800ere"'), "error")
    add("nul_byte", good.encode().replace(b'"radius"', b'"rad\x00ius"'), "error")
    add("escaped_nul_key", good.replace('"ball"', '"ba\\u0000ll"'), "error", (F,))
    add("duplicate_key", good.replace('"radius": 0.6', '"radius": 0.6, "radius": 2'), "error", (F, "radius"))
    add("comment", "// scene\n" + good, "error")
    add("trailing_garbage", good + " }", "error")
    add("single_quotes", good.replace('"', "'"), "error")
    add("binary_garbage", bytes(range(256)) * 4, "error")
    for k in range(12):  # truncated at 12 points
        cut = max(1, len(good) * k // 12)
        add(f"truncated_{k:02d}", good[:cut], "error")

    def special(label, make_path, expect, names):
        def run(tmp):
            import limn
            return outputs_of(limn.load(make_path(tmp)))
        cases.append(Case(f"file/{label}", "load", expect, names, run))

    def fifo(tmp):
        p = os.path.join(tmp, "fifo.json")
        os.mkfifo(p)
        return p

    def dangling(tmp):
        p = os.path.join(tmp, "link.json")
        os.symlink(os.path.join(tmp, "nowhere.json"), p)
        return p

    special("directory", lambda tmp: tmp, "error", ("directory",))
    special("fifo", fifo, "error", ("fifo.json", "regular"))
    special("missing", lambda tmp: os.path.join(tmp, "missing.json"), "error", ("missing.json", "not found"))
    special("dangling_symlink", dangling, "error", ("link.json",))
    special("dev_null", lambda tmp: "/dev/null", "error", ("/dev/null",))
    special("path_not_a_path", lambda tmp: 5, "error", ("path",))
    special("nul_in_path", lambda tmp: os.path.join(tmp, "a\x00b.json"), "error", ("a",))

    # Files named by a scene that are not regular files.
    def named_file(label, kind, make_name, names):
        def run(tmp):
            import limn
            name = make_name(tmp)
            if kind == "texture":
                d = small_scene(floor={"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": {"type": "bitmap", "filename": name}}})
            elif kind == "envmap":
                d = small_scene(env={"type": "envmap", "filename": name})
            else:
                d = small_scene(m={"type": kind, "filename": name})
            return outputs_of(limn.load_dict(d, base_dir=tmp))
        cases.append(Case(f"file/{label}", "load", "error", names, run))

    for kind, obj in (("ply", "m"), ("obj", "m"), ("heightfield", "m"), ("texture", "floor"), ("envmap", "env")):
        named_file(f"{kind}_fifo", kind, lambda tmp: (os.mkfifo(os.path.join(tmp, "f.dat")), "f.dat")[1], (obj, "f.dat"))
        named_file(f"{kind}_directory", kind, lambda tmp: (os.mkdir(os.path.join(tmp, "d.dat")), "d.dat")[1], (obj, "d.dat"))
        named_file(f"{kind}_dev_zero", kind, lambda tmp: "/dev/zero", (obj, "/dev/zero"))
        named_file(f"{kind}_missing", kind, lambda tmp: "missing.dat", (obj, "missing.dat"))
    return cases


# ---- C. mesh files ---------------------------------------------------------------------------------

def ply_text(vertices, faces, fmt="ascii", uv=None, extra_vertex_props=(), index_type="int", count_type="uchar", coord_type="float"):
    """A PLY file: ascii, binary_little_endian or binary_big_endian."""
    props = [f"property {coord_type} {c}\n" for c in "xyz"]
    if uv is not None:
        props += [f"property float {c}\n" for c in "st"]
    props += [f"property {t} {n}\n" for t, n in extra_vertex_props]
    header = (f"ply\nformat {fmt} 1.0\nelement vertex {len(vertices)}\n" + "".join(props)
              + f"element face {len(faces)}\nproperty list {count_type} {index_type} vertex_indices\nend_header\n")
    if fmt == "ascii":
        rows = []
        for i, v in enumerate(vertices):
            row = [repr(float(x)) for x in v] + ([repr(float(x)) for x in uv[i]] if uv is not None else [])
            row += ["0"] * len(extra_vertex_props)
            rows.append(" ".join(row))
        rows += [" ".join(str(int(x)) for x in [len(f), *f]) for f in faces]
        return (header + "\n".join(rows) + "\n").encode()
    e = "<" if fmt == "binary_little_endian" else ">"
    code = {"float": "f", "double": "d", "int": "i", "uint": "I", "uchar": "B", "ushort": "H", "short": "h", "char": "b"}
    body = b""
    for i, v in enumerate(vertices):
        body += struct.pack(e + code[coord_type] * 3, *v)
        if uv is not None:
            body += struct.pack(e + "ff", *uv[i])
        for t, _ in extra_vertex_props:
            body += struct.pack(e + code[t], 0)
    for f in faces:
        body += struct.pack(e + code[count_type], len(f)) + struct.pack(e + code[index_type] * len(f), *f)
    return header.encode() + body


QUAD_V = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)]
QUAD_UV = [(0, 0), (1, 0), (1, 1), (0, 1)]
QUAD_F = [(0, 1, 2, 3)]


def obj_text(vertices, faces, uv=None) -> bytes:
    lines = [f"v {x} {y} {z}" for x, y, z in vertices]
    if uv is not None:
        lines += [f"vt {u} {v}" for u, v in uv]
        lines += ["f " + " ".join(f"{i + 1}/{i + 1}" for i in f) for f in faces]
    else:
        lines += ["f " + " ".join(str(i + 1) for i in f) for f in faces]
    return ("\n".join(lines) + "\n").encode()


def mesh_case(label, kind, data, expect, names=None):
    name = "hostile." + kind
    names = names or ("mesh_under_test", name)

    def run(tmp):
        import limn
        write(tmp, name, data)
        d = small_scene(mesh_under_test={"type": kind, "filename": name, "allow_degenerate": False})
        return outputs_of(limn.load_dict(d, base_dir=tmp))
    return Case(f"mesh/{kind}/{label}", "load", expect, names, run)


def mesh_cases() -> list[Case]:
    rng = np.random.default_rng(7)
    cases = []
    valid = {
        "ply_ascii": ply_text(QUAD_V, QUAD_F, "ascii", QUAD_UV),
        "ply_le": ply_text(QUAD_V, QUAD_F, "binary_little_endian", QUAD_UV),
        "ply_be": ply_text(QUAD_V, QUAD_F, "binary_big_endian", QUAD_UV, index_type="uint", count_type="ushort", coord_type="double"),
        "obj": obj_text(QUAD_V, QUAD_F, QUAD_UV),
    }
    kind_of = {"ply_ascii": "ply", "ply_le": "ply", "ply_be": "ply", "obj": "obj"}
    for fmt, data in valid.items():
        kind = kind_of[fmt]
        cases.append(mesh_case(f"{fmt}/valid", kind, data, "ok", ()))
        cases.append(mesh_case(f"{fmt}/empty", kind, b"", "error"))
        # Truncated: a binary PLY loses data (an error); text may still parse (either).
        for k in range(1, 16):
            cut = len(data) * k // 16
            cases.append(mesh_case(f"{fmt}/truncated_{k:02d}", kind, data[:cut], "error" if fmt in ("ply_le", "ply_be") else "either"))
        if kind == "ply":
            end = data.index(b"end_header\n") + len(b"end_header\n")
            for extra in (0, 1, 7, 20):
                cases.append(mesh_case(f"{fmt}/cut_{extra}_after_header", kind, data[:end + extra], "error"))
        # Garbled: random bytes overwritten (anything but a crash, a hang or a non-finite output).
        for k in range(25):
            b = bytearray(data)
            for _ in range(1 + k % 4):
                b[int(rng.integers(len(b)))] = int(rng.integers(256))
            cases.append(mesh_case(f"{fmt}/garbled_{k:02d}", kind, bytes(b), "either"))
    for k in range(8):
        cases.append(mesh_case(f"garbage_{k}", "ply" if k % 2 else "obj", bytes(rng.integers(0, 256, 200 + 300 * k, dtype=np.uint8)), "error"))

    head = "ply\nformat ascii 1.0\n"
    vxyz = "property float x\nproperty float y\nproperty float z\n"
    flist = "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    ply_specific = {
        # the issue's segfault: texture coordinates and an index far out of range
        "uv_index_1e8": (head + "element vertex 3\n" + vxyz + "property float s\nproperty float t\n" + flist
                         + "0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n3 0 1 100000000\n", "error"),
        "index_negative": (head + "element vertex 3\n" + vxyz + flist + "0 0 0\n1 0 0\n0 1 0\n3 0 1 -1\n", "error"),
        "index_equal_count": (head + "element vertex 3\n" + vxyz + flist + "0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "error"),
        "index_fraction": (head + "element vertex 3\n" + vxyz + flist + "0 0 0\n1 0 0\n0 1 0\n3 0 1 1.5\n", "error"),
        "count_huge": (head + "element vertex 4294967295\n" + vxyz + flist + "0 0 0\n", "error"),
        "count_20_digits": (head + "element vertex 99999999999999999999\n" + vxyz + flist, "error"),
        "count_negative": (head + "element vertex -3\n" + vxyz + flist, "error"),
        "list_count_255": (head + "element vertex 3\n" + vxyz + flist + "0 0 0\n1 0 0\n0 1 0\n255 0 1 2\n", "error"),
        "list_count_2": (head + "element vertex 3\n" + vxyz + flist + "0 0 0\n1 0 0\n0 1 0\n2 0 1\n", "error"),
        "list_count_0": (head + "element vertex 3\n" + vxyz + flist + "0 0 0\n1 0 0\n0 1 0\n0\n", "error"),
        "nan_vertex": (head + "element vertex 3\n" + vxyz + flist + "nan 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "error"),
        "inf_vertex": (head + "element vertex 3\n" + vxyz + flist + "inf 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "error"),
        "beyond_float": (head + "element vertex 3\n" + vxyz + flist + "1e39 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "error"),
        "1e38_vertices": (head + "element vertex 3\n" + vxyz + flist + "0 0 0\n1e38 0 0\n0 1e38 0\n3 0 1 2\n", "error"),
        "no_end_header": (head + "element vertex 3\n" + vxyz, "error"),
        "endless_comments": (head + "comment x\n" * 20000, "error"),
        "no_format": ("ply\nelement vertex 3\n" + vxyz + flist, "error"),
        "unknown_format": ("ply\nformat binary_middle_endian 1.0\nelement vertex 3\n" + vxyz + flist, "error"),
        "unknown_type": (head + "element vertex 3\nproperty quad x\n" + flist, "error"),
        "no_faces": (head + "element vertex 3\n" + vxyz + "end_header\n0 0 0\n1 0 0\n0 1 0\n", "error"),
        "no_z": (head + "element vertex 3\nproperty float x\nproperty float y\n" + flist + "0 0\n1 0\n0 1\n3 0 1 2\n", "error"),
        "float_indices": (head + "element vertex 3\n" + vxyz + "element face 1\nproperty list uchar float vertex_indices\nend_header\n"
                          + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "error"),
        "trailing_data": (head + "element vertex 3\n" + vxyz + flist + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n7 7 7\n", "error"),
        "degenerate": (head + "element vertex 3\n" + vxyz + flist + "0 0 0\n1 0 0\n2 0 0\n3 0 1 2\n", "error"),
        "crlf": ("ply\r\nformat ascii 1.0\r\nelement vertex 3\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\n"
                 "element face 1\r\nproperty list uchar int vertex_indices\r\nend_header\r\n0 0 0\r\n1 0 0\r\n0 1 0\r\n3 0 1 2\r\n", "ok"),
        "extra_element": (head + "element vertex 3\n" + vxyz + "element material 2\nproperty list uchar float k\n" + flist
                          + "0 0 0\n1 0 0\n0 1 0\n2 0.5 0.5\n0\n3 0 1 2\n", "ok"),
        "pentagon": (head + "element vertex 5\n" + vxyz + flist + "0 0 0\n1 0 0\n1.3 1 0\n0.5 1.6 0\n-0.3 1 0\n5 0 1 2 3 4\n", "ok"),
    }
    for label, (text, expect) in ply_specific.items():
        cases.append(mesh_case(label, "ply", text.encode(), expect))
    # binary: counts larger than the data; list counts larger than the data; index types
    le = "ply\nformat binary_little_endian 1.0\n"
    cases.append(mesh_case("binary_count_huge", "ply", (le + "element vertex 1000000000\n" + vxyz + flist).encode() + b"\0" * 64, "error"))
    cases.append(mesh_case("binary_list_huge", "ply", (le + "element vertex 3\n" + vxyz
                                                        + "element face 1\nproperty list uint int vertex_indices\nend_header\n").encode()
                           + struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<I", 4000000000) + b"\0" * 12, "error"))
    cases.append(mesh_case("binary_nan", "ply", ply_text([(float("nan"), 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)], "binary_little_endian"), "error"))
    cases.append(mesh_case("binary_index_big", "ply", ply_text([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 7)], "binary_big_endian"), "error"))
    cases.append(mesh_case("binary_index_neg", "ply", ply_text([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, -1)], "binary_little_endian"), "error"))
    cases.append(mesh_case("binary_trailing", "ply", ply_text(QUAD_V, QUAD_F, "binary_little_endian") + b"garbage", "error"))
    cases.append(mesh_case("binary_short_count_type", "ply", ply_text(QUAD_V, QUAD_F, "binary_little_endian", count_type="short"), "ok"))
    obj_specific = {
        "index_zero": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "error"),
        "index_big": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 100000000\n", "error"),
        "index_1e10": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 10000000000\n", "error"),
        "index_negative_far": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -100\n", "error"),
        "index_negative": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n", "ok"),
        "uv_index_big": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/100000000\n", "error"),
        "uv_mixed": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2 3/1\n", "error"),
        "forward_reference": ("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n", "error"),
        "two_vertices": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "error"),
        "nan": ("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "error"),
        "inf": ("v 0 0 inf\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "error"),
        "1e39": ("v 0 0 1e39\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "error"),
        "1e400": ("v 0 0 1e400\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "error"),
        "1e38": ("v 0 0 0\nv 1e38 0 0\nv 0 1e38 0\nf 1 2 3\n", "error"),
        "words": ("v a b c\nf 1 2 3\n", "error"),
        "no_faces": ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "error"),
        "text": ("this is not an obj file\n" * 5, "error"),
        "nul": ("v 0 0 0\x00\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "error"),
        "long_polygon": ("".join(f"v {math.cos(a)} {math.sin(a)} 0\n" for a in np.linspace(0, 6.2, 2000))
                         + "f " + " ".join(str(i) for i in range(1, 2001)) + "\n", "ok"),
        "many_lines": ("# x\n" * 100000 + "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "ok"),
        "long_line": ("v 0 0 0 " + "1 " * 200000 + "\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "ok"),
        "degenerate": ("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "error"),
        "statements": ("mtllib x.mtl\no a\ng b\nusemtl c\ns 1\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvp 0.5\nl 1 2\np 1\nf 1//1 2//1 3//1\n", "ok"),
    }
    for label, (text, expect) in obj_specific.items():
        cases.append(mesh_case(label, "obj", text.encode(), expect))
    return cases


# ---- D. images -------------------------------------------------------------------------------------

def png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def png_claiming(width: int, height: int) -> bytes:
    """A PNG whose header (with a correct CRC) claims width x height, with one tiny IDAT."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) + png_chunk(b"IDAT", zlib.compress(b"\0" * 64)) + png_chunk(b"IEND", b"")


def exr_claiming(width: int, height: int) -> bytes:
    """A scanline OpenEXR header claiming width x height (and nothing after it)."""
    def attr(name, kind, value):
        return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value
    channels = b"R\0" + struct.pack("<iB3xii", 2, 0, 1, 1) + b"\0"
    box = struct.pack("<iiii", 0, 0, width - 1, height - 1)
    header = (attr("channels", "chlist", channels) + attr("compression", "compression", b"\0") + attr("dataWindow", "box2i", box)
              + attr("displayWindow", "box2i", box) + attr("lineOrder", "lineOrder", b"\0")
              + attr("pixelAspectRatio", "float", struct.pack("<f", 1)) + attr("screenWindowCenter", "v2f", struct.pack("<ff", 0, 0))
              + attr("screenWindowWidth", "float", struct.pack("<f", 1)) + b"\0")
    return b"\x76\x2f\x31\x01" + struct.pack("<I", 2) + header


def image_bytes(ext: str) -> bytes:
    import limn
    rgb = (np.arange(4 * 5 * 3, dtype=np.float32).reshape(4, 5, 3) % 7) / 7
    if ext == "pfm":  # Portable Float Map: little endian (negative scale), rows bottom to top
        return b"PF\n5 4\n-1.0\n" + rgb[::-1].astype("<f4").tobytes()
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "x." + ext)
        limn.write_image(p, rgb)
        with open(p, "rb") as f:
            return f.read()


def image_case(label, ext, make_data, use, expect, extra_names=()):
    """`use`: texture, envmap, heightfield or read (limn.read_image)."""
    name = "hostile." + ext
    obj = {"texture": "tex_under_test", "envmap": "env_under_test", "heightfield": "hf_under_test", "read": ""}[use]
    names = tuple(n for n in (obj, name) if n) + tuple(extra_names)

    def run(tmp):
        import limn
        write(tmp, name, make_data())
        if use == "read":
            return [limn.read_image(os.path.join(tmp, name))]
        if use == "texture":
            d = small_scene(tex_under_test={"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": {"type": "bitmap", "filename": name}}})
        elif use == "envmap":
            d = small_scene(env_under_test={"type": "envmap", "filename": name})
            del d["sky"]
        else:
            d = small_scene(hf_under_test={"type": "heightfield", "filename": name})
        return outputs_of(limn.load_dict(d, base_dir=tmp))
    return Case(f"image/{use}/{ext}/{label}", "load", expect, names, run)


def image_cases() -> list[Case]:
    cases = []
    rng = np.random.default_rng(11)
    cache = {}

    def data_of(ext):
        if ext not in cache:
            cache[ext] = image_bytes(ext)
        return cache[ext]

    uses = ("texture", "envmap", "heightfield", "read")
    for ext in ("png", "jpg", "exr", "hdr", "tif", "bmp", "tga", "pfm"):
        for use in uses:
            cases.append(image_case("valid", ext, lambda ext=ext: data_of(ext), use, "ok", ()))
        cases.append(image_case("empty", ext, lambda: b"", uses[len(cases) % 4], "error"))
        for k, frac in enumerate((0.1, 0.3, 0.5, 0.7, 0.9)):
            use = uses[k % 4]
            # TGA keeps its pixels before a long footer, PNG before a 12-byte end chunk: cutting only
            # those leaves a complete image.
            tail_only = (ext == "tga" and frac > 0.2) or (ext == "png" and frac > 0.8)
            cases.append(image_case(f"truncated_{int(frac * 100)}", ext, lambda ext=ext, frac=frac: data_of(ext)[:max(1, int(len(data_of(ext)) * frac))],
                                    use, "either" if tail_only else "error"))
        for k in range(8):
            seed = int(rng.integers(1 << 30))

            def garbled(ext=ext, seed=seed):
                b = bytearray(data_of(ext))
                r = np.random.default_rng(seed)
                for _ in range(1 + seed % 5):
                    b[int(r.integers(len(b)))] = int(r.integers(256))
                return bytes(b)
            cases.append(image_case(f"garbled_{k}", ext, garbled, uses[k % 4], "either"))
    for use in uses:
        cases.append(image_case("png_claims_100000x100000", "png", lambda: png_claiming(100000, 100000), use, "error"))
        cases.append(image_case("png_claims_30000x30000", "png", lambda: png_claiming(30000, 30000), use, "error"))
        cases.append(image_case("png_claims_0x5", "png", lambda: png_claiming(0, 5), use, "error"))
        cases.append(image_case("exr_claims_2^30x2^30", "exr", lambda: exr_claiming(1 << 30, 1 << 30), use, "error"))
        cases.append(image_case("exr_claims_100000x100000", "exr", lambda: exr_claiming(100000, 100000), use, "error"))
        cases.append(image_case("exr_header_only", "exr", lambda: exr_claiming(4, 4), use, "error"))
        cases.append(image_case("random_bytes", "png", lambda: bytes(np.random.default_rng(3).integers(0, 256, 500, dtype=np.uint8)), use, "error"))
        cases.append(image_case("text", "png", lambda: b"not an image\n" * 10, use, "error"))
        cases.append(image_case("wrong_extension_exr_as_png", "png", lambda: data_of("exr"), use, "ok", ()))
        cases.append(image_case("nan_pixels", "exr", lambda: nan_exr(), use, "error"))
    return cases


def nan_exr() -> bytes:
    import limn
    a = np.full((2, 2, 3), 0.5, np.float32)
    a[1, 1, 1] = np.nan
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "n.exr")
        limn.write_image(p, a)
        with open(p, "rb") as f:
            return f.read()


# ---- E. transforms on every kind of object ---------------------------------------------------------

TRANSFORMS = {
    "scale_1e38": ({"scale": 1e38}, "either"),
    "scale_1e300": ({"scale": 1e300}, "error"),
    "scale_1e-300": ({"scale": 1e-300}, "error"),
    "scale_1e-38": ({"scale": 1e-38}, "error"),
    "scale_1e18": ({"scale": 1e18}, "either"),
    "scale_1e-10": ({"scale": 1e-10}, "either"),
    "scale_zero_axis": ({"scale": [1, 1, 0]}, "error"),
    "scale_nan": ({"scale": float("nan")}, "error"),
    "singular_matrix": ([[1, 0, 0, 0], [0, 1, 0, 0], [1, 1, 0, 0], [0, 0, 0, 1]], "error"),
    "zero_matrix": (np.zeros((4, 4)), "error"),
    "projective_matrix": ([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 0]], "error"),
    "inf_matrix": (np.diag([np.inf, 1.0, 1.0, 1.0]), "error"),
    "matrix_1e300": (np.diag([1e300, 1e300, 1e300, 1.0]), "error"),
    "steps_overflow": ([{"scale": 1e200}, {"scale": 1e200}], "error"),
    "steps_underflow": ([{"scale": 1e-200}, {"scale": 1e-200}], "error"),
    "translate_1e38": ({"translate": [1e38, 0, 0]}, "either"),
    "translate_3e38": ({"translate": [3e38, 3e38, 3e38]}, "either"),
    "translate_1e300": ({"translate": [1e300, 0, 0]}, "error"),
    "rotate_zero_axis": ({"rotate": {"axis": [0, 0, 0], "angle": 30}}, "error"),
    "rotate_huge_angle": ({"rotate": {"axis": [0, 0, 1], "angle": 1e300}}, "either"),
    "look_at_same": ({"look_at": {"origin": [1, 1, 1], "target": [1, 1, 1]}}, "error"),
    "look_at_parallel_up": ({"look_at": {"origin": [0, 0, 0], "target": [0, 0, 5], "up": [0, 0, 1]}}, "error"),
    "shear": ([[1, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "either"),
}
# The objects, how to give them a to_world, and the transforms that are fine for them.
TRANSFORM_TARGETS = {
    "ball": ("ball", {"shear": "error"}),
    "floor": ("floor", {}),
    "box": ("box", {}),
    "tri": ("tri", {}),
    "hf": ("hf", {"shear": "error"}),
    "sensor": ("sensor", {}),
    "lamp": ("lamp", {"scale_1e300": "either", "scale_1e-300": "either", "scale_1e-38": "either", "steps_overflow": "either",
                      "steps_underflow": "either", "matrix_1e300": "either"}),
    "sun": ("sun", {"translate_1e300": "either"}),
    "mesh_file": ("mesh_file", {}),
    "env": ("env", {"shear": "error", "translate_1e300": "either"}),
}


def transform_cases() -> list[Case]:
    cases = []
    for target, (obj, overrides) in TRANSFORM_TARGETS.items():
        for label, (value, expect) in TRANSFORMS.items():
            expect = overrides.get(label, expect)

            def run(tmp, obj=obj, value=value):
                import limn
                d = base_scene()
                if obj in ("lamp", "sun"):
                    d[obj].pop("position", None)
                    d[obj].pop("direction", None)
                if obj == "mesh_file":
                    write(tmp, "quad.ply", ply_text(QUAD_V, QUAD_F, "binary_little_endian"))
                    d["mesh_file"] = {"type": "ply", "filename": "quad.ply"}
                if obj == "env":
                    limn.write_image(os.path.join(tmp, "env.exr"), np.full((4, 8, 3), 0.5, np.float32))
                    d["env"] = {"type": "envmap", "filename": "env.exr"}
                    del d["sky"]
                d[obj]["to_world"] = value
                return outputs_of(limn.load_dict(d, base_dir=tmp))
            cases.append(Case(f"transform/{target}/{label}", "load", expect, (obj, "to_world"), run))
    return cases


# ---- fuzz regressions: inputs that once crashed or hung a fuzz target ------------------------------

def fuzz_regression_cases() -> list[Case]:
    cases = []
    for path in sorted(glob.glob(os.path.join(FUZZ_CORPUS, "*", "crash-*")) + glob.glob(os.path.join(FUZZ_CORPUS, "*", "timeout-*"))):
        target = os.path.basename(os.path.dirname(path))
        label = os.path.basename(path)
        with open(path, "rb") as f:
            data = f.read()
        if target == "scene_json":
            cases.append(Case(f"fuzz/{target}/{label}", "load", "either", ("hostile.json",), load_file_case(data)))
        elif target in ("obj", "ply"):
            cases.append(mesh_case(f"fuzz/{label}", target, data, "either"))
        elif target == "image":
            ext = "tga" if data and data[-1] % 4 == 0 else "img"
            cases.append(image_case(f"fuzz/{label}", ext, lambda data=data: data, "read", "either"))
        elif target == "heightfield":
            ext = "tga" if data and data[-1] % 4 == 0 else "img"
            cases.append(image_case(f"fuzz/{label}", ext, lambda data=data: data, "heightfield", "either"))
    return cases


# ---- F. runtime calls --------------------------------------------------------------------------------

def runtime_cases() -> list[Case]:
    cases = []

    def add(label, expect, names, body, heightfield=False):
        def run(tmp):
            import limn
            # Derivatives of a scene with a heightfield use the heightfield estimator, which takes
            # rough reflective BSDFs only; the other derivative cases leave the heightfield out.
            d = base_scene()
            if heightfield:
                del d["box"], d["glass"]
            elif label.startswith(("forward", "backward")):
                del d["hf"]
            return body(limn.load_dict(d, base_dir=tmp), limn)
        cases.append(Case(f"runtime/{label}", "runtime", expect, names, run))

    # render
    add("render_threads_1e6", "either", ("threads",), lambda s, limn: [s.render(spp=1, threads=10 ** 6)])
    add("render_threads_-1", "error", ("threads",), lambda s, limn: [s.render(spp=1, threads=-1)])
    add("render_threads_2^40", "error", ("threads",), lambda s, limn: [s.render(spp=1, threads=2 ** 40)])
    add("render_spp_2^31-1", "either", ("spp",), lambda s, limn: [s.render(spp=2 ** 31 - 1)])
    add("render_spp_1e12", "error", ("spp",), lambda s, limn: [s.render(spp=10 ** 12)])
    add("render_spp_-5", "error", ("spp",), lambda s, limn: [s.render(spp=-5)])
    add("render_spp_float", "error", ("spp",), lambda s, limn: [s.render(spp=1.5)])
    add("render_seed_-1", "error", ("seed",), lambda s, limn: [s.render(spp=1, seed=-1)])
    add("render_seed_2^70", "error", ("seed",), lambda s, limn: [s.render(spp=1, seed=2 ** 70)])
    add("render_max_depth_1e9", "either", ("max_depth",), lambda s, limn: [s.render(spp=1, max_depth=10 ** 9)])
    add("render_max_depth_-5", "error", ("max_depth",), lambda s, limn: [s.render(spp=1, max_depth=-5)])

    # derivatives: tangents, adjoints, counts
    def fwd(name, tangent, **kw):
        def body(s, limn):
            s.set_differentiable([name])
            t = np.broadcast_to(np.asarray(tangent, np.float64), s.params[name].shape).copy()
            return [s.render_forward({name: t}, **kw)]
        return body

    def bwd(name, adjoint, **kw):
        def body(s, limn):
            s.set_differentiable([name])
            a = np.full((s.height, s.width, 3), adjoint) if np.isscalar(adjoint) else adjoint
            g = s.render_backward(a, **kw)
            return list(g.values())
        return body

    for name in ("ball.center", "ball.radius", "tri.vertex_positions", "floor.reflectance", "hf.heights"):
        for label, value, expect in (("1e38", 1e38, "either"), ("1e300", 1e300, "either"), ("-1e38", -1e38, "either"),
                                     ("nan", float("nan"), "error"), ("inf", float("inf"), "error")):
            hf = name.startswith("hf.")
            add(f"forward_{name}_tangent_{label}", expect, (name,), fwd(name, value, spp=1), heightfield=hf)
            add(f"backward_{name}_adjoint_{label}", expect, ("adjoint",), bwd(name, value, spp=1), heightfield=hf)
    add("forward_threads_1e6", "either", ("threads",), fwd("ball.center", 1.0, spp=1, threads=10 ** 6))
    add("forward_threads_-1", "error", ("threads",), fwd("ball.center", 1.0, spp=1, threads=-1))
    add("forward_spp_-1", "error", ("spp",), fwd("ball.center", 1.0, spp=-1))
    add("forward_spp_2^31-1", "either", ("spp",), fwd("ball.center", 1.0, spp=2 ** 31 - 1))
    add("forward_spp_boundary_2^31-1", "either", ("spp_boundary",), fwd("ball.center", 1.0, spp=1, spp_boundary=2 ** 31 - 1))
    add("forward_spp_1e12", "error", ("spp",), fwd("ball.center", 1.0, spp=10 ** 12))
    add("forward_guiding_bogus", "error", ("guiding",), fwd("ball.center", 1.0, spp=1, guiding="bogus"))
    add("backward_threads_1e6", "either", ("threads",), bwd("ball.center", 1.0, spp=1, threads=10 ** 6))
    add("backward_spp_-3", "error", ("spp",), bwd("ball.center", 1.0, spp=-3))
    add("backward_adjoint_shape", "error", ("adjoint",), bwd("ball.center", np.ones((3, 3, 3)), spp=1))

    # update() after setting parameters, then a render
    def edit(name, value):
        def body(s, limn):
            v = s.params[name]
            s.params[name] = np.broadcast_to(np.asarray(value, np.float64), v.shape) if np.isscalar(value) or np.ndim(value) < v.ndim else value
            s.update()
            return outputs_of(s)
        return body

    edits = [
        ("ball.radius", 1e30, "either"), ("ball.radius", 1e38, "either"), ("ball.radius", 3e38, "either"), ("ball.radius", 1e300, "error"),
        ("ball.radius", float("nan"), "error"), ("ball.radius", -1.0, "error"), ("ball.radius", 1e-30, "either"),
        ("ball.center", [1e38, 0, 0], "either"), ("ball.center", [3.4e38, 3.4e38, 3.4e38], "either"), ("ball.center", [float("nan"), 0, 0], "error"),
        ("ball.to_world.translation", [1e38, 0, 0], "either"), ("ball.to_world.translation", [3e38, 3e38, 3e38], "either"),
        ("ball.to_world.translation", [float("inf"), 0, 0], "error"),
        ("floor.to_world.translation", [1e38, 0, 0], "either"), ("floor.to_world.translation", [3e38, 0, 0], "either"),
        ("hf.to_world.translation", [1e38, 0, 0], "either"),
        ("tri.vertex_positions", 1e38, "either"), ("tri.vertex_positions", float("nan"), "error"),
        ("floor.vertex_positions", 1e38, "either"),
        ("hf.heights", 1e38, "either"), ("hf.heights", float("nan"), "error"), ("hf.heights", 1e30, "either"),
        ("floor.reflectance", -1.0, "error"), ("floor.reflectance", 1e38, "either"), ("floor.reflectance", float("nan"), "error"),
        ("ball.alpha", 1e38, "either"), ("ball.alpha", 0.0, "error"),
        ("light.radiance", 1e38, "either"), ("light.radiance", -1.0, "error"), ("light.radiance", float("inf"), "error"),
        ("lamp.intensity", 1e38, "either"), ("sun.irradiance", 1e38, "either"), ("sky.radiance", 1e38, "either"),
    ]
    for name, value, expect in edits:
        label = str(value[0] if isinstance(value, list) else value)
        add(f"update_{name}={label}", expect, (name,), edit(name, value))

    # Adam
    def adam(steps=2, grad=1.0, **kw):
        def body(s, limn):
            x = np.zeros(3, np.float32)
            opt = limn.optim.Adam(x, **kw)
            for _ in range(steps):
                opt.step(np.full(3, grad))
            return [x]
        return body

    for label, kw, expect, names in (
            ("lr_inf", {"lr": math.inf}, "error", ("Adam", "lr")), ("lr_nan", {"lr": math.nan}, "error", ("Adam", "lr")),
            ("lr_-1", {"lr": -1.0}, "error", ("Adam", "lr")), ("lr_1e38", {"lr": 1e38}, "either", ("Adam", "lr")),
            ("lr_1e300", {"lr": 1e300}, "either", ("Adam", "lr")),
            ("betas_1_1", {"betas": (1, 1)}, "error", ("Adam", "betas")), ("betas_0.9_1", {"betas": (0.9, 1.0)}, "error", ("Adam", "betas")),
            ("betas_-0.1", {"betas": (-0.1, 0.9)}, "error", ("Adam", "betas")), ("betas_1.5", {"betas": (1.5, 0.9)}, "error", ("Adam", "betas")),
            ("betas_nan", {"betas": (math.nan, 0.9)}, "error", ("Adam", "betas")), ("betas_one", {"betas": (0.9,)}, "error", ("Adam", "betas")),
            ("eps_0", {"eps": 0.0}, "either", ("Adam", "eps")), ("eps_-1", {"eps": -1.0}, "error", ("Adam", "eps")),
            ("eps_nan", {"eps": math.nan}, "error", ("Adam", "eps"))):
        add(f"adam_{label}", expect, names, adam(**kw))
    add("adam_grad_1e38", "either", ("Adam",), adam(grad=1e38))
    add("adam_grad_1e300", "either", ("Adam",), adam(grad=1e300))
    add("adam_grad_inf", "error", ("Adam", "gradient"), adam(grad=math.inf))
    return cases


# ---- the whole battery -----------------------------------------------------------------------------

def all_cases() -> list[Case]:
    return (dict_field_cases() + dict_specific_cases() + file_cases() + mesh_cases() + image_cases() + transform_cases()
            + fuzz_regression_cases() + runtime_cases())


def classify(case: Case, tmp: str) -> tuple[str, str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            outputs = case.run(tmp)
        except (ValueError, TypeError, KeyError) as e:
            msg = (e.args[0] if isinstance(e, KeyError) and e.args else str(e))
            msg = msg if isinstance(msg, str) else str(msg)
            missing = [n for n in case.names if n not in msg]
            detail = f"{type(e).__name__}: {msg[:400]}"
            if case.expect == "ok":
                return "valid input refused", detail
            if not msg.strip() or missing:
                return "unclear error", detail + (f" [does not name {missing}]" if missing else " [empty message]")
            return "clean error", detail
        except RecursionError as e:
            return "unclear error", f"RecursionError: {str(e)[:200]}"
        except Exception as e:  # anything else is not a clean refusal
            return "unclear error", f"{type(e).__name__}: {str(e)[:400]}"
    for o in outputs:
        a = np.asarray(o, dtype=np.float64)
        if not np.isfinite(a).all():
            return "non-finite output", f"{int((~np.isfinite(a)).sum())} of {a.size} values are not finite"
    messages = [str(w.message) for w in caught]
    if case.expect == "error":
        return "nonsense accepted", "accepted; warnings: " + "; ".join(m[:160] for m in messages[:3])
    if case.expect == "warn" and not any(all(n in m for n in case.names) for m in messages):
        return "nonsense accepted", f"no warning naming {list(case.names)}; warnings: " + "; ".join(m[:160] for m in messages[:3])
    return "ok", ""


def worker(indices: list[int]) -> None:
    """Runs cases in this process; reports on a private copy of stdout (libraries may print)."""
    import resource
    resource.setrlimit(resource.RLIMIT_AS, (8 << 30, 8 << 30))  # a runaway allocation fails here, not in the machine
    proto = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)
    cases = all_cases()
    for i in indices:
        proto.write(f"S {i}\n")
        with tempfile.TemporaryDirectory(prefix="limn-hostile-") as tmp:
            outcome, detail = classify(cases[i], tmp)
        proto.write("R " + json.dumps([i, outcome, detail]) + "\n")
    proto.write("E\n")


def _spawn(indices: list[int]) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, os.path.abspath(__file__), "--worker", ",".join(map(str, indices))],
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, cwd=ROOT)


def _run_batch(indices: list[int], results: dict, suspects: list) -> None:
    """Runs `indices` in workers, restarting after a crash or hang; the case that was running then is
    put on `suspects` (to be run again alone)."""
    todo = list(indices)
    while todo:
        p = _spawn(todo)
        buf, current, deadline = b"", None, time.monotonic() + STARTUP_TIMEOUT
        done, failed = set(), None
        while True:
            wait = deadline - time.monotonic()
            ready = select.select([p.stdout], [], [], wait)[0] if wait > 0 else []
            if not ready:  # timeout
                p.kill()
                p.wait()
                if current is None:
                    raise RuntimeError("a battery worker stalled outside a case (import or case generation)")
                failed = current
                suspects.append((current, "hang"))
                break
            chunk = os.read(p.stdout.fileno(), 65536)
            if not chunk:  # the worker died (or finished)
                p.wait()
                if current is not None:
                    failed = current
                    suspects.append((current, f"crash (exit {p.returncode})"))
                elif len(done) < len(todo):
                    raise RuntimeError(f"a battery worker exited with {p.returncode} between cases")
                break
            buf += chunk
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                text = line.decode()
                if text.startswith("S "):
                    current = int(text[2:])
                elif text.startswith("R "):
                    i, outcome, detail = json.loads(text[2:])
                    results[i] = (outcome, detail)
                    done.add(i)
                    current = None
                deadline = time.monotonic() + CASE_TIMEOUT
        p.stdout.close()
        todo = [i for i in todo if i not in done and i != failed]


def _run_alone(i: int, first: str) -> tuple[str, str]:
    p = _spawn([i])
    try:
        out, _ = p.communicate(timeout=STARTUP_TIMEOUT + CASE_TIMEOUT)
    except subprocess.TimeoutExpired:
        p.kill()
        p.communicate()
        return "hang", f"no result within {CASE_TIMEOUT:.0f} s (alone; in its batch: {first})"
    for line in out.decode().splitlines():
        if line.startswith("R "):
            _, outcome, detail = json.loads(line[2:])
            return outcome, detail + f" [in its batch: {first}]"
    sig = -p.returncode if p.returncode < 0 else None
    name = signal.Signals(sig).name if sig else f"exit {p.returncode}"
    return "crash", f"died with {name} (alone; in its batch: {first})"


def run_battery(indices: list[int], jobs: int = JOBS) -> dict[int, tuple[str, str]]:
    results: dict[int, tuple[str, str]] = {}
    suspects: list = []
    chunks = [indices[k::jobs] for k in range(jobs)]
    threads = [threading.Thread(target=_run_batch, args=(c, results, suspects)) for c in chunks if c]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for i, first in suspects:
        results[i] = _run_alone(i, first)
    missing = [i for i in indices if i not in results]
    if missing:
        raise RuntimeError(f"no result for cases {missing[:10]}")
    return results


def summarize(cases: list[Case], results: dict) -> tuple[collections.Counter, list[str]]:
    counts = collections.Counter(results[i][0] for i in results)
    bad = [f"{results[i][0]:>20}  {cases[i].id}  ({cases[i].expect})  {results[i][1]}" for i in sorted(results) if results[i][0] not in CLEAN]
    return counts, bad


# ---- pytest ------------------------------------------------------------------------------------------

_RESULTS: dict = {}


def _results_for(area: str):
    cases = all_cases()
    if area not in _RESULTS:
        indices = [i for i, c in enumerate(cases) if c.area == area]
        _RESULTS[area] = run_battery(indices)
    return cases, _RESULTS[area]


def test_the_battery_has_over_1000_cases_and_every_class_of_input():
    cases = all_cases()
    assert len(cases) >= 1000, len(cases)
    groups = collections.Counter(c.id.split("/")[0] for c in cases)
    for g in ("dict", "dict-specific", "dict-structure", "file", "mesh", "image", "transform", "runtime"):
        assert groups[g] > 0, g
    assert len({c.id for c in cases}) == len(cases), "case ids must be unique"


def _check(area: str):
    cases, results = _results_for(area)
    counts, bad = summarize(cases, results)
    report = f"{area}: " + ", ".join(f"{k}: {counts.get(k, 0)}" for k in CLASSES)
    assert not bad, report + "\n" + "\n".join(bad[:60]) + (f"\n... and {len(bad) - 60} more" if len(bad) > 60 else "")


def test_loading_hostile_input_never_crashes_hangs_or_accepts_nonsense():
    """Scene dictionaries and files, mesh files, images, transforms, fuzz regressions."""
    _check("load")


def test_runtime_calls_with_hostile_arguments():
    """render / render_forward / render_backward, update() after extreme edits, Adam."""
    _check("runtime")


# ---- command line ------------------------------------------------------------------------------------

def main(argv: list[str]) -> int:
    if len(argv) >= 2 and argv[0] == "--worker":
        worker([int(i) for i in argv[1].split(",") if i])
        return 0
    area = argv[argv.index("--area") + 1] if "--area" in argv else None
    cases = all_cases()
    indices = [i for i, c in enumerate(cases) if area is None or c.area == area]
    t0 = time.monotonic()
    results = run_battery(indices)
    counts, bad = summarize(cases, results)
    import limn
    print(f"limn from {os.path.dirname(limn.__file__)}; {len(indices)} cases in {time.monotonic() - t0:.0f} s")
    by_group: dict = collections.defaultdict(collections.Counter)
    for i in indices:
        by_group[cases[i].area + ":" + cases[i].id.split("/")[0]][results[i][0]] += 1
    print(f"{'':>22}" + "".join(f"{k:>20}" for k in CLASSES))
    for g in sorted(by_group):
        print(f"{g:>22}" + "".join(f"{by_group[g].get(k, 0):>20}" for k in CLASSES))
    print(f"{'total':>22}" + "".join(f"{counts.get(k, 0):>20}" for k in CLASSES))
    print("\n".join(bad))
    if "--json" in argv:
        with open(argv[argv.index("--json") + 1], "w") as f:
            json.dump({cases[i].id: {"area": cases[i].area, "expect": cases[i].expect, "outcome": results[i][0], "detail": results[i][1]}
                       for i in indices}, f, indent=1)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
