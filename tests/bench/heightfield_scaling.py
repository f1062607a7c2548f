"""Heightfield cost against resolution (the heightfield paper's Figure 2 / A3 kind of study), in one run:
time per sample per pixel of the forward pass (render) and of the backward pass (render_backward with
the heightfield estimator: mipmap search with its curvature tests, with the maximum test alone, and
brute-force search) on the terrain and on the worst
case of Figure A2 (a smooth bump under a very large light), for 256^2 .. 2048^2 heights; and the
theta sub-range trade-off of App. C on the worst case (time against gradient variance).

Regenerate (after ./bootstrap.sh):
    .venv/bin/python tests/bench/heightfield_scaling.py            # writes docs/reports/heightfield/scaling.md
"""
from __future__ import annotations

import argparse
import copy
import importlib.util
import json
import os
import platform
import time
import warnings

import numpy as np

import limn
import limn.shapes

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
spec = importlib.util.spec_from_file_location("hf_make", os.path.join(ROOT, "scenes", "heightfield", "make.py"))
make = importlib.util.module_from_spec(spec)
spec.loader.exec_module(make)


def scene_at(name: str, n: int, film: int) -> limn.Scene:
    d = copy.deepcopy(make.SCENES[name])
    data = limn.shapes.terrain_heights(n) if name == "terrain" else limn.shapes.bump_heights(n)
    d["terrain"]["data"] = data.astype(np.float32)  # passed as an array, not as JSON lists
    d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = film
    return limn.load_dict(d)


def timed(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def cells(scene) -> int:
    line = next(l for l in scene.last_stats["summary"] if l.startswith("heightfield estimator"))
    return int(line.split("mipmap nodes and ")[1].split(" cells")[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolutions", default="256,512,1024,2048")
    ap.add_argument("--film", type=int, default=64)
    ap.add_argument("--spp", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "reports", "heightfield"))
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    warnings.simplefilter("ignore")
    res = [int(r) for r in args.resolutions.split(",")]
    rows = []
    for name in ("terrain", "bump"):
        for n in res:
            scene = scene_at(name, n, args.film)
            scene.set_differentiable(["terrain.heights"])
            adjoint = np.ones((args.film, args.film, 3), np.float32)
            px = args.film * args.film  # samples per spp
            lo, hi = args.spp, 4 * args.spp

            def per_sample(fn, **kw):
                # Slope between two budgets: the cost of one more sample, without the per-call cost
                # (for the backward pass, the gradient buffers: O(heights), 4M slots at 2048^2).
                t_lo = timed(lambda: fn(spp=lo, **kw), args.repeats)
                t_hi = timed(lambda: fn(spp=hi, **kw), args.repeats)
                return (t_hi - t_lo) / ((hi - lo) * px) * 1e6

            fwd = per_sample(scene.render)
            bwd = per_sample(lambda **kw: scene.render_backward(adjoint, **kw))
            c_fast = cells(scene) / (hi * px)
            max_only = per_sample(lambda **kw: scene.render_backward(adjoint, heightfield_curvature_test=False, **kw))
            c_max = cells(scene) / (hi * px)
            # The per-call cost, measured on a 2x2 film (8 samples); the brute force (seconds per call at
            # 2048^2) runs one budget and has it subtracted.
            tiny = scene_at(name, n, 2)
            tiny.set_differentiable(["terrain.heights"])
            tiny_adjoint = np.ones((2, 2, 3), np.float32)
            fixed = timed(lambda: tiny.render_backward(tiny_adjoint, spp=2), args.repeats)
            del tiny
            brute_t = timed(lambda: scene.render_backward(adjoint, spp=lo, heightfield_mipmap=False), 1)
            c_slow = cells(scene) / (lo * px)
            brute = (brute_t - fixed) / (lo * px) * 1e6
            rows.append(dict(scene=name, n=n, fwd=fwd, bwd=bwd, max_only=max_only, brute=brute, ratio=bwd / fwd,
                             fixed_ms=fixed * 1e3, cells=c_fast, cells_max=c_max, cells_brute=c_slow))
            print(rows[-1], flush=True)

    # App. C on the worst case: time and gradient variance per theta sub-range (same budget).
    sub = []
    scene = scene_at("bump", 512, 32)
    scene.set_differentiable(["terrain.heights"])
    t = {"terrain.heights": limn.shapes.bump_heights(512)}
    for deg in (0.0, 20.0, 5.0, 1.0):
        imgs, secs = [], []
        for k in range(8):
            t0 = time.perf_counter()
            imgs.append(scene.render_forward(t, spp=8, seed=100 + k, theta_subrange=deg))
            secs.append(time.perf_counter() - t0)
        imgs = np.stack(imgs)
        sub.append(dict(deg=deg, seconds=float(np.median(secs)), variance=float(imgs.var(0, ddof=1).mean()),
                        mean=float(imgs.mean()), cells=cells(scene) / (32 * 32 * 8)))
        print(sub[-1], flush=True)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, name in zip(axes, ("terrain", "bump")):
        r = [x for x in rows if x["scene"] == name]
        ns = [x["n"] for x in r]
        ax.loglog(ns, [x["fwd"] for x in r], "o-", label="forward (render)")
        ax.loglog(ns, [x["bwd"] for x in r], "s-", label="backward, mipmap search with curvature tests")
        ax.loglog(ns, [x["max_only"] for x in r], "d:", label="backward, mipmap maximum test only")
        ax.loglog(ns, [x["brute"] for x in r], "^--", label="backward, brute-force search")
        ax.set_xlabel("heights per side")
        ax.set_ylabel("microseconds per sample")
        ax.set_title(name if name == "terrain" else "bump under a huge light (worst case)")
        ax.legend()
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, "scaling.png"), dpi=110)

    lines = ["# Heightfield cost against resolution", "",
             f"Generated by `.venv/bin/python tests/bench/heightfield_scaling.py` on {platform.node()} "
             f"({os.cpu_count()} cores), film {args.film}x{args.film}, best of {args.repeats} runs at {args.spp} and "
             f"{4 * args.spp} spp; "
             "all numbers of one table come from one run.", "",
             "Time per sample per pixel (microseconds: the slope between the two budgets, so a call's fixed cost "
             "is left out; `backward per call` is that fixed cost, measured on a 2x2 film: mostly the per-thread "
             "gradient buffers of one double per height) of the forward pass (`Scene.render`, the path tracer "
             "through the mipmap ray traversal) and of the backward pass (`render_backward` with the heightfield "
             "estimator: peak search per slice, taped path, reverse sweep) with the maximum-mipmap peak search "
             "and its curvature tests (core/geometry/shapes/heightfield/peak_search.h, the default), with the mipmap's maximum test "
             "alone (the paper's Algorithm 1, `heightfield_curvature_test=False`), and with the brute-force search that "
             "samples every cell along each slice. `cells` is the number of level-0 cells the search sampled per "
             "camera sample.", "",
             "| scene | heights | forward us | backward us | backward / forward | backward per call ms | maximum test only: backward us "
             "| brute-force backward us | cells (curvature tests) | cells (maximum test only) | cells (brute force) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for x in rows:
        lines.append(f"| {x['scene']} | {x['n']}^2 | {x['fwd']:.2f} | {x['bwd']:.2f} | {x['ratio']:.1f} | {x['fixed_ms']:.0f} | {x['max_only']:.2f} | "
                     f"{x['brute']:.2f} | {x['cells']:.0f} | {x['cells_max']:.0f} | {x['cells_brute']:.0f} |")
    lines += ["", "![cost against resolution](scaling.png)", "",
              "## Theta sub-ranges on the worst case (App. C)", "",
              "Bump with 512^2 heights under the 40x40 light, 32x32 film, 8 spp, 8 seeds: median time of one "
              "`render_forward`, mean per-pixel variance of the derivative image over the seeds, and its mean "
              "(all estimates of the same quantity: the sub-ranges trade variance for time, not bias).", "",
              "| max sub-range | seconds | cells per sample | variance | mean |", "|---|---|---|---|---|"]
    for x in sub:
        label = "whole range" if x["deg"] == 0 else f"{x['deg']:g} deg"
        lines.append(f"| {label} | {x['seconds']:.3f} | {x['cells']:.0f} | {x['variance']:.3e} | {x['mean']:.4e} |")
    with open(os.path.join(args.out, "scaling.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("wrote", os.path.join(args.out, "scaling.md"))


if __name__ == "__main__":
    main()
