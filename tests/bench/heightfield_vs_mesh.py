"""Heightfield estimator against the mesh pipeline on the same surface, in one run: gradient error
against run time at several sample budgets. The mesh is the heightfield's B-spline surface sampled
at the grid points (smooth vertex normals); its tangent is the same height change pushed through
the same sampling, so both describe one motion. Each renderer is compared with its own central
finite-difference reference (the two surfaces differ by the triangulation), high-sample, split in
two halves to estimate the reference's own noise.

Regenerate (after ./bootstrap.sh):
    .venv/bin/python tests/bench/heightfield_vs_mesh.py        # writes docs/reports/heightfield/vs_mesh.md
"""
from __future__ import annotations

import argparse
import copy
import json
import os
import platform
import time
import warnings

import numpy as np

import limn
import limn.shapes

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def mesh_of(d: dict) -> dict:
    """The heightfield of scene d as a triangle mesh through its surface at the grid points."""
    hf = d["terrain"]
    v, f = limn.shapes.heightfield_as_mesh(np.asarray(hf["data"], np.float32), hf["size"], hf["height_scale"])
    m = copy.deepcopy(d)
    m["terrain"] = {"type": "mesh", "vertex_positions": v, "faces": f, "face_normals": False, "bsdf": hf["bsdf"]}
    return m


def blocks(img: np.ndarray, b: int = 4) -> np.ndarray:
    h, w, c = img.shape
    return img.reshape(h // b, b, w // b, b, c).mean(axis=(1, 3))


def rel_rmse(a: np.ndarray, ref: np.ndarray) -> float:
    """RMSE of 4x4-pixel block means, relative to the reference's RMS (blocks: the FD reference's
    per-pixel noise would otherwise set the floor)."""
    a, ref = blocks(a), blocks(ref)
    return float(np.sqrt(((a - ref) ** 2).mean()) / np.sqrt((ref ** 2).mean()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="cone", choices=["cone", "terrain"])
    ap.add_argument("--budgets", default="4,16,64,256")
    ap.add_argument("--fd-spp", type=int, default=16384)
    ap.add_argument("--runs", type=int, default=3, help="independent runs per budget (errors averaged)")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "reports", "heightfield"))
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    with open(os.path.join(ROOT, "scenes", "heightfield", args.scene + ".json")) as f:
        d = json.load(f)
    h = np.asarray(d["terrain"]["data"], np.float32)
    t_h = h.copy() if args.scene == "cone" else np.maximum(0, 1 - (np.linspace(-1, 1, h.shape[1])[None] ** 2 +
                                                                    np.linspace(-1, 1, h.shape[0])[:, None] ** 2) / 0.3) ** 2
    t_h = t_h.astype(np.float32)
    t_mesh = np.zeros((h.size, 3), np.float32)
    t_mesh[:, 2] = (d["terrain"]["height_scale"] * limn.shapes.bspline_at_grid(t_h)).ravel()

    hf_scene = limn.load_dict(d)
    hf_scene.set_differentiable(["terrain.heights"])
    mesh_scene = limn.load_dict(mesh_of(d))
    mesh_scene.set_differentiable(["terrain.vertex_positions"])
    cases = {"heightfield": (hf_scene, {"terrain.heights": t_h}), "mesh": (mesh_scene, {"terrain.vertex_positions": t_mesh})}

    refs, ref_noise, ref_seconds = {}, {}, {}
    for label, (scene, tan) in cases.items():
        t0 = time.perf_counter()
        halves = [limn.fd(scene, tan, eps=2e-2, spp=args.fd_spp // 2, seed=1000 + k) for k in range(2)]
        ref_seconds[label] = time.perf_counter() - t0
        refs[label] = 0.5 * (halves[0] + halves[1])
        ref_noise[label] = 0.5 * rel_rmse(halves[0], halves[1])  # the mean's error is half the halves' difference
        print(label, "reference noise", ref_noise[label], flush=True)

    rows = []
    methods = [("heightfield", "heightfield estimator", {}),
               ("mesh", "mesh pipeline, uniform boundary sampling", {"guiding": "none"}),
               ("mesh", "mesh pipeline, projective grid", {"guiding": "grid"})]
    for budget in [int(b) for b in args.budgets.split(",")]:
        for label, method, options in methods:
            scene, tan = cases[label]
            errs, secs = [], []
            for r in range(args.runs):
                t0 = time.perf_counter()
                img = scene.render_forward(tan, spp=budget, seed=100 * budget + r, **options)
                secs.append(time.perf_counter() - t0)
                errs.append(rel_rmse(img, refs[label]))
            rows.append(dict(method=method, spp=budget, seconds=float(np.median(secs)), error=float(np.mean(errs))))
            print(rows[-1], flush=True)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    for method in dict.fromkeys(r["method"] for r in rows):
        r = [x for x in rows if x["method"] == method]
        ax.loglog([x["seconds"] for x in r], [x["error"] for x in r], "o-", label=method)
    ax.set_xlabel("seconds per derivative image")
    ax.set_ylabel("relative RMSE against FD")
    ax.set_title(f"{args.scene}: heightfield estimator vs mesh pipeline")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, f"vs_mesh_{args.scene}.png"), dpi=110)

    def at(method, spp):
        return next(x for x in rows if x["method"] == method and x["spp"] == spp)

    lines = [f"# Heightfield estimator against the mesh pipeline ({args.scene})", "",
             f"Generated by `.venv/bin/python tests/bench/heightfield_vs_mesh.py --scene {args.scene}` on "
             f"{platform.node()} ({os.cpu_count()} cores); all rows from one run. Scene "
             f"`scenes/heightfield/{args.scene}.json` ({h.shape[1]}x{h.shape[0]} heights, "
             f"{hf_scene.width}x{hf_scene.height} film); the mesh is the same B-spline surface sampled at the "
             f"grid points ({h.size} vertices, {2 * (h.shape[0] - 1) * (h.shape[1] - 1)} triangles, smooth normals), "
             "moved by the same height change. Error: RMSE of the derivative image (4x4-pixel block means) against its own FD reference "
             f"({args.fd_spp} spp, eps 2e-2), divided by the reference's RMS; mean of {args.runs} runs; time: median. "
             "The mesh pipeline runs its interior, primary-visibility and indirect boundary terms at `spp` samples "
             "each; the heightfield estimator replaces all three with `spp` paths per pixel.", "",
             f"Reference noise (relative): heightfield {ref_noise['heightfield']:.3f}, mesh {ref_noise['mesh']:.3f}: "
             "errors near these values are the reference's, not the estimator's.", "",
             "| method | spp | seconds | relative error |", "|---|---|---|---|"]
    for x in rows:
        lines.append(f"| {x['method']} | {x['spp']} | {x['seconds']:.2f} | {x['error']:.3f} |")
    budgets = [int(b) for b in args.budgets.split(",")]
    lines += ["", "Equal samples (error of the mesh pipeline with uniform / projective guiding divided by the "
              "heightfield estimator's):", ""]
    for b in budgets:
        hf_e = at("heightfield estimator", b)["error"]
        lines.append(f"- {b} spp: {at('mesh pipeline, uniform boundary sampling', b)['error'] / hf_e:.1f}x / "
                     f"{at('mesh pipeline, projective grid', b)['error'] / hf_e:.1f}x")
    lines += ["", f"![error against time](vs_mesh_{args.scene}.png)"]
    path = os.path.join(args.out, f"vs_mesh_{args.scene}.md")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("wrote", path)


if __name__ == "__main__":
    main()
