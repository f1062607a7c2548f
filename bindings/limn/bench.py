"""Gradient error against run time: ``python3 -m limn bench scene.json --param NAME``.

Renders the finite-difference reference once (cached on disk), then for each method and budget
times render_forward and records RMSE and MAE against the reference (relative to the reference's
RMS). Writes <out>/<scene>.md (table, command, what was computed) and <out>/<scene>.png (plot)."""
from __future__ import annotations

import os
import shlex
import sys
import time
import warnings

import numpy as np

from .fd import fd
from .scene import load

METHODS = {
    "interior": {"spp_primary": 0, "spp_boundary": 0},
    "primary": {"spp_boundary": 0},
    "full": {},
    "grid": {"guiding": "grid"},
}


def default_tangent(value: np.ndarray, kind: str) -> np.ndarray:
    if kind == "x" and value.ndim == 2 and value.shape[1] == 3:
        t = np.zeros_like(value)
        t[:, 0] = 1.0
        return t
    if kind == "x" and value.shape == (3,):
        return np.array([1.0, 0.0, 0.0], np.float32)
    return np.ones_like(value)


def run(scene_path: str, param: str, methods: list[str], budgets: list[int], fd_spp: int, eps: float, out: str,
        tangent: str = "x", seed: int = 0, argv: list[str] | None = None) -> str:
    for m in methods:
        if m not in METHODS:
            raise ValueError(f"unknown method '{m}' (known: {', '.join(METHODS)})")
    scene = load(scene_path)
    if param not in scene.params:
        raise ValueError(f"{scene_path}: unknown parameter '{param}'")
    t = {param: default_tangent(scene.params[param], tangent)}
    scene.set_differentiable([param])
    t0 = time.perf_counter()
    reference = fd(scene, t, eps=eps, spp=fd_spp, seed=seed + 12345)
    t_ref = time.perf_counter() - t0
    ref_rms = float(np.sqrt((reference.astype(np.float64) ** 2).mean())) or 1.0
    rows, summary = [], {}
    for m in methods:
        for b in budgets:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                img = scene.render_forward(t, spp=b, seed=seed, **METHODS[m])
            st = scene.last_stats
            err = img.astype(np.float64) - reference
            rows.append((m, b, st["seconds"], float(np.sqrt((err ** 2).mean())) / ref_rms, float(np.abs(err).mean()) / ref_rms))
            summary[m] = st["summary"]
    name = os.path.splitext(os.path.basename(scene_path))[0]
    os.makedirs(out, exist_ok=True)
    command = "python3 -m limn " + " ".join(shlex.quote(a) for a in (argv or []))
    lines = [f"# Gradient error against run time: {name}", "",
             f"Regenerate: `{command}`", "",
             f"Parameter `{param}`, tangent `{tangent}`; reference: central differences, eps {eps}, {fd_spp} spp "
             f"({t_ref:.1f} s, cached). Errors are relative to the reference's RMS. Film {scene.width}x{scene.height}; "
             f"budget = samples per pixel for every term computed. One run on a shared 2-core machine.", "",
             "| method | budget (spp) | time (s) | relative RMSE | relative MAE |", "|---|---|---|---|---|"]
    for m, b, sec, rmse, mae in rows:
        lines.append(f"| {m} | {b} | {sec:.3f} | {rmse:.4f} | {mae:.4f} |")
    lines += ["", "Terms per method (the renderer's own summary):", ""]
    for m, s in summary.items():
        lines.append(f"- **{m}**: " + "; ".join(s))
    lines.append("")
    md = os.path.join(out, name + ".md")
    with open(md, "w") as f:
        f.write("\n".join(lines))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(5, 3.6))
        for m in methods:
            pts = [(r[2], r[3]) for r in rows if r[0] == m]
            ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", label=m)
        ax.set_xlabel("render_forward time (s)")
        ax.set_ylabel("relative RMSE vs FD")
        ax.set_title(name)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(os.path.join(out, name + ".png"), dpi=120)
        plt.close(fig)
        with open(md, "a") as f:
            f.write(f"![error against time]({name}.png)\n")
    except ImportError:
        print("matplotlib is not available: no plot written", file=sys.stderr)
    return md
