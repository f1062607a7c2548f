"""Gradient error against run time: ``python3 -m limn bench scene.json --param NAME``.

Renders the finite-difference reference once (two independent halves, whose difference measures the
reference's own error), then for each method and budget
times render_forward and records RMSE and MAE against the reference (relative to the reference's
RMS). Writes <out>/<scene>.md (table, command, what was computed) and <out>/<scene>.png (plot)."""
from __future__ import annotations

import os
import shlex
import sys
import time
import warnings

import numpy as np

from .. import fd, load

METHODS = {
    "interior": {"spp_primary": 0, "spp_boundary": 0},
    "primary": {"spp_boundary": 0},
    "full": {"guiding": "none"},                                   # indirect term, uniform boundary sampling
    "default": {},                                                 # the defaults (guiding "auto")
    "grid": {"guiding": "grid", "projective": False},              # path-space baseline, 4 points per cell
    "grid10x": {"guiding": "grid", "projective": False, "guiding_spp": 40},
    "projective_grid": {"guiding": "grid", "projective": True},
    # The paper's projective grid: one grid, no direction histogram (section 5.1.1).
    "paper_projective_grid": {"guiding": "grid", "projective": True, "grid_octaves": 0, "direction_mix": 0.0},
    "octree_untrained": {"guiding": "octree", "octree_training": 0, "octree_refine_rounds": 0},  # the paper's octree
    "octree_unrefined": {"guiding": "octree", "octree_refine_rounds": 0},  # with the training round
    "octree": {"guiding": "octree"},              # and two rounds splitting the heavy leaves (the default)
}


def method_options(method: str) -> dict:
    """A method's options; ``name:independent`` is the method with independent boundary points
    instead of the default stratified ones (``boundary_sampler``)."""
    name, _, sampler = method.partition(":")
    if name not in METHODS or sampler not in ("", "independent", "stratified"):
        raise ValueError(f"unknown method '{method}' (known: {', '.join(METHODS)}, each optionally with "
                         f"':independent' or ':stratified')")
    return dict(METHODS[name], **({"boundary_sampler": sampler} if sampler else {}))


def default_tangent(value: np.ndarray, kind: str) -> np.ndarray:
    if kind == "x" and value.ndim == 2 and value.shape[1] in (3, 4):  # vertices; curve points (x, y, z, r): radius kept
        t = np.zeros_like(value)
        t[:, 0] = 1.0
        return t
    if kind == "x" and value.shape == (3,):
        return np.array([1.0, 0.0, 0.0], np.float32)
    return np.ones_like(value)


def guide_seconds(summary: list[str]) -> float:
    """Guide build time from the indirect term's summary line (0 when nothing was built)."""
    for line in summary:
        if "built in " in line:
            return float(line.split("built in ")[1].split(" s")[0])
    return 0.0


def run(scene_path: str, param: str, methods: list[str], budgets: list[int], fd_spp: int, eps: float, out: str,
        tangent: str = "x", seed: int = 0, argv: list[str] | None = None, runs: int = 1) -> str:
    options = {m: method_options(m) for m in methods}
    scene = load(scene_path)
    if param not in scene.params:
        raise ValueError(f"{scene_path}: unknown parameter '{param}'")
    t = {param: default_tangent(scene.params[param], tangent)}
    scene.set_differentiable([param])
    t0 = time.perf_counter()
    # The reference as the mean of two independent halves (fd_spp / 2 each): half their difference
    # estimates the reference's own error (the mean of two halves has the variance of one half / 2,
    # the difference twice one half's), which bounds how small an RMSE against it can be measured.
    halves = [fd(scene, t, eps=eps, spp=max(1, fd_spp // 2), seed=seed + 12345 + 7 * h).astype(np.float64) for h in (0, 1)]
    reference = 0.5 * (halves[0] + halves[1])
    t_ref = time.perf_counter() - t0
    ref_rms = float(np.sqrt((reference ** 2).mean())) or 1.0
    ref_noise = float(np.sqrt((0.25 * (halves[0] - halves[1]) ** 2).mean())) / ref_rms
    # Runs interleaved (for each budget and run, every method in turn): a shared machine's speed
    # drifts by tens of per cent over a bench, and every method should see the same drift.
    samples = {(m, b): [] for m in methods for b in budgets}
    summary = {}
    for b in budgets:
        for r in range(runs):
            print(f"bench {os.path.basename(scene_path)}: {b} spp, run {r + 1} of {runs}", file=sys.stderr, flush=True)
            for m in methods:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    # guide_refresh=0: every call builds its own guide (the cache holds one guide per
                    # scene, and interleaved methods would otherwise reuse each other's).
                    img = scene.render_forward(t, spp=b, seed=seed + 1000 * r, **dict(options[m], guide_refresh=0))
                st = scene.last_stats
                samples[(m, b)].append((img.astype(np.float64), st["seconds"], guide_seconds(st["summary"])))
                summary[m] = st["summary"]
    rows = []
    for (m, b), runs_mb in samples.items():
        images = np.stack([x[0] for x in runs_mb])
        err = images - reference
        rmse = np.sqrt((err ** 2).mean(axis=(1, 2, 3))) / ref_rms
        mae = np.abs(err).mean(axis=(1, 2, 3)) / ref_rms
        # Means over runs: the RMSE as the root of the mean squared error, so outliers count. The
        # noise is the estimator's own standard deviation (pixel RMS of the sample variance over
        # the runs): the RMSE a reference without error would give, as the estimators are unbiased.
        noise = float(np.sqrt(np.var(images, axis=0, ddof=1).mean())) / ref_rms if runs > 1 else float("nan")
        rows.append((m, b, float(np.mean([x[1] for x in runs_mb])), float(np.sqrt(np.mean(rmse ** 2))), float(np.mean(mae)),
                     float(np.mean([x[2] for x in runs_mb])), float(np.max(rmse)), noise))
    name = os.path.splitext(os.path.basename(scene_path))[0]
    os.makedirs(out, exist_ok=True)
    command = "python3 -m limn " + " ".join(shlex.quote(a) for a in (argv or []))
    lines = [f"# Gradient error against run time: {name}", "",
             f"Regenerate: `{command}`", "",
             f"Parameter `{param}`, tangent `{tangent}`; reference: central differences, eps {eps}, {fd_spp} spp "
             f"as two independent halves ({t_ref:.1f} s); the reference's own error (the pixel RMS of half the "
             f"halves' difference, relative to its RMS): {ref_noise:.4f}, a floor under every relative RMSE below. Errors are relative to the reference's RMS. Film {scene.width}x{scene.height}; "
             f"budget = samples per pixel for every term computed. {runs} run(s) per row on a shared 2-core machine "
             f"(seeds differ; for each budget and run every method in turn, so that they share the machine's drift); time includes building the guide (in every call: guide_refresh=0).", "",
             "Methods: `full` uniform boundary sampling; `grid` / `grid10x` the path-space baseline grid with 4 / 40 "
             "random points per cell; `projective_grid` and `octree` filled from projected seeds (`paper_projective_grid`: "
             "one grid and no direction histogram, as in the paper; `octree_untrained`: "
             "from the projections alone, as in the paper; `octree_unrefined`: with the training round's points too; "
             "`octree`: and two refinement rounds, the default). "
             "The indirect term's boundary points are stratified (`boundary_sampler`, the default) unless the method "
             "says `:independent`.", "",
             "Run-to-run noise: the pixel RMS of the standard deviation over the runs, relative to the reference's RMS "
             "(the error against a reference without error of its own; the RMSE also holds the reference's error).", "",
             "| method | budget (spp) | time (s) | guide set-up (s) | relative RMSE | worst run | relative MAE | run-to-run noise |",
             "|---|---|---|---|---|---|---|---|"]
    for m, b, sec, rmse, mae, guide, worst, noise in rows:
        lines.append(f"| {m} | {b} | {sec:.3f} | {guide:.3f} | {rmse:.4f} | {worst:.4f} | {mae:.4f} | "
                     + (f"{noise:.4f} |" if noise == noise else "n/a (1 run) |"))
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
        panels = [(3, "relative RMSE vs FD")] + ([(7, "run-to-run noise")] if runs > 1 else [])
        fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 3.6), squeeze=False)
        for ax, (col, label) in zip(axes[0], panels):
            for m in methods:
                pts = [(r[2], r[col]) for r in rows if r[0] == m]
                ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", label=m)
            ax.axhline(ref_noise, color="grey", ls="--", lw=1, label="FD reference's own error")
            ax.set_xlabel("render_forward time (s)")
            ax.set_ylabel(label)
            ax.set_title(f"{name}: {label}")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(os.path.join(out, name + ".png"), dpi=120)
        plt.close(fig)
        with open(md, "a") as f:
            f.write(f"![error against time]({name}.png)\n")
    except ImportError:
        print("matplotlib is not available: no plot written", file=sys.stderr)
    return md
