"""Heightfield estimator against the mesh pipeline on the same surface, in one run: gradient error
against run time at several sample budgets. The mesh is the heightfield's B-spline surface sampled
at the grid points (smooth vertex normals); its tangent is the same height change pushed through
the same sampling, so both describe one motion. Each renderer is compared with its own central
finite-difference reference (the two surfaces differ by the triangulation), high-sample, split in
two halves to estimate the reference's own noise.

With --mitsuba, Mitsuba 3 (prb_projective, llvm_ad_rgb; the peer of the heightfield paper's
7.7x claim) renders the same mesh in the same run, against the mesh's reference. Mitsuba is a
comparison peer for this report only, never a dependency.

Regenerate (after ./bootstrap.sh):
    .venv/bin/python tests/bench/heightfield_vs_mesh.py --scene cone     # writes docs/reports/heightfield/vs_mesh_cone.md
    .venv/bin/pip install mitsuba==3.7.1 && .venv/bin/python tests/bench/heightfield_vs_mesh.py --scene cone --mitsuba
"""
from __future__ import annotations

import argparse
import copy
import importlib.util
import json
import os
import platform
import subprocess
import sys
import tempfile
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


def write_ply(path: str, v: np.ndarray, f: np.ndarray) -> None:
    """Binary PLY of a triangle mesh (Mitsuba computes smooth vertex normals for it)."""
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\nproperty float x\nproperty float y\n"
              f"property float z\nelement face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    faces = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"], faces["i"] = 3, f
    with open(path, "wb") as out:
        out.write(header.encode())
        out.write(np.ascontiguousarray(v, "<f4").tobytes())
        out.write(faces.tobytes())


# Mitsuba's integrators on the mesh. prb_reparam (Loubet et al. 2019), which the paper's 2023
# comparison probably used, is no longer in Mitsuba 3.7 (and 3.5-3.6 fail on meshes).
MITSUBA_CONFIGS = {
    "Mitsuba 3 prb_projective, guiding none": {"type": "prb_projective", "guiding": "none"},
    "Mitsuba 3 prb_projective, guiding octree": {"type": "prb_projective", "guiding": "octree"},
}


def mitsuba_worker(work: str, config: str, budgets: list[int], runs: int) -> None:
    """Mitsuba 3 on the mesh in work/ (scene.json, mesh.ply, tangent.npy, reference.npy,
    primal.npy): prints one JSON line {"ratio", "diff", "rows"}."""
    spec = importlib.util.spec_from_file_location("mitsuba_compare", os.path.join(ROOT, "tests", "bench", "mitsuba_compare.py"))
    mc = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mc)  # sets the llvm_ad_rgb variant
    mi, dr = mc.mi, mc.dr
    with open(os.path.join(work, "scene.json")) as fh:
        d = json.load(fh)
    s = d["sensor"]
    desc = {"type": "scene",
            "integrator": MITSUBA_CONFIGS[config] | {"max_depth": d["integrator"]["max_depth"]},
            "sensor": {"type": "perspective", "fov": s["fov"], "to_world": mc.transform(s["to_world"]),
                       "film": {"type": "hdrfilm", "width": s["film"]["width"], "height": s["film"]["height"],
                                "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                       "sampler": {"type": "independent", "sample_count": 4}},
            "terrain": {"type": "ply", "filename": os.path.join(work, "mesh.ply"), "face_normals": False,
                        "bsdf": mc.bsdf(d["terrain"]["bsdf"])},
            "light": {"type": "rectangle", "to_world": mc.transform(d["light"]["to_world"]),
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [d["light"]["emitter"]["radiance"]] * 3}}},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [d["sky"]["radiance"]] * 3}}}
    scene = mi.load_dict(desc)
    params = mi.traverse(scene)
    key = "terrain.vertex_positions"
    base = type(params[key])(params[key])
    tangent = mi.Float(np.load(os.path.join(work, "tangent.npy")).ravel())
    ref = np.load(os.path.join(work, "reference.npy"))
    primal_limn = np.load(os.path.join(work, "primal.npy"))
    primal = np.array(mi.render(scene, spp=1024, seed=5))[..., :3].astype(np.float64)

    def gradient(spp: int, seed: int):
        return mc.mitsuba_gradient(scene, params, key, lambda theta: base + theta * tangent, spp, seed)

    # Mitsuba's own central difference (same eps as limn's reference): how far the two renderers'
    # surfaces differ in their derivative, whatever the estimator.
    fd_images = []
    for sign in (1.0, -1.0):
        params[key] = base + sign * 2e-2 * tangent
        params.update()
        fd_images.append(np.array(mi.render(scene, params, spp=8192, seed=11))[..., :3].astype(np.float64))
    own_fd = (fd_images[0] - fd_images[1]) / 4e-2
    rows = []
    for b in budgets:
        gradient(b, 999)  # JIT compilation for this budget (a new kernel per spp), not timed
        errs, secs = [], []
        for r in range(runs):
            g, sec = gradient(b, 100 * b + r)
            errs.append(rel_rmse(g, ref))
            secs.append(sec)
        rows.append(dict(method=config, spp=b, seconds=float(np.median(secs)),
                         error=float(np.mean(errs))))
    print(json.dumps({"ratio": float(primal.mean() / primal_limn.mean()), "fd_error": rel_rmse(own_fd, ref),
                      "diff": float(np.sqrt(((primal - primal_limn) ** 2).mean() / (primal_limn ** 2).mean())),
                      "rows": rows}), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="cone", choices=["cone", "terrain"])
    ap.add_argument("--budgets", default="4,16,64,256")
    ap.add_argument("--fd-spp", type=int, default=65536)
    ap.add_argument("--runs", type=int, default=8, help="independent runs per budget (errors averaged)")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "reports", "heightfield"))
    ap.add_argument("--mitsuba", action="store_true", help="add Mitsuba 3 (prb_projective) on the mesh, in the same run")
    ap.add_argument("--mitsuba-worker", nargs=2, metavar=("WORK", "CONFIG"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    budgets = [int(b) for b in args.budgets.split(",")]
    if args.mitsuba_worker:
        return mitsuba_worker(args.mitsuba_worker[0], args.mitsuba_worker[1], budgets, args.runs)
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
    mesh_desc = mesh_of(d)
    mesh_scene = limn.load_dict(mesh_desc)
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

    mitsuba_lines = []
    if args.mitsuba:
        work = tempfile.mkdtemp(prefix="limn_hf_mitsuba_")
        write_ply(os.path.join(work, "mesh.ply"), mesh_desc["terrain"]["vertex_positions"], mesh_desc["terrain"]["faces"])
        np.save(os.path.join(work, "tangent.npy"), t_mesh)
        np.save(os.path.join(work, "reference.npy"), refs["mesh"])
        np.save(os.path.join(work, "primal.npy"), mesh_scene.render(spp=1024, seed=5).astype(np.float64))
        with open(os.path.join(work, "scene.json"), "w") as fh:
            json.dump({k: v for k, v in d.items() if k != "terrain"} | {"terrain": {"bsdf": d["terrain"]["bsdf"]}}, fh)
        for config in MITSUBA_CONFIGS:
            # A process per configuration: a Dr.Jit compiler failure aborts it, not this run.
            res = subprocess.run([sys.executable, os.path.abspath(__file__), "--mitsuba-worker", work, config,
                                  "--budgets", args.budgets, "--runs", str(args.runs)], capture_output=True, text=True)
            out = [l[l.index('{"ratio"'):] for l in res.stdout.splitlines() if '{"ratio"' in l]
            if res.returncode != 0 or not out:
                raise SystemExit(f"{config} failed (exit {res.returncode}): {res.stderr[-500:]}")
            r = json.loads(out[-1])
            rows += r["rows"]
            for x in r["rows"]:
                print(x, flush=True)
            if not mitsuba_lines:
                import mitsuba
                mitsuba_lines = [f"Mitsuba {mitsuba.__version__} (`llvm_ad_rgb`, `prb_projective`, forward mode, box filter; "
                                 "times exclude its first call per budget, which compiles) renders the mesh (a PLY of the same vertices; "
                                 "Mitsuba computes its own smooth normals) against the mesh's reference. Primal images at "
                                 f"1024 spp: Mitsuba / limn mean {r['ratio']:.4f}, relative RMS difference {r['diff']:.4f}. Mitsuba's "
                                 f"own central difference (8192 spp, eps 2e-2) differs from limn's mesh reference by "
                                 f"{r['fd_error']:.3f} (relative, as the errors below): below that, Mitsuba's rows measure the "
                                 "two surfaces' difference, not its estimator.", ""]

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
             f"Generated by `.venv/bin/python tests/bench/heightfield_vs_mesh.py --scene {args.scene}"
             f"{' --mitsuba' if args.mitsuba else ''}` on "
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
             *mitsuba_lines,
             "| method | spp | seconds | relative error |", "|---|---|---|---|"]
    for x in rows:
        lines.append(f"| {x['method']} | {x['spp']} | {x['seconds']:.2f} | {x['error']:.3f} |")
    others = [m for m in dict.fromkeys(x["method"] for x in rows) if m != "heightfield estimator"]
    lines += ["", "Equal samples: each method's error divided by the heightfield estimator's, as RMSE ratio / MSE "
              "ratio (the paper's App. A1 compares mean squared errors: 7.7x lower than Mitsuba 3 at 16 spp):", "",
              "| spp | " + " | ".join(others) + " |", "|---|" + "---|" * len(others)]
    for b in budgets:
        hf_e = at("heightfield estimator", b)["error"]
        lines.append(f"| {b} | " + " | ".join(f"{at(m, b)['error'] / hf_e:.1f}x / {(at(m, b)['error'] / hf_e) ** 2:.1f}x"
                                               for m in others) + " |")
    lines += ["", f"![error against time](vs_mesh_{args.scene}.png)"]
    path = os.path.join(args.out, f"vs_mesh_{args.scene}.md")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("wrote", path)


if __name__ == "__main__":
    main()
