"""limn against Mitsuba 3 (prb_projective, llvm_ad_rgb) on fibre curves (`bsplinecurve`, issue 36):
gradient error against run time for both renderers by the rules and with the machinery of
tests/bench/mitsuba_compare.py (the same budgets, a warm-up call per budget, interleaved timed
calls, >= 3 runs, one FD reference in two independent halves whose noise is stated, rows within 2x
of it marked capped), plus the checks that the two renderers see the same curve:

- both read the same control-point file (Mitsuba's format: x y z r per line); Mitsuba's
  `mi.traverse` control points are compared with limn's;
- the primal images at 1024 spp (relative RMS difference, against the two renderers' own noise);
- Mitsuba's own central difference of its primal (same seeds at theta +- eps, two halves) against
  limn's: if the scenes match, they differ by no more than their combined noise.

Scenes (scenes/curves/): fibre_env (a bent fibre, radius 0.08-0.2, 5 spans, seen directly in front
of a constant environment: primary silhouettes and rims), coil_reflection (the 3-turn coil of
curves_bench.sh, seen only in the GGX alpha 0.005 plane's reflection of a large emitter),
fibre_shadow (a thinner copy of the fibre over a floor under a small area light: its shadow and its
primary silhouettes). Parameter: x translation of all control points.

Where Mitsuba is wrong (mitsuba3 PR #1906: a u/v mismatch in the silhouette sampling, and a
Frenet-frame torsion using C''' that jumps at span joints): the derivative images at the largest
budget (mean over the runs) are compared with the reference per region: pixels where the tube near
an interior span joint is seen (directly, in the mirror, or as a shadow), pixels near the open ends,
and the rest; and the sum of each derivative image against the reference's.

Regenerate (the scenes can run side by side, `--scenes S` each; 35-55 min per scene at a load average of 25-34 on 2 cores):
    nice .venv/bin/python tests/bench/mitsuba_curves.py
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mitsuba_compare as mc  # noqa: E402  the shared measurement and report machinery

ROOT = mc.ROOT
SCENES = os.path.join(ROOT, "scenes", "curves")
WORK = os.path.join(tempfile.gettempdir(), "limn_mitsuba_curves")
ORDER = ["fibre_env", "coil_reflection", "fibre_shadow"]
FD_EPS = 5e-3
# Mitsuba's guidings per scene, chosen for the time limit: its octree costs 55-105 s per call on the
# 48 x 48 fibre_env (the guide build, fixed; its grid 10 s, none 3 s at 16 spp), and fibre_env's
# derivative is mostly primary (its octree guides only the tube's self-shadowing there).
MITSUBA_PLAN = {"fibre_env": ["grid"], "coil_reflection": ["octree", "grid"], "fibre_shadow": ["octree"]}


def load_desc(name: str) -> dict:
    with open(os.path.join(SCENES, name + ".json")) as f:
        return json.load(f)


def curve_id(desc: dict) -> str:
    (cid,) = [k for k, v in desc.items() if isinstance(v, dict) and v.get("type") == "bsplinecurve"]
    return cid


def curve_file(name: str, desc: dict) -> str:
    """The scene's control points in Mitsuba's text format (one 'x y z r' line each), read by both."""
    path = os.path.join(WORK, name + "_curve.txt")
    pts = desc[curve_id(desc)]["control_points"]
    with open(path, "w") as f:
        f.write("\n".join(" ".join(f"{x:.9g}" for x in p) for p in pts) + "\n")
    return path


def limn_desc(name: str) -> dict:
    """The scene with its curve read from the shared text file."""
    desc = load_desc(name)
    cid = curve_id(desc)
    path = curve_file(name, desc)
    desc[cid] = {k: v for k, v in desc[cid].items() if k != "control_points"}
    desc[cid]["filename"] = path
    return desc


def limn_scene(name: str):
    import limn
    desc = limn_desc(name)
    scene = limn.load_dict(desc, base_dir=SCENES)
    key = curve_id(desc) + ".control_points"
    t = np.zeros_like(scene.params[key])
    t[:, 0] = 1.0
    scene.set_differentiable([key])
    return desc, scene, {key: t}


def mitsuba_dict(mi, desc: dict, guiding: str) -> dict:
    out = {"type": "scene",
           "integrator": {"type": "prb_projective", "max_depth": desc["integrator"]["max_depth"], "guiding": guiding},
           "sensor": mc.mitsuba_sensor(mi, desc["sensor"])}
    for key, v in desc.items():
        if not isinstance(v, dict) or key in ("integrator", "sensor"):
            continue
        if v["type"] == "constant":
            out[key] = {"type": "constant", "radiance": {"type": "rgb", "value": [v["radiance"]] * 3}}
            continue
        m = {"type": v["type"]}
        if "bsdf" in v:
            m["bsdf"] = mc.bsdf(v["bsdf"])
        if v["type"] == "bsplinecurve":
            m["filename"] = v["filename"]
        elif v["type"] != "rectangle":
            raise ValueError(f"scene object '{key}': type '{v['type']}' has no Mitsuba translation here")
        if "to_world" in v:
            m["to_world"] = mc.transform(mi, v["to_world"])
        if "emitter" in v:
            m["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": [v["emitter"]["radiance"]] * 3}}
        out[key] = m
    return out


class CurvePeer(mc.MitsubaPeer):
    """One Mitsuba configuration: forward-mode derivative images along an x translation of all
    control points (Mitsuba's '<id>.control_points', flattened x y z r)."""

    def __init__(self, desc: dict, guiding: str):
        self.dr, self.mi = dr, mi = mc.import_mitsuba()
        self.scene = mi.load_dict(mitsuba_dict(mi, desc, guiding))
        self.params = mi.traverse(self.scene)
        self.key = curve_id(desc) + ".control_points"
        self.base = mi.Float(self.params[self.key])
        self.dir = dr.tile(mi.Float([1.0, 0.0, 0.0, 0.0]), dr.width(self.base) // 4)

    def control_points(self) -> np.ndarray:
        return np.array(self.base).reshape(-1, 4)

    def primal(self, spp: int, seed: int, theta: float = 0.0) -> np.ndarray:
        self.params[self.key] = self.moved(theta)
        self.params.update()
        img = np.array(self.mi.render(self.scene, spp=spp, seed=seed))[..., :3].astype(np.float64)
        self.params[self.key] = self.mi.Float(self.base)
        self.params.update()
        return img

    def fd(self, eps: float, spp: int, seed: int, chunk: int = 1024) -> np.ndarray:
        """Mitsuba's central difference of its primal, the same seed at +- eps, in chunks of spp."""
        acc, n = 0.0, 0
        for k in range(0, spp, chunk):
            s = min(chunk, spp - k)
            acc = acc + s * (self.primal(s, seed + k, eps) - self.primal(s, seed + k, -eps)) / (2 * eps)
            n += s
        return acc / n

    def moved(self, theta):
        return self.base + theta * self.dir


def worker(name: str, guiding: str, budgets: list[int], runs: int, with_limn: bool, with_mitsuba: bool) -> int:
    """One guiding, the renderers that run it interleaved; prints one JSON line and saves each
    renderer's mean derivative image at the largest budget."""
    # limn is not loaded for Mitsuba alone (two Embree copies in one process are not needed then)
    desc, scene, tangent = limn_scene(name) if with_limn else (limn_desc(name), None, None)
    ref = np.load(os.path.join(WORK, f"{name}_reference.npy"))
    rms = float(np.sqrt((ref ** 2).mean()))
    peer = CurvePeer(desc, guiding) if with_mitsuba else None
    out = {"guiding": guiding}
    top = {"limn": [], "mitsuba": []}

    def timed(who, fn, b):
        t0 = time.perf_counter()
        img = fn()
        s = time.perf_counter() - t0
        if not np.isfinite(img).all():  # counted and reported; the error is taken with them set to 0
            k = int((~np.isfinite(img)).sum())
            print(f"# {name} {guiding} {who} {b} spp: {k} non-finite pixel values", file=sys.stderr, flush=True)
            out.setdefault("nonfinite", []).append([who, b, k])
            img = np.nan_to_num(img, nan=0.0, posinf=0.0, neginf=0.0)
        if b == budgets[-1]:
            top[who].append(img)
        return s, float(np.sqrt(((img - ref) ** 2).mean()) / rms)

    def run_limn(b, seed):
        return timed("limn", lambda: scene.render_forward(tangent, spp=b, seed=seed, guiding=guiding).astype(np.float64), b)

    def run_mi(b, seed):
        return timed("mitsuba", lambda: peer.gradient(b, seed), b)

    mc.interleaved(out, run_limn if with_limn else None, run_mi if peer is not None else None, budgets, runs, f"{name} {guiding}")
    out["top_sums"] = {who: [float(i.sum()) for i in imgs[-runs:]] for who, imgs in top.items()}
    for who, imgs in top.items():
        if imgs:  # the warm-up call at the top budget is not among them: seeds 7, 107, ... only
            np.save(os.path.join(WORK, f"{name}_{guiding}_{who}_mean.npy"), np.mean(imgs[-runs:], axis=0))
    print("RESULT " + json.dumps(out), flush=True)
    return 0


# ---------------------------------------------------------------------------------------------------
# Regions of the image: where the tube near a span joint, near an end, is seen


def bspline(P: np.ndarray, s: int, t: float):
    """Uniform cubic B-spline span s (points s .. s+3) at t: point and radius."""
    b = np.array([(1 - t) ** 3, 3 * t ** 3 - 6 * t ** 2 + 4, -3 * t ** 3 + 3 * t ** 2 + 3 * t + 1, t ** 3]) / 6
    q = b @ P[s:s + 4]
    return q[:3], q[3]


def tube_points(P: np.ndarray, vs) -> np.ndarray:
    """Surface points of the tube at the global curve parameters vs (span + t), 24 around each."""
    out = []
    for v in vs:
        s = min(int(v), len(P) - 4)
        c, r = bspline(P, s, v - s)
        c2, _ = bspline(P, s, min(v - s + 1e-3, 1.0)) if v - s < 1.0 else bspline(P, s, v - s)
        c1, _ = bspline(P, s, max(v - s - 1e-3, 0.0))
        T = c2 - c1
        T /= np.linalg.norm(T)
        a = np.cross(T, [0.0, 0.0, 1.0] if abs(T[2]) < 0.9 else [1.0, 0.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(T, a)
        for u in np.linspace(0, 2 * np.pi, 24, endpoint=False):
            out.append(c + r * (np.cos(u) * a + np.sin(u) * b))
    return np.array(out)


def project(desc: dict, X: np.ndarray) -> np.ndarray:
    """Pixel (column, row) of world points for the scene's look_at camera (x fov = y fov: square film)."""
    la = desc["sensor"]["to_world"]["look_at"]
    o, tgt, up = (np.array(la[k], float) for k in ("origin", "target", "up"))
    d = (tgt - o) / np.linalg.norm(tgt - o)
    right = np.cross(d, up)
    right /= np.linalg.norm(right)
    upv = np.cross(right, d)
    q = X - o
    z = q @ d
    tan = np.tan(np.radians(desc["sensor"]["fov"]) / 2)
    W, H = desc["sensor"]["film"]["width"], desc["sensor"]["film"]["height"]
    col = ((q @ right) / (z * tan) + 1) / 2 * W
    row = (1 - (q @ upv) / (z * tan)) / 2 * H
    return np.stack([col, row], 1)[z > 0]


def seen_points(name: str, desc: dict, X: np.ndarray) -> np.ndarray:
    """Where tube points X show in this scene's image: directly, mirrored in the plane z = 0
    (coil_reflection: seen only there), their shadow on the floor z = 0 from the lamp's centre."""
    if name == "coil_reflection":
        return project(desc, X * np.array([1, 1, -1]))
    pix = [project(desc, X)]
    if "lamp" in desc:
        L = np.array(desc["lamp"]["to_world"][-1]["translate"], float)
        s = L[2] / (L[2] - X[:, 2])
        pix.append(project(desc, L + s[:, None] * (X - L)))
    return np.concatenate(pix)


def mask_of(desc: dict, pix: np.ndarray, grow: int = 1) -> np.ndarray:
    W, H = desc["sensor"]["film"]["width"], desc["sensor"]["film"]["height"]
    m = np.zeros((H, W), bool)
    for c, r in pix.astype(int):
        m[max(r - grow, 0):r + grow + 1, max(c - grow, 0):c + grow + 1] = True
    return m


def regions(name: str, desc: dict, P: np.ndarray) -> dict:
    """Boolean masks: 'joints' (the tube within 0.1 span of an interior joint), 'ends' (within 0.15
    span of an open end), 'rest' (everything else)."""
    S = len(P) - 3
    joint_v = [j + dv for j in range(1, S) for dv in np.linspace(-0.1, 0.1, 5)]
    end_v = list(np.linspace(0, 0.15, 4)) + list(S - np.linspace(0, 0.15, 4))
    joints = mask_of(desc, seen_points(name, desc, tube_points(P, joint_v)))
    ends = mask_of(desc, seen_points(name, desc, tube_points(P, end_v))) & ~joints
    return {"joints": joints, "ends": ends, "rest": ~(joints | ends)}


def region_stats(name: str, desc: dict, P: np.ndarray, ref: np.ndarray, a: np.ndarray, b: np.ndarray) -> dict:
    """Per region and renderer/guiding: relative RMSE of the mean derivative image at the top budget,
    its sum against the reference's, and the reference's own noise there."""
    R = regions(name, desc, P)
    out = {"pixels": {k: int(m.sum()) for k, m in R.items()}, "ref_sum": {}, "ref_noise": {}, "images": {}}
    for k, m in R.items():
        out["ref_sum"][k] = float(ref[m].sum())
        out["ref_noise"][k] = float(np.sqrt(((a - b)[m] ** 2).mean()) / 2 / max(np.sqrt((ref[m] ** 2).mean()), 1e-30))
    out["ref_sum"]["all"] = float(ref.sum())
    out["ref_sum"]["all_noise"] = float(abs(a.sum() - b.sum()) / 2)  # one draw of the mean's noise: rough
    for f in sorted(os.listdir(WORK)):
        if f.startswith(name + "_") and f.endswith("_mean.npy"):
            label = f[len(name) + 1:-9]
            img = np.load(os.path.join(WORK, f))
            e = {"sum": float(img.sum()), "scale": float((img * ref).sum() / (ref * ref).sum()),
                 "corr": float(np.corrcoef(img.ravel(), ref.ravel())[0, 1])}
            for k, m in R.items():
                e[k] = float(np.sqrt(((img - ref)[m] ** 2).mean()) / max(np.sqrt((ref[m] ** 2).mean()), 1e-30))
                e["sum_" + k] = float(img[m].sum())
            out["images"][label] = e
    return out


# ---------------------------------------------------------------------------------------------------
# Measuring


def measure_scene(name: str, args, mi) -> dict:
    import limn
    desc, scene, tangent = limn_scene(name)
    (key,) = tangent
    t0 = time.perf_counter()
    ref, noise, a, b = mc.reference_halves(scene, tangent, args.eps, args.fd_spp)
    print(f"{name}: reference in {time.perf_counter() - t0:.0f} s, its noise {noise:.4f}", flush=True)
    np.save(os.path.join(WORK, f"{name}_reference.npy"), ref)
    np.save(os.path.join(WORK, f"{name}_reference_halves.npy"), np.stack([a, b]))
    data = {"scene": name, "mitsuba_version": mi.__version__, "eps": args.eps, "fd_spp": args.fd_spp,
            "ref_noise": noise, "runs": args.runs, "budgets": args.budgets,
            "machine": f"{platform.node()} ({os.cpu_count()} cores)", "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "load": f"{os.getloadavg()[0]:.1f}", "configs": {}, "failures": [],
            "control_points": scene.params[key].tolist()}

    # The same curve in both: control points, primal images, each renderer's FD.
    peer = CurvePeer(desc, "octree")
    P = scene.params[key].astype(np.float64)
    data["control_points_max_diff"] = float(np.abs(peer.control_points() - P).max())
    pl = [scene.render(spp=512, seed=s).astype(np.float64) for s in (5, 6)]
    pm = [peer.primal(512, s) for s in (5, 6)]
    rel = lambda x, y, r: float(np.sqrt(((x - y) ** 2).mean()) / np.sqrt((r ** 2).mean()))
    primal_l, primal_m = 0.5 * (pl[0] + pl[1]), 0.5 * (pm[0] + pm[1])
    data["primal_ratio"] = float(primal_m.mean() / primal_l.mean())
    data["primal_diff"] = rel(primal_m, primal_l, primal_l)
    # Each 1024-spp mean's own noise from its two halves; their difference's noise is the sum in quadrature.
    data["primal_noise"] = float(np.hypot(rel(pl[0], pl[1], primal_l), rel(pm[0], pm[1], primal_l)) / 2)
    t0 = time.perf_counter()
    fa, fb = (peer.fd(args.eps, args.mi_fd_spp // 2, s) for s in (12345, 777))
    mfd = 0.5 * (fa + fb)
    data["mi_fd_time"] = time.perf_counter() - t0
    data["mi_fd_spp"] = args.mi_fd_spp
    data["mi_fd_noise"] = rel(fa, fb, ref) / 2
    data["mi_fd_diff"] = rel(mfd, ref, ref)
    data["mi_fd_sum"] = float(mfd.sum())
    np.save(os.path.join(WORK, f"{name}_primal.npy"), np.stack([primal_l, primal_m]))
    np.save(os.path.join(WORK, f"{name}_mifd.npy"), mfd)
    print(f"{name}: control points differ by {data['control_points_max_diff']:.2g}; primal diff {data['primal_diff']:.4f} "
          f"(noise {data['primal_noise']:.4f}); Mitsuba FD vs limn FD {data['mi_fd_diff']:.4f} "
          f"(noises {data['mi_fd_noise']:.4f}, {noise:.4f}; {data['mi_fd_time']:.0f} s)", flush=True)
    del peer

    mi_guidings = args.mitsuba_guidings if args.mitsuba_guidings is not None else MITSUBA_PLAN[name]
    data["limn_guidings"], data["mitsuba_guidings"] = args.limn_guidings, mi_guidings
    for guiding in [g for g in ("auto", "grid", "octree", "none") if g in args.limn_guidings or g in mi_guidings]:
        base = [sys.executable, os.path.abspath(__file__), "--worker", name, guiding, "--runs", str(args.runs),
                "--budgets", *map(str, args.budgets)] + ([] if guiding in args.limn_guidings else ["--no-limn"])
        if guiding not in mi_guidings:
            base.append("--no-mitsuba")
        r = mc.run_worker(base, guiding, data)
        if r is not None:
            data["configs"][guiding] = r
        with open(os.path.join(args.data_dir, name + ".json"), "w") as f:  # partial results survive
            json.dump(data, f, indent=1)
    return data


# ---------------------------------------------------------------------------------------------------
# The report


def figure(datas: dict, png: str, top: int):
    """Per scene: limn's primal, the FD reference, limn's and Mitsuba's (octree) mean derivative at the
    top budget, Mitsuba's FD; joints' and ends' pixels outlined."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    cols = ["primal (limn)", "FD reference (limn)", "limn auto", "Mitsuba", "Mitsuba - reference", "Mitsuba's own FD"]
    fig, axes = plt.subplots(len(datas), len(cols), figsize=(2.1 * len(cols), 2.3 * len(datas)), squeeze=False)
    for i, (n, d) in enumerate(datas.items()):
        ref = np.load(os.path.join(WORK, f"{n}_reference.npy"))
        v = np.abs(ref.mean(-1)).max() or 1.0
        desc = limn_desc(n)
        R = regions(n, desc, np.array(d["control_points"]))
        mi_g = next((g for g in ("octree", "grid", "none") if os.path.exists(os.path.join(WORK, f"{n}_{g}_mitsuba_mean.npy"))), None)
        mi_img = np.load(os.path.join(WORK, f"{n}_{mi_g}_mitsuba_mean.npy")) if mi_g else None
        for j, title in enumerate(cols):
            ax = axes[i][j]
            ax.set_xticks([])
            ax.set_yticks([])
            img = {"FD reference (limn)": ref, "Mitsuba": mi_img, "Mitsuba - reference": None if mi_img is None else mi_img - ref}.get(title)
            if title == "limn auto" and os.path.exists(os.path.join(WORK, f"{n}_auto_limn_mean.npy")):
                img = np.load(os.path.join(WORK, f"{n}_auto_limn_mean.npy"))
            if title == "Mitsuba's own FD":
                img = np.load(os.path.join(WORK, f"{n}_mifd.npy"))
            if title.startswith("Mitsuba") and mi_g and title != "Mitsuba's own FD":
                title = title.replace("Mitsuba", f"Mitsuba {mi_g}")
            if j == 0:
                pr = np.load(os.path.join(WORK, f"{n}_primal.npy"))[0]
                ax.imshow(np.clip(pr / max(pr.max(), 1e-9), 0, 1) ** (1 / 2.2))
            elif img is None:
                ax.set_title(f"{title}\n(not run)", fontsize=6)
                continue
            else:
                ax.imshow(img.mean(-1), cmap="RdBu_r", vmin=-v, vmax=v)
            ax.contour(R["joints"], levels=[0.5], colors="k", linewidths=0.4)
            ax.contour(R["ends"], levels=[0.5], colors="g", linewidths=0.4)
            ax.set_title(title, fontsize=6)
        axes[i][0].set_ylabel(n, fontsize=7)
    fig.suptitle(f"d image / d x (mean over runs at {top} spp; colour range = reference's max); black: near span joints, green: near ends",
                 fontsize=7)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def region_table(n: str, d: dict) -> list[str]:
    rs = d.get("regions")
    notes = [f"- {m}" for m in d.get("notes", [])]
    for g, c in d.get("configs", {}).items():
        for who, b, k in c.get("nonfinite", []):
            notes.append(f"- {'limn' if who == 'limn' else 'Mitsuba'} {g} at {b} spp: {k} NaN/Inf pixel values in one call "
                         "(set to 0 for the error)")
    notes += [""] if notes else []
    if not rs:
        return notes
    top = d["budgets"][-1]
    lines = [f"Derivative images at {top} spp, mean over the {d['runs']} runs, against the reference per region "
             "(relative RMSE in the region; sum of the derivative over the region; the whole image's sum). "
             "Regions: pixels where the tube within 0.1 span of an interior span joint is seen "
             + ("(in the mirror)" if n == "coil_reflection" else "(directly or as a shadow)" if "shadow" in n else "(directly)")
             + f"; within 0.15 span of an open end; the rest. Pixels: joints {rs['pixels']['joints']}, ends "
             f"{rs['pixels']['ends']}, rest {rs['pixels']['rest']}.", "",
             "| image | joints: rel. RMSE | ends: rel. RMSE | rest: rel. RMSE | sum joints | sum ends | sum rest | sum all | least-squares scale to the reference, correlation |",
             "|---|---|---|---|---|---|---|---|---|",
             f"| reference (its own noise) | ({rs['ref_noise']['joints']:.3f}) | ({rs['ref_noise']['ends']:.3f}) | "
             f"({rs['ref_noise']['rest']:.3f}) | {rs['ref_sum']['joints']:.3g} | {rs['ref_sum']['ends']:.3g} | "
             f"{rs['ref_sum']['rest']:.3g} | {rs['ref_sum']['all']:.3g} ± {rs['ref_sum'].get('all_noise', float('nan')):.2g} | 1, 1 |"]
    for label, e in sorted(rs["images"].items()):
        g, who = label.rsplit("_", 1)
        sums = d["configs"].get(g, {}).get("top_sums", {}).get(who, [])
        if len(sums) > 1:  # the mean image's sum with the standard error over the runs
            e["sum"] = f"{np.mean(sums):.3g} ± {np.std(sums, ddof=1) / np.sqrt(len(sums)):.2g}"
        name = f"limn {mc.LIMN_LABEL.get(g, g)}" if who == "limn" else f"Mitsuba {g}"
        lines.append(f"| {name} | {e['joints']:.3f} | {e['ends']:.3f} | {e['rest']:.3f} | {e['sum_joints']:.3g} | "
                     f"{e['sum_ends']:.3g} | {e['sum_rest']:.3g} | {e['sum'] if isinstance(e['sum'], str) else format(e['sum'], '.3g')} | "
                     f"{e['scale']:.3f}, {e['corr']:.3f} |")
    return notes + lines + [""]


def report(out_path: str, data_dir: str, command: str):
    names = sorted((f[:-5] for f in os.listdir(data_dir) if f.endswith(".json")),
                   key=lambda n: ORDER.index(n) if n in ORDER else 99)
    datas = {}
    for n in names:
        with open(os.path.join(data_dir, n + ".json")) as f:
            datas[n] = json.load(f)
    for n, d in datas.items():
        if os.path.exists(os.path.join(WORK, f"{n}_reference_halves.npy")):
            a, b = np.load(os.path.join(WORK, f"{n}_reference_halves.npy"))
            d["regions"] = region_stats(n, limn_desc(n), np.array(d["control_points"]), 0.5 * (a + b), a, b)
            with open(os.path.join(data_dir, n + ".json"), "w") as f:  # kept for --report-only without the images
                json.dump(d, f, indent=1)
    datas = {n: d for n, d in datas.items() if "mi_fd_diff" in d}
    any_d = next(iter(datas.values()))
    out_dir = os.path.dirname(out_path)
    lines = ["# limn and Mitsuba 3 on fibre curves (`bsplinecurve`)", "",
             f"Regenerate: `{command}` (`--scenes S` runs one scene: the three can run side by side; "
             "`--report-only` rewrites this page from mitsuba_data/ and the images left in " + WORK + "). "
             "Time per scene here: " + ", ".join(f"{n} {d['seconds'] / 60:.0f} min" for n, d in datas.items() if "seconds" in d)
             + " (with the machine's load below; on an idle machine a fraction of that).", "",
             f"Mitsuba {any_d['mitsuba_version']} (`llvm_ad_rgb`, `prb_projective`, forward mode) and limn on "
             f"{any_d['machine']}, {any_d['date']}, load average at the start of each scene "
             + ", ".join(f"{n} {d.get('load', '?')}" for n, d in datas.items()) + " on 2 cores shared with other engineers' builds and tests: absolute times are slower than an "
             "idle machine's; the interleaving puts both renderers under the same load. Measured as in "
             "[../projective/mitsuba.md](../projective/mitsuba.md) (tests/bench/mitsuba_compare.py, whose functions "
             "this script uses): the same budgets for both (spp for every term; Mitsuba's call spp sets sppc = sppp = "
             "sppi), a warm-up call per budget and guiding for Mitsuba, the timed calls interleaved, "
             f"{any_d['runs']} runs with the same seeds, median time and mean ± sd of the relative RMSE. "
             "limn `auto` is its default guiding (the projective grid below 256 boundary spp, the octree from "
             "there); Mitsuba has no counterpart, its default is `octree`.", "",
             f"Reference: limn's central difference (eps {any_d['eps']}), the mean of two independent halves of "
             f"{any_d['fd_spp'] // 2} spp; its own noise is stated per scene, rows within {mc.CAP:g}x of it are "
             "marked † (capped by the reference).", "",
             "Parameter: x translation of all control points (`<id>.control_points[:, 0]`; Mitsuba's "
             "`<id>.control_points` is exposed by `mi.traverse` as differentiable and discontinuous, a flat "
             "x y z r array). Radius derivatives were not measured.", "",
             "What Mitsuba gets wrong, the crashes and what was not run: [README.md](README.md#mitsuba-3-side-by-side) "
             "(written from these numbers).", "",
             "## Do both renderers see the same curve?", "",
             "Both read the same text file of control points (Mitsuba's format). Primal: both at 2 x 512 spp; "
             "the noise column is what two such renders differ by from noise alone. Mitsuba's FD: its own "
             f"primal at theta +- eps (eps as the reference's, the same seed at both ends), two halves of "
             "the stated spp; it should differ from limn's FD by no more than the two references' noise "
             "combined (sqrt of the sum of squares).", "",
             "| scene | control points: max abs difference | primal: Mitsuba / limn mean | primal: rel. RMS difference | its noise | Mitsuba FD vs limn FD: rel. RMS difference | noise: Mitsuba FD, limn FD (combined) | FD sums: Mitsuba, limn |",
             "|---|---|---|---|---|---|---|---|"]
    for n, d in datas.items():
        lines.append(f"| {n} | {d['control_points_max_diff']:.2g} | {d['primal_ratio']:.4f} | {d['primal_diff']:.4f} | "
                     f"{d['primal_noise']:.4f} | {d['mi_fd_diff']:.3f} | {d['mi_fd_noise']:.3f}, {d['ref_noise']:.3f} "
                     f"({np.hypot(d['mi_fd_noise'], d['ref_noise']):.3f}) | {d['mi_fd_sum']:.3g}, "
                     f"{d['regions']['ref_sum']['all'] if 'regions' in d else float('nan'):.3g} |")
    lines += [""]
    summary = ["## Equal-time comparison", "",
               "Mitsuba's error / limn's at equal time (as in ../projective/mitsuba.md: each renderer's "
               "(median time, mean error) points without those another of its points beats in both, joined in "
               "log-log, interpolated at the other's times, no extrapolation). Above 1: limn ahead. †: within "
               f"{mc.CAP:g}x of the reference's noise.", ""]
    body = []
    for n, d in datas.items():
        su, bo = mc.scene_section(n, d, out_dir, prefix="mitsuba_")
        summary += su
        body += bo + region_table(n, d)
    try:
        figure(datas, os.path.join(out_dir, "mitsuba_images.png"), any_d["budgets"][-1])
        body += ["## Derivative images", "", "![derivative images](mitsuba_images.png)", ""]
    except (ImportError, FileNotFoundError) as e:
        body += [f"(derivative images not drawn: {e})", ""]
    with open(out_path, "w") as f:
        f.write("\n".join(lines + summary + body) + "\n")
    print("wrote", out_path)


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="+", default=ORDER)
    ap.add_argument("--budgets", type=int, nargs="+", default=[16, 256], help="both renderers'")
    ap.add_argument("--limn-guidings", nargs="+", default=["auto", "grid"], choices=["auto", "octree", "grid", "none"])
    ap.add_argument("--mitsuba-guidings", nargs="+", choices=["octree", "grid", "none"],
                    help="for every scene (default: MITSUBA_PLAN, per scene)")
    ap.add_argument("--fd-spp", type=int, default=8192, help="limn's reference, both halves together")
    ap.add_argument("--mi-fd-spp", type=int, default=4096, help="Mitsuba's own FD, both halves together")
    ap.add_argument("--eps", type=float, default=FD_EPS)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "reports", "curves", "mitsuba.md"))
    ap.add_argument("--report-only", action="store_true")
    ap.add_argument("--worker", nargs=2, metavar=("SCENE", "GUIDING"), help=argparse.SUPPRESS)
    ap.add_argument("--no-mitsuba", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--no-limn", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--merge-worker", nargs=2, metavar=("SCENE", "OUTPUT"),
                    help="merge the RESULT line of a worker run by hand (--worker SCENE GUIDING ...) into SCENE's data")
    args = ap.parse_args()
    os.makedirs(WORK, exist_ok=True)
    if args.worker:
        return worker(args.worker[0], args.worker[1], args.budgets, args.runs, not args.no_limn, not args.no_mitsuba)
    if args.runs < 3:
        ap.error("--runs must be at least 3 (the project's measurement rules)")
    args.data_dir = os.path.join(os.path.dirname(args.out), "mitsuba_data")
    command = "nice .venv/bin/python tests/bench/mitsuba_curves.py " + " ".join(a for a in sys.argv[1:] if a != "--report-only")
    if args.merge_worker:
        name, output = args.merge_worker
        with open(output) as f:
            (r,) = [json.loads(l[l.index("RESULT ") + 7:]) for l in f if "RESULT " in l][-1:]
        path = os.path.join(args.data_dir, name + ".json")
        with open(path) as f:
            data = json.load(f)
        g = r["guiding"]
        data["failures"] = [m for m in data["failures"] if f"guiding '{g}'" not in m]
        old = data["configs"].get(g)
        if old is not None:  # the renderers this run did not run keep their rows
            for key in ("runs", "warmup", "top_sums"):
                for w in ("limn", "mitsuba"):
                    if not r.get(key, {}).get(w) and old.get(key, {}).get(w):
                        r.setdefault(key, {})[w] = old[key][w]
            r["nonfinite"] = old.get("nonfinite", []) + r.get("nonfinite", [])
        data["configs"][g] = r
        data.setdefault("notes", []).append(
            f"guiding '{g}' ({', '.join(w for w in ('limn', 'mitsuba') if r['runs'][w])}) ran in a separate worker process "
            "at the same time as the other renderer's calls (not interleaved with them), for time (same code: --worker)")
        with open(path, "w") as f:
            json.dump(data, f, indent=1)
        print("merged", g, "into", path)
        return 0
    if args.report_only:
        report(args.out, args.data_dir, command.strip())
        return 0
    _, mi = mc.import_mitsuba()
    os.makedirs(args.data_dir, exist_ok=True)
    warnings.simplefilter("ignore")
    for name in args.scenes:
        t0 = time.perf_counter()
        d = measure_scene(name, args, mi)
        d["seconds"] = time.perf_counter() - t0
        with open(os.path.join(args.data_dir, name + ".json"), "w") as f:
            json.dump(d, f, indent=1)
        print(f"{name}: done in {d['seconds']:.0f} s", flush=True)
        report(args.out, args.data_dir, command.strip())
    return 0


if __name__ == "__main__":
    sys.exit(main())
