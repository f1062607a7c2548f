"""Bit-for-bit equality of renders, derivative images and gradients across a refactor.

    .venv/bin/python tests/refactor_equality.py record DIR     # before: writes DIR/<case>.npz
    .venv/bin/python tests/refactor_equality.py check DIR      # after: compares, exit code 1 on any difference
    .venv/bin/python tests/refactor_equality.py list           # the cases

Every scene of scenes/validation, scenes/projective, scenes/heightfield (and the bench, default and
shadow-wall scenes) is rendered, and differentiated forward (a fixed random tangent) and backward (a
fixed random adjoint) at fixed seeds: its named parameter with each guide ("none", the baseline
grid, the projective grid, the octree), and every parameter of the scene at once. One thread, so
that the boundary terms' per-thread sums are added in one order (the interior term and render()
do not depend on the thread count; the splatted terms do, in the last bits).

`check` prints, per array, whether it is bit-identical, else the largest difference in units in
the last place (float32) and relative to the array's RMS."""
from __future__ import annotations

import argparse
import glob
import os
import sys
import warnings

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(ROOT, "scenes")

# The parameter each scene is built to test (scenes/validation/README.md; the projective benches).
MAIN_PARAM = {
    "validation/occluder_point": "box.vertex_positions",
    "validation/occluder_area": "box.vertex_positions",
    "validation/self_shadow_point": "terrain.vertex_positions",
    "validation/self_shadow_area": "terrain.vertex_positions",
    "validation/sphere_occluder_point": "ball.center",
    "validation/sphere_occluder_area": "ball.radius",
    "validation/glossy_reflection": "shape.vertex_positions",
    "validation/glossy_reflection_reflective_emitter": "shape.vertex_positions",
    "validation/sphere_glossy_reflection": "shape.center",
    "validation/emitting_occluder_reflection": "shape.vertex_positions",
    "projective/sphere": "shape.center",
    "projective/torus": "shape.vertex_positions",
    "projective/cube_hole": "shape.vertex_positions",
    "projective/bunny": "shape.vertex_positions",
    "heightfield/bump": "terrain.heights",
    "heightfield/cone": "terrain.heights",
    "heightfield/terrain": "terrain.heights",
    "bench_shadow": "box.vertex_positions",
    "bench_reflection": "shape.vertex_positions",
    "bench_silhouette": "box.vertex_positions",
    "default": None,
    "shadow_wall/scene": "shape.vertex_positions",
}
GUIDES = {
    "none": {"guiding": "none"},
    "grid": {"guiding": "grid", "projective": False},
    "projective_grid": {"guiding": "grid"},
    "octree": {"guiding": "octree", "guiding_seeds": 16, "octree_training": 16},
}


def scene_files() -> list[tuple[str, str]]:
    out = []
    for pattern in ("validation/*.json", "projective/*.json", "heightfield/*.json", "*.json", "shadow_wall/scene.json"):
        for path in sorted(glob.glob(os.path.join(SCENES, pattern))):
            out.append((os.path.relpath(path, SCENES)[:-5], path))
    return out


def random_like(shape, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).standard_normal(shape)


def cases(scene_name: str, scene) -> list[tuple[str, list[str], dict]]:
    """(label, differentiable parameters, options) for the derivative calls of a scene."""
    out = []
    main = MAIN_PARAM.get(scene_name)
    heightfield = any(n.endswith(".heights") for n in scene.params)
    if main and main in scene.params:
        for g, opts in GUIDES.items():
            if heightfield and g != "none":
                continue  # the heightfield estimator has no guides
            out.append((f"{main}/{g}", [main], opts))
    names = [n for n in scene.params]
    if heightfield:  # only its heights and area emitters may move with a heightfield
        names = [n for n in names if not n.endswith((".vertex_positions", ".to_world.translation", ".center", ".radius"))
                 or n.endswith(".heights")]
    out.append(("all/none", names, {"guiding": "none"}))
    return out


def compute(scene_name: str, path: str) -> dict[str, np.ndarray]:
    import limn
    arrays = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = limn.load(path)
        arrays["render"] = scene.render(spp=8, seed=7, threads=1)
        for label, names, opts in cases(scene_name, scene):
            scene.set_differentiable(names)
            tangents = {n: random_like(scene.params[n].shape, 11 + i) for i, n in enumerate(names)}
            arrays[f"forward {label}"] = scene.render_forward(tangents, spp=4, seed=5, threads=1, **opts)
            adjoint = random_like((scene.height, scene.width, 3), 13).astype(np.float32)
            grads = scene.render_backward(adjoint, spp=4, seed=6, threads=1, **opts)
            for n, g in grads.items():
                arrays[f"backward {label} {n}"] = np.asarray(g)
    return arrays


def ulp_distance(a: np.ndarray, b: np.ndarray) -> int:
    """Largest distance in float32 units in the last place between a and b."""
    ia = np.asarray(a, dtype=np.float32).view(np.int32).astype(np.int64)
    ib = np.asarray(b, dtype=np.float32).view(np.int32).astype(np.int64)
    ia = np.where(ia < 0, -(ia & 0x7FFFFFFF), ia)
    ib = np.where(ib < 0, -(ib & 0x7FFFFFFF), ib)
    return int(np.max(np.abs(ia - ib))) if ia.size else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=["record", "check", "list"])
    ap.add_argument("dir", nargs="?", default=os.path.join(ROOT, "build", "equality"))
    ap.add_argument("--only", default="", help="substring of the scene names to run")
    args = ap.parse_args()
    os.makedirs(args.dir, exist_ok=True)
    failures = 0
    for name, path in scene_files():
        if args.only and args.only not in name:
            continue
        if args.mode == "list":
            print(name)
            continue
        arrays = compute(name, path)
        file = os.path.join(args.dir, name.replace("/", "__") + ".npz")
        if args.mode == "record":
            np.savez(file, **arrays)
            print(f"{name}: recorded {len(arrays)} arrays", flush=True)
            continue
        ref = dict(np.load(file))
        for key in sorted(set(ref) | set(arrays)):
            if key not in ref or key not in arrays:
                print(f"{name}: {key}: {'missing now' if key in ref else 'new'}")
                failures += 1
                continue
            a, b = ref[key], arrays[key]
            if a.shape == b.shape and np.array_equal(a, b):
                continue
            failures += 1
            if a.shape != b.shape:
                print(f"{name}: {key}: shape {a.shape} -> {b.shape}")
                continue
            rms = float(np.sqrt(np.mean(np.square(a.astype(np.float64))))) or 1.0
            print(f"{name}: {key}: differs in {int(np.sum(a != b))} of {a.size} values, max {ulp_distance(a, b)} ulp (float32), "
                  f"max |diff| / RMS {float(np.max(np.abs(a.astype(np.float64) - b))) / rms:.3g}")
        print(f"{name}: {len(arrays)} arrays checked", flush=True)
    if args.mode == "check":
        print("equality: " + ("all arrays bit-identical" if failures == 0 else f"{failures} arrays differ"))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
