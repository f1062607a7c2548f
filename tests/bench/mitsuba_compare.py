"""limn against Mitsuba 3 (prb_projective, llvm_ad_rgb) on the projective-sampling test scenes, in one
run on this machine: gradient error against run time for both renderers against one finite-
difference reference (limn's, cached; the primal images are compared first so that the reference
means the same for both). Mitsuba is a comparison peer for this report only, never a dependency.

Regenerate (after ./bootstrap.sh):
    .venv/bin/pip install mitsuba==3.7.1 && .venv/bin/python tests/bench/mitsuba_compare.py

Mitsuba 3.7.1 (Dr.Jit 1.2.0): 3.9 emits an LLVM intrinsic (fminimum) that Debian 12's
LLVM 14/15 cannot compile for x86 ("LLVM ERROR: Cannot select"), and 3.5-3.6 fail to compile
prb_projective on meshes ("use of undefined value"); llvm_ad_rgb uses the system LLVM.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import limn

try:
    import drjit as dr
    import mitsuba as mi
except ImportError:
    sys.exit("Mitsuba 3 is not installed: .venv/bin/pip install mitsuba")
mi.set_variant("llvm_ad_rgb")

SCENES = os.path.join(ROOT, "scenes", "projective")
WORK = os.path.join(tempfile.gettempdir(), "limn_mitsuba_compare")  # reference and primal handed to the workers


def transform(spec) -> mi.ScalarTransform4f:
    """A limn/Mitsuba-dictionary to_world (list of scale/rotate/translate/look_at steps)."""
    T = mi.ScalarTransform4f()
    for step in spec if isinstance(spec, list) else [spec]:
        (kind, v), = step.items()
        if kind == "scale":
            T = mi.ScalarTransform4f().scale(v if isinstance(v, list) else [v, v, v]) @ T
        elif kind == "rotate":
            T = mi.ScalarTransform4f().rotate(v["axis"], v["angle"]) @ T
        elif kind == "translate":
            T = mi.ScalarTransform4f().translate(v) @ T
        elif kind == "look_at":
            T = mi.ScalarTransform4f().look_at(origin=v["origin"], target=v["target"], up=v["up"]) @ T
        else:
            raise ValueError(f"transform step '{kind}'")
    return T


def bsdf(d: dict) -> dict:
    if d["type"] == "diffuse":
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": [d["reflectance"]] * 3}}
    if d["type"] == "roughconductor":
        return {"type": "roughconductor", "distribution": d["distribution"], "alpha": d["alpha"]}
    raise ValueError(d["type"])


def mitsuba_scene(desc: dict, guiding: str, spp: int) -> dict:
    s = desc["sensor"]
    out = {"type": "scene",
           "integrator": {"type": "prb_projective", "max_depth": desc["integrator"]["max_depth"], "guiding": guiding,
                          "sppc": spp, "sppp": spp, "sppi": spp},
           "sensor": {"type": "perspective", "fov": s["fov"], "to_world": transform(s["to_world"]),
                      "film": {"type": "hdrfilm", "width": s["film"]["width"], "height": s["film"]["height"],
                               "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                      "sampler": {"type": "independent", "sample_count": spp}}}
    for key in ("plane", "emitter", "shape"):
        sh = desc[key]
        m = {"type": sh["type"], "bsdf": bsdf(sh["bsdf"])}
        if sh["type"] == "sphere":
            m.update(center=sh["center"], radius=sh["radius"])
        elif sh["type"] == "ply":
            m.update(filename=os.path.join(SCENES, sh["filename"]), face_normals=sh.get("face_normals", False))
        if "to_world" in sh:
            m["to_world"] = transform(sh["to_world"])
        if "emitter" in sh:
            m["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": [sh["emitter"]["radiance"]] * 3}}
        out[key] = m
    return out


def mitsuba_gradient(scene, params, key, moved, spp, seed):
    """Forward-mode derivative image along theta, where params[key] = moved(theta), and the seconds it took."""
    theta = mi.Float(0.0)
    dr.enable_grad(theta)
    params[key] = moved(theta)
    params.update()
    dr.forward(theta, dr.ADFlag.ClearEdges)
    t0 = time.perf_counter()
    image = mi.render(scene, params, spp=spp, seed=seed)
    dr.forward_to(image)
    g = dr.grad(image)
    dr.eval(g)
    out = np.array(g)
    seconds = time.perf_counter() - t0
    return out[..., :3].astype(np.float64), seconds


def translation_x(kind, base):
    """moved(theta) for a translation along +x of a sphere's to_world or of mesh vertices."""
    if kind == "sphere":
        return lambda theta: mi.Transform4f().translate(mi.Vector3f(theta, 0.0, 0.0)) @ base
    shift = dr.tile(mi.Float([1.0, 0.0, 0.0]), dr.width(base) // 3)
    return lambda theta: base + theta * shift


def worker(name: str, guiding: str, budgets: list[int], runs: int) -> int:
    """One Mitsuba configuration: prints {"ratio", "diff", "rows"} as JSON."""
    with open(os.path.join(SCENES, name + ".json")) as f:
        desc = json.load(f)
    ref = np.load(os.path.join(WORK, "reference.npy"))
    primal_limn = np.load(os.path.join(WORK, "primal.npy"))
    rms = float(np.sqrt((ref ** 2).mean()))
    msc = mi.load_dict(mitsuba_scene(desc, guiding, 4))
    params = mi.traverse(msc)
    kind = "sphere" if desc["shape"]["type"] == "sphere" else "mesh"
    key = "shape.to_world" if kind == "sphere" else "shape.vertex_positions"
    base = type(params[key])(params[key])
    primal_mi = np.array(mi.render(msc, spp=1024, seed=5))[..., :3].astype(np.float64)
    ratio = float(primal_mi.mean() / primal_limn.mean())
    diff = float(np.sqrt(((primal_mi - primal_limn) ** 2).mean()) / np.sqrt((primal_limn ** 2).mean()))
    mitsuba_gradient(msc, params, key, translation_x(kind, base), 4, 999)  # JIT warm-up
    rows = []
    for b in budgets:
        errs, secs = [], []
        for r in range(runs):
            g, s = mitsuba_gradient(msc, params, key, translation_x(kind, base), b, 7 + 100 * r)
            errs.append(((g - ref) ** 2).mean())
            secs.append(s)
        rows.append((f"Mitsuba {guiding}", b, float(np.mean(secs)), float(np.sqrt(np.mean(errs))) / rms))
    print(json.dumps({"ratio": ratio, "diff": diff, "rows": rows}), flush=True)
    return 0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="+", default=["sphere", "torus", "cube_hole", "bunny"])
    ap.add_argument("--budgets", type=int, nargs="+", default=[4, 16, 64], help="Mitsuba's budgets")
    ap.add_argument("--limn-budgets", type=int, nargs="+", default=[4, 16, 64, 256, 1024],
                    help="limn's (larger: limn is faster per sample, the comparison is at equal time)")
    ap.add_argument("--fd-spp", type=int, default=131072, help="the reference's, as in the bench reports")
    ap.add_argument("--eps", type=float, default=5e-3, help="the reference's, as in the bench reports")
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "reports", "projective", "mitsuba.md"))
    ap.add_argument("--worker", nargs=2, metavar=("SCENE", "GUIDING"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        return worker(args.worker[0], args.worker[1], args.budgets, args.runs)
    os.makedirs(WORK, exist_ok=True)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    warnings.simplefilter("ignore")
    lines = ["# limn and Mitsuba 3 on the projective-sampling test scenes", "",
             "Regenerate: `.venv/bin/pip install mitsuba==3.7.1 && .venv/bin/python tests/bench/mitsuba_compare.py` "
             "(3.7.1: 3.9 needs a newer LLVM than Debian 12's, 3.5-3.6 fail on meshes)", "",
             f"Mitsuba {mi.__version__} (`llvm_ad_rgb`, integrator `prb_projective`, forward mode) and limn on the same "
             "machine in one run (2 cores, shared); one finite-difference reference per scene (limn, eps "
             f"{args.eps}, {args.fd_spp} spp, cached: the bench reports' own); relative RMSE = RMSE / RMS of the reference, root mean square over "
             f"{args.runs} runs with different seeds. Budget: samples per pixel for every term (Mitsuba: sppc = sppp = sppi). "
             "Mitsuba's times exclude its first call per configuration (JIT compilation) and include its guiding; "
             "limn's include its guide set-up.", ""]
    for name in args.scenes:
        path = os.path.join(SCENES, name + ".json")
        with open(path) as f:
            desc = json.load(f)
        scene = limn.load(path)
        param = "shape.center" if desc["shape"]["type"] == "sphere" else "shape.vertex_positions"
        t = np.zeros_like(scene.params[param])
        if t.ndim == 2:
            t[:, 0] = 1.0
        else:
            t[0] = 1.0
        scene.set_differentiable([param])
        ref = limn.fd(scene, {param: t}, eps=args.eps, spp=args.fd_spp, seed=12345).astype(np.float64)
        rms = float(np.sqrt((ref ** 2).mean()))
        rows = []
        primal_limn = scene.render(spp=1024, seed=5).astype(np.float64)
        np.save(os.path.join(WORK, "reference.npy"), ref)
        np.save(os.path.join(WORK, "primal.npy"), primal_limn)
        ratio = diff = float("nan")
        failures = []
        for guiding in ("none", "grid", "octree"):
            # Each Mitsuba configuration in a process of its own: a Dr.Jit compiler failure aborts it.
            cmd = [sys.executable, os.path.abspath(__file__), "--worker", name, guiding, "--runs", str(args.runs),
                   "--budgets", *map(str, args.budgets)]
            res = subprocess.run(cmd, capture_output=True, text=True)
            out = [l[l.index('{"ratio"'):] for l in res.stdout.splitlines() if '{"ratio"' in l]  # after Mitsuba's colour codes
            if res.returncode != 0 or not out:
                err = [l for l in (res.stdout + res.stderr).splitlines() if "error" in l.lower() or "failure" in l.lower()]
                failures.append(f"Mitsuba with guiding '{guiding}' failed (exit {res.returncode}): {(err or ['no output'])[0].strip()[:200]}")
                continue
            r = json.loads(out[-1])
            if guiding == "none":
                ratio, diff = r["ratio"], r["diff"]
            rows += [tuple(x) for x in r["rows"]]
        for label, opts in (("limn none", {"guiding": "none"}), ("limn projective grid", {"guiding": "grid"}),
                            ("limn octree", {"guiding": "octree"})):
            for b in args.limn_budgets:
                errs, secs = [], []
                for r in range(args.runs):
                    img = scene.render_forward({param: t}, spp=b, seed=7 + 100 * r, **opts)
                    errs.append(((img - ref) ** 2).mean())
                    secs.append(scene.last_stats["seconds"])
                rows.append((label, b, float(np.mean(secs)), float(np.sqrt(np.mean(errs))) / rms))
        lines += [f"## {name}", "",
                  f"Primal images at 1024 spp: Mitsuba / limn mean {ratio:.4f}, relative RMS difference {diff:.4f}.", ""]
        lines += [f"- {f}" for f in failures] + ([""] if failures else [])
        lines += [
                  "| renderer, guiding | budget (spp) | time (s) | relative RMSE |", "|---|---|---|---|"]
        lines += [f"| {r[0]} | {r[1]} | {r[2]:.3f} | {r[3]:.4f} |" for r in rows]
        lines.append("")
        try:
            import matplotlib
            matplotlib.use("Agg")
            import matplotlib.pyplot as plt
            fig, ax = plt.subplots(figsize=(5.5, 3.8))
            for label in dict.fromkeys(r[0] for r in rows):
                pts = [(r[2], r[3]) for r in rows if r[0] == label]
                ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-" if label.startswith("limn") else "s--", label=label)
            ax.set_xlabel("seconds per derivative image")
            ax.set_ylabel("relative RMSE vs FD")
            ax.set_title(f"{name}: limn and Mitsuba 3")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=7)
            fig.tight_layout()
            png = f"mitsuba_{name}.png"
            fig.savefig(os.path.join(os.path.dirname(args.out), png), dpi=110)
            plt.close(fig)
            lines += [f"![{name}]({png})", ""]
        except ImportError:
            pass
        print(f"{name}: done", flush=True)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("wrote", args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
