"""Cost of render_backward relative to render at equal samples per pixel, and memory, on the
demo scene (limn.examples.multiview: a 642-vertex mesh, three views' first camera, 48x48). Writes
docs/reports/derivative_cost.md. Run after ./bootstrap.sh:

    .venv/bin/python tests/bench/derivative_cost.py
"""
from __future__ import annotations

import os
import resource
import statistics
import sys
import time
import warnings

import numpy as np

import limn
from limn.examples import multiview
from limn.shapes import icosphere

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def timed(fn, repeats=3):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> int:
    warnings.simplefilter("ignore")
    sphere, faces = icosphere(2)
    rows = []
    for size in (48, 128):
        scene = limn.load_dict(multiview.view(multiview.ground_truth(sphere), faces, (0, -4.5, 1.2), size))
        scene.set_differentiable(["shape.vertex_positions"])
        adjoint = np.random.default_rng(0).normal(size=(size, size, 3)).astype(np.float32)
        for spp in (8, 32):
            t_render = timed(lambda: scene.render(spp=spp))
            t_interior = timed(lambda: scene.render_backward(adjoint, spp=spp, spp_primary=0, spp_boundary=0))
            t_full = timed(lambda: scene.render_backward(adjoint, spp=spp))
            rows.append((size, spp, t_render, t_interior, t_full))
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    lines = ["# Cost of derivatives", "",
             "Regenerate: `.venv/bin/python tests/bench/derivative_cost.py` (after `./bootstrap.sh`).", "",
             "The demo's shape (642 vertices, flat shading, sun and sky, path tracer max_depth 3) seen from its "
             "first camera; all vertex positions differentiable; medians of 3 runs at 2 threads on a shared machine. "
             "render_backward includes the interior term and, for 'all terms', the primary and indirect boundary terms "
             "at the same samples per pixel.", "",
             "| film | spp | render (s) | backward, interior (s) | ratio | backward, all terms (s) | ratio |",
             "|---|---|---|---|---|---|---|"]
    for size, spp, tr, ti, tf in rows:
        lines.append(f"| {size}x{size} | {spp} | {tr:.3f} | {ti:.3f} | {ti / tr:.2f} | {tf:.3f} | {tf / tr:.2f} |")
    lines += ["", f"Peak resident memory of the whole process (Python, numpy, scenes, tapes): {rss_mb:.0f} MB. "
              "The tape holds one path (or one boundary sample) per thread at a time, so derivative memory does not grow "
              "with the image or the sample count; gradients are one double per parameter slot per thread.", ""]
    out = os.path.join(ROOT, "docs", "reports", "derivative_cost.md")
    with open(out, "w") as f:
        f.write("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
