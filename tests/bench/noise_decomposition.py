"""Where a full derivative image's run-to-run noise comes from, on the projective-sampling test
scenes: `.venv/bin/python tests/bench/noise_decomposition.py [--budget 1024] [--runs 6] [--scenes sphere ...]`.

Every guide's full render is the sum of two renders with the same seed (render_forward's terms
add up exactly: tests/python/test_indirect_boundary.py): the interior and primary-visibility terms
(`spp_boundary=0`, the same for every guide) and the indirect boundary term alone (`spp_interior=0,
spp_primary=0`, the only term a guide acts on). So the full noise is measured from the sums, and the
indirect term's share and the guides' gain on that term alone come from the same runs. Noise: the
pixel RMS of the standard deviation over the runs, relative to the RMS of the bench's reference
(`python3 -m limn bench`: eps 0.005, 131072 spp, cached); equal time: noise x sqrt(time)."""
from __future__ import annotations

import argparse
import math
import os
import sys
import warnings

import numpy as np

import limn
from limn.examples.bench import default_tangent, guide_seconds, method_options

SCENES = {"sphere": "shape.center", "torus": "shape.vertex_positions", "cube_hole": "shape.vertex_positions",
          "bunny": "shape.vertex_positions"}
GUIDES = ["projective_grid", "octree"]


def noise(images: np.ndarray, ref_rms: float) -> float:
    return float(np.sqrt(np.var(images, axis=0, ddof=1).mean())) / ref_rms


def measure(name: str, budget: int, runs: int) -> dict:
    root = os.path.join(os.path.dirname(__file__), "..", "..", "scenes", "projective")
    scene = limn.load(os.path.join(root, name + ".json"))
    param = SCENES[name]
    scene.set_differentiable([param])
    t = {param: default_tangent(scene.params[param], "x")}
    ref = limn.fd(scene, t, eps=0.005, spp=131072, seed=12345)
    ref_rms = float(np.sqrt((ref.astype(np.float64) ** 2).mean()))
    configs = {"interior": {"spp_boundary": 0}}
    configs.update({g: dict(method_options(g), spp_interior=0, spp_primary=0) for g in GUIDES})
    images = {c: [] for c in configs}
    seconds = {c: [] for c in configs}
    setup = {c: [] for c in configs}
    for r in range(runs):  # interleaved, as the bench: every configuration shares the machine's drift
        print(f"{name}: run {r + 1} of {runs}", file=sys.stderr, flush=True)
        for c, opts in configs.items():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                img = scene.render_forward(t, spp=budget, seed=1000 * r, **opts)
            images[c].append(img.astype(np.float64))
            seconds[c].append(scene.last_stats["seconds"])
            setup[c].append(guide_seconds(scene.last_stats["summary"]))
    out = {"interior": (noise(np.stack(images["interior"]), ref_rms), float(np.mean(seconds["interior"])))}
    for g in GUIDES:
        alone = np.stack(images[g])
        full = alone + np.stack(images["interior"])
        out[g] = {"alone": noise(alone, ref_rms), "full": noise(full, ref_rms), "time": float(np.mean(seconds[g])),
                  "setup": float(np.mean(setup[g]))}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=int, default=1024)
    ap.add_argument("--runs", type=int, default=6)
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "..", "..", "docs", "reports", "projective",
                                                  "noise_decomposition.md"))
    args = ap.parse_args()
    results = {s: measure(s, args.budget, args.runs) for s in args.scenes}
    cmd = ".venv/bin/python tests/bench/noise_decomposition.py " + " ".join(sys.argv[1:])
    lines = ["# Where the derivative image's noise comes from", "",
             f"Regenerate: `{cmd.strip()}`", "",
             *[l for l in __doc__.split("\n\n")[1].splitlines()], "",
             f"{args.budget} spp for every term, {args.runs} runs per row on a shared 2-core machine. "
             "Time: mean seconds of one render of the indirect term alone (guide set-up included) or of the "
             "interior and primary terms. Equal-time gain of the octree over the projective grid: "
             "noise x sqrt(time) of the grid over that of the octree; for the full image the time is the "
             "sum of the two renders.", "",
             "| scene | interior + primary: noise | time (s) | guide | indirect term alone: noise | time (s) | set-up (s) "
             "| full image: noise | interior's share of the full variance |",
             "|---|---|---|---|---|---|---|---|---|"]
    gains_alone, gains_full = [], []
    for s, r in results.items():
        n_i, t_i = r["interior"]
        for g in GUIDES:
            x = r[g]
            lines.append(f"| {s} | {n_i:.4f} | {t_i:.2f} | {g} | {x['alone']:.4f} | {x['time']:.2f} | {x['setup']:.2f} | "
                         f"{x['full']:.4f} | {100 * n_i ** 2 / x['full'] ** 2:.0f} % |")
        grid, octree = r["projective_grid"], r["octree"]
        gains_alone.append(grid["alone"] * math.sqrt(grid["time"]) / (octree["alone"] * math.sqrt(octree["time"])))
        gains_full.append(grid["full"] * math.sqrt(grid["time"] + t_i) / (octree["full"] * math.sqrt(octree["time"] + t_i)))
    geo = lambda v: math.exp(sum(math.log(x) for x in v) / len(v))
    lines += ["", "Equal-time noise gain of the octree over the projective grid:", "",
              "| scene | indirect term alone | full image |", "|---|---|---|"]
    for s, a, f in zip(results, gains_alone, gains_full):
        lines.append(f"| {s} | {a:.2f}x | {f:.2f}x |")
    lines.append(f"| geometric mean | {geo(gains_alone):.2f}x | {geo(gains_full):.2f}x |")
    lines.append("")
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out, "w") as f:
        f.write("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
