"""Heightfield optimisations of the heightfield paper (Tong et al. 2023), each with Adam and the
Large-Steps (Laplacian) preconditioner on the grid of heights: ``python3 -m limn demo heightfield``.

- terrain (Figure 8): a terrain recovered from a flat plane from four views under a sky and a
  sun-like area light; the height error against the ground truth is known.
- shadow art (Figure 3): the right half of the field must cast a target shadow onto the left half,
  which is held at zero so the shadow cannot come from shading alone (the target is rendered from a
  known right half, so it is a shadow a field can cast).
- two lights (Figure 1): one field, two lighting conditions, two different target images (ridges
  along x under one light, along y under the other); the field has to serve both.

``--report DIR`` writes DIR/optimisation.md and a plot of loss and height error against time."""
from __future__ import annotations

import json
import os
import time
import warnings

import numpy as np

from .. import load_dict, optim, write_image
from ..shapes import terrain_heights

N = 33  # heights per side


def sensor(origin, target=(0, 0, 0.1), res=40, fov=40):
    # Straight down (x = y = 0): +y is the image's up; otherwise +z.
    up = [0, 1, 0] if origin[0] == 0 and origin[1] == 0 else [0, 0, 1]
    return {"type": "perspective", "fov": fov,
            "to_world": {"look_at": {"origin": list(origin), "target": list(target), "up": up}},
            "film": {"type": "hdrfilm", "width": res, "height": res}, "sampler": {"type": "independent", "sample_count": 8}}


def light(position, radiance, scale=0.35):
    return {"type": "rectangle",
            "to_world": [{"scale": scale}, {"look_at": {"origin": list(position), "target": [0, 0, 0], "up": [0, 0, 1]}}],
            "emitter": {"type": "area", "radiance": radiance}}


def view(heights, origin, light_pos, height_scale=0.35, sky=0.3, radiance=25.0, res=40):
    return {"type": "scene", "integrator": {"type": "path", "max_depth": 2},
            "sensor": sensor(origin, res=res),
            "terrain": {"type": "heightfield", "data": np.asarray(heights, np.float32), "size": [2, 2],
                        "height_scale": height_scale, "bsdf": {"type": "diffuse", "reflectance": 0.6}},
            "light": light(light_pos, radiance),
            **({"sky": {"type": "constant", "radiance": sky}} if sky > 0 else {})}


def ridges(axis: str, n: int = N) -> np.ndarray:
    x = np.linspace(-1, 1, n)
    X, Y = np.meshgrid(x, -x)
    u = X if axis == "x" else Y
    return (0.5 + 0.5 * np.cos(3 * np.pi * u) * np.exp(-(X ** 2 + Y ** 2) / 0.5)).astype(np.float32)


def problem(task: str):
    """(views as (scene, target), mask or None, ground truth or None, description)."""
    flat = np.zeros((N, N), np.float32)
    if task == "terrain":
        truth = terrain_heights(N, seed=5)
        sun = (1.6, 1.0, 1.2)
        origins = [(0, -2.6, 2.4), (2.6, 0, 2.4), (0, 2.6, 2.4), (-2.6, 0, 2.4)]
        targets = [load_dict(view(truth, o, sun)).render(spp=256, seed=900 + i) for i, o in enumerate(origins)]
        views = [(load_dict(view(flat, o, sun)), t) for o, t in zip(origins, targets)]
        return views, None, truth, "terrain from four views (Figure 8)"
    if task == "shadow_art":
        # Looking down (image left = world -x) with a low light from +x: the left half is held at zero,
        # so the target shadow on it can only come from the right half. The target is rendered from a
        # known right half (a ridge near the middle), so the shadow is one a field can cast. A flat
        # start casts no shadow and so has no shadow derivative: the free half starts from a gentle
        # random relief (the paper's CLIP task needs a bumpy start for the same reason).
        x = np.linspace(-1, 1, N)
        X, Y = np.meshgrid(x, -x)
        free = X > 0.0
        truth = np.where(free, 1.2 * np.exp(-((X - 0.3) ** 2 / 0.02 + Y ** 2 / 0.15)), 0.0).astype(np.float32)
        start = np.where(free, 0.3 * terrain_heights(N, seed=11), 0.0).astype(np.float32)
        sun = (2.6, 0.0, 0.45)
        target = load_dict(view(truth, (0, 0, 3.2), sun, sky=0.05, radiance=60.0)).render(spp=256, seed=901)
        lit = load_dict(view(start, (0, 0, 3.2), sun, sky=0.05, radiance=60.0))
        mask = free.astype(np.float32).ravel()  # the left half (x <= 0) stays at 0
        return [(lit, target)], mask, truth, "shadow art with the left half held at zero (Figure 3)"
    if task == "two_lights":
        a, b = (2.0, 0.4, 1.0), (-0.4, 2.0, 1.0)
        t1 = load_dict(view(ridges("x"), (0, 0, 3.0), a, sky=0.1)).render(spp=256, seed=902)
        t2 = load_dict(view(ridges("y"), (0, 0, 3.0), b, sky=0.1)).render(spp=256, seed=903)
        views = [(load_dict(view(flat, (0, 0, 3.0), a, sky=0.1)), t1), (load_dict(view(flat, (0, 0, 3.0), b, sky=0.1)), t2)]
        return views, None, None, "two lighting conditions, two target images (Figure 1)"
    raise ValueError(f"unknown heightfield task '{task}' (known: terrain, shadow_art, two_lights)")


TASKS = ("terrain", "shadow_art", "two_lights")


def run(task: str = "terrain", out: str = "out/heightfield", iterations: int = 80, spp: int = 4, lr: float = 0.05,
        lambda_: float = 10.0, verbose: bool = True) -> dict:
    os.makedirs(out, exist_ok=True)
    views, mask, truth, what = problem(task)
    name = "terrain.heights"
    history = []
    t0 = time.perf_counter()

    def report(it, loss, heights):
        err = float(np.sqrt(((heights - truth) ** 2).mean()) * 0.35) if truth is not None else None
        history.append({"iteration": it, "loss": loss, "height_rmse": err, "seconds": time.perf_counter() - t0})
        if verbose and (it % 10 == 0 or it == iterations - 1):
            extra = f"  height RMSE {err:.4f}" if err is not None else ""
            print(f"{task}: iteration {it:4d}  loss {loss:.5f}{extra}  {time.perf_counter() - t0:6.1f} s", flush=True)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = optim.fit(views, name, iterations=iterations, lr=lr, lambda_=lambda_, spp=spp,
                           faces=optim.grid_faces(N, N), mask=mask, callback=report)
    final = views[0][0].params[name].copy()
    summary = {"task": task, "what": what, "initial_loss": result.losses[0], "final_loss": result.losses[-1],
               "seconds": time.perf_counter() - t0, "iterations": len(result.losses), "history": history}
    if truth is not None:
        summary["initial_height_rmse"] = float(np.sqrt((truth ** 2).mean()) * 0.35)
        summary["final_height_rmse"] = float(np.sqrt(((final - truth) ** 2).mean()) * 0.35)
    for i, (s, t) in enumerate(views):
        write_image(os.path.join(out, f"{task}_view{i}_result.png"), s.render(spp=64))
        write_image(os.path.join(out, f"{task}_view{i}_target.png"), t)
    np.save(os.path.join(out, f"{task}_heights.npy"), final)
    with open(os.path.join(out, f"{task}_history.json"), "w") as f:
        json.dump(summary, f, indent=1)
    if verbose:
        extra = (f", height RMSE {summary['initial_height_rmse']:.4f} -> {summary['final_height_rmse']:.4f}"
                 if truth is not None else "")
        print(f"{task}: loss {summary['initial_loss']:.5f} -> {summary['final_loss']:.5f}{extra} in {summary['seconds']:.1f} s; "
              f"wrote {os.path.abspath(out)}")
    return summary


def report(folder: str, iterations: int = 80, argv: str = "") -> str:
    """All three tasks; DIR/optimisation.md, optimisation.png and the renders."""
    os.makedirs(folder, exist_ok=True)
    runs = [run(task, out=folder, iterations=iterations) for task in TASKS]
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for r in runs:
        h = r["history"]
        axes[0].semilogy([x["seconds"] for x in h], [x["loss"] / h[0]["loss"] for x in h], label=r["task"])
        if r["task"] == "terrain":
            axes[1].plot([x["seconds"] for x in h], [x["height_rmse"] for x in h], label="terrain")
    axes[0].set_xlabel("seconds")
    axes[0].set_ylabel("loss / initial loss")
    axes[0].legend()
    axes[1].set_xlabel("seconds")
    axes[1].set_ylabel("height RMSE (scene units)")
    axes[1].legend()
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(folder, "optimisation.png"), dpi=110)
    lines = ["# Heightfield optimisations (heightfield paper, Figures 1, 3, 8)", "",
             f"Generated by `{argv or 'python3 -m limn demo heightfield --report ' + folder}`. "
             f"{N}x{N} heights (height_scale 0.35, 2x2 field), 40x40 films, 4 spp per view and iteration, "
             "Adam (lr 0.05) with the Large-Steps preconditioner (lambda 10) on the grid's Laplacian; the "
             "derivatives come from the heightfield estimator. Times are wall-clock on this machine.", "",
             "| task | iterations | seconds | loss first -> last | height RMSE first -> last |", "|---|---|---|---|---|"]
    for r in runs:
        err = (f"{r['initial_height_rmse']:.4f} -> {r['final_height_rmse']:.4f}" if "final_height_rmse" in r else "n/a (no unique answer)")
        lines.append(f"| {r['what']} | {r['iterations']} | {r['seconds']:.1f} | {r['initial_loss']:.5f} -> {r['final_loss']:.5f} | {err} |")
    lines += ["", "![loss and height error against time](optimisation.png)", "",
              "Renders of every view (target and result) are next to this file: `<task>_view<i>_target.png`, "
              "`<task>_view<i>_result.png`; the optimised heights as `<task>_heights.npy`."]
    path = os.path.join(folder, "optimisation.md")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    return path
