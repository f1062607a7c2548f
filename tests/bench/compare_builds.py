"""Two builds of limn on the same seeds: did a change make a guide worse, or did the reports' seeds?

The bench reports all use seeds 1000 r (run r), so one unlucky realisation shows in every one of
them. This renders the derivative image with each method, on seeds the reports do not use, with the
installed limn and with another build, against one finite-difference reference (the bench's, from the
installed build), and
prints each one's relative RMSE, median and worst run and run-to-run noise (as `python3 -m limn
bench` defines them). Build the other commit beside the checkout first, e.g.

    git worktree add /tmp/old <commit>
    .venv/bin/pip install --no-deps --no-build-isolation --target /tmp/oldlimn /tmp/old
    .venv/bin/python tests/bench/compare_builds.py --other /tmp/oldlimn scenes/projective/bunny.json

(twelfth pass of docs/reports/projective/README.md: 16 runs per method, about 7 min per build on 2 cores).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import warnings


def measure(scene_path: str, param: str, methods: list[str], budget: int, runs: int, seed: int, reference_file: str) -> dict:
    """Errors of the limn on sys.path (called in a child process per build). The first build's
    child writes the reference to reference_file; the second reads it, so both meet one reference."""
    import numpy as np
    import limn
    try:
        from limn.examples.bench import default_tangent, method_options
    except ImportError:  # a build from before the bench moved to limn.examples
        from limn.bench import default_tangent, method_options
    scene = limn.load(scene_path)
    t = {param: default_tangent(scene.params[param], "x")}
    scene.set_differentiable([param])
    if os.path.exists(reference_file):
        reference = np.load(reference_file)
    else:
        reference = limn.fd(scene, t, eps=0.005, spp=131072, seed=12345).astype(np.float64)  # the bench's, cached
        np.save(reference_file, reference)
    ref_rms = float(np.sqrt((reference ** 2).mean())) or 1.0
    rows = {}
    for m in methods:
        images = []
        for r in range(runs):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                images.append(scene.render_forward(t, spp=budget, seed=seed + 1000 * r, **method_options(m)).astype(np.float64))
            print(f"{limn.__file__}: {m}, run {r + 1} of {runs}", file=sys.stderr, flush=True)
        images = np.stack(images)
        rmse = np.sqrt(((images - reference) ** 2).mean(axis=(1, 2, 3))) / ref_rms
        rows[m] = {"rmse": float(np.sqrt((rmse ** 2).mean())), "median": float(np.median(rmse)), "worst": float(rmse.max()),
                   "noise": float(np.sqrt(np.var(images, axis=0, ddof=1).mean())) / ref_rms}
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--other", required=True, help="folder holding the other build's `limn` package (pip --target)")
    ap.add_argument("--param", default="shape.vertex_positions")
    ap.add_argument("--methods", default="projective_grid,octree")
    ap.add_argument("--budget", type=int, default=1024)
    ap.add_argument("--runs", type=int, default=16)
    ap.add_argument("--seed", type=int, default=50000, help="run r uses seed + 1000 r (the reports use 0 + 1000 r)")
    ap.add_argument("--child", help=argparse.SUPPRESS)  # the reference's .npy file
    args = ap.parse_args()
    methods = args.methods.split(",")
    if args.child:
        print(json.dumps(measure(args.scene, args.param, methods, args.budget, args.runs, args.seed, args.child)))
        return
    if not os.path.isdir(os.path.join(args.other, "limn")):
        sys.exit(f"compare_builds: {args.other} holds no `limn` package (build it with pip install --target {args.other})")
    results = {}
    with tempfile.TemporaryDirectory(prefix="limn_compare_builds_") as folder:
        reference_file = os.path.join(folder, "reference.npy")
        for label, extra_path in (("installed", None), ("other", args.other)):
            env = dict(os.environ)
            if extra_path:
                env["PYTHONPATH"] = os.path.abspath(extra_path) + os.pathsep + env.get("PYTHONPATH", "")
            child = [sys.executable, os.path.abspath(__file__), args.scene, "--other", args.other, "--param", args.param,
                     "--methods", args.methods, "--budget", str(args.budget), "--runs", str(args.runs), "--seed", str(args.seed),
                     "--child", reference_file]
            results[label] = json.loads(subprocess.run(child, env=env, check=True, stdout=subprocess.PIPE, text=True).stdout)
    print(f"{args.scene}, {args.budget} spp, {args.runs} runs (seeds {args.seed} + 1000 r); relative to the reference's RMS\n")
    print("| build | method | RMSE | median run | worst run | run-to-run noise |")
    print("|---|---|---|---|---|---|")
    for label, rows in results.items():
        for m, r in rows.items():
            print(f"| {label} | {m} | {r['rmse']:.4f} | {r['median']:.4f} | {r['worst']:.4f} | {r['noise']:.4f} |")


if __name__ == "__main__":
    main()
