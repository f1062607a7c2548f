"""Is the yarn's guided self-shadow derivative biased, or heavy-tailed? (docs/derivatives.md,
"Curves: the yarn's self-shadow under an area light"; tests/python/test_curves.py).

  .venv/bin/python tests/bench/yarn_guides.py

The yarn scene of test_curves.yarn_with_fd (area light, the upper strand moving), indirect term's
interior part only (the perimeter part is small there), at the five shadow pixels where the guided
block z-test fails: central differences (8 seeds, eps 0.02, 1024 spp), uniform boundary samples at
8192 spp (6 seeds), the default projective grid at 512 spp (48 seeds, a guide per call) and a
coarse grid (R = 4, one level, no direction histogram) at 512 spp (24 seeds). Prints each pixel's
mean +- standard error and, for the default grid, the spread of the seeds.
"""
from __future__ import annotations

import os
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
from test_curves import yarn_with_fd  # noqa: E402

PIXELS = [(9, 8), (10, 8), (11, 8), (12, 7), (12, 8)]


def main() -> None:
    warnings.simplefilter("ignore")
    scene, name, t, fd = yarn_with_fd("area")
    print("pixel          " + "".join(f"{str(p):>18s}" for p in PIXELS))

    def row(label, stack):
        m, se = stack.mean(0), stack.std(0, ddof=1) / np.sqrt(len(stack))
        print(f"{label:15s}" + "".join(f"{m[p][0]:>10.3f} +- {se[p][0]:.3f}" for p in PIXELS), flush=True)

    row("FD (all terms)", fd)
    runs = {
        "uniform 8192": (6, dict(spp_boundary=8192, guiding="none")),
        "grid 512": (48, dict(spp_boundary=512, guiding="grid")),
        "coarse grid 512": (24, dict(spp_boundary=512, guiding="grid", grid_resolution=4, grid_octaves=0, direction_mix=0.0)),
    }
    stacks = {}
    for label, (seeds, kw) in runs.items():
        start = time.time()
        stacks[label] = np.stack([scene.render_forward({name: t}, spp=4, spp_primary=0, boundary_parts="interior", guide_refresh=0,
                                                       seed=500 + k, **kw) for k in range(seeds)])
        row(label, stacks[label])
        print(f"{'':15s}({seeds} seeds, {time.time() - start:.0f} s)")
    print("default grid, each pixel's seeds sorted (smallest 4 ... largest 2):")
    for p in PIXELS:
        v = np.sort(stacks["grid 512"][(slice(None),) + p + (0,)])
        print(f"  {str(p):8s}", np.round(v[:4], 3), "...", np.round(v[-2:], 3))


if __name__ == "__main__":
    main()
