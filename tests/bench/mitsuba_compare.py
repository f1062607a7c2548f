"""limn against Mitsuba 3 (prb_projective, llvm_ad_rgb) on the projective-sampling test scenes:
gradient error against run time for both renderers, measured by the project's rules (issue 36):

- the same budgets (spp) for both renderers: Mitsuba's cost per call is mostly its guide build, so
  it gains most at high spp;
- a warm-up call per budget and per configuration for Mitsuba (Dr.Jit compiles kernels per call
  shape); limn has no JIT, one warm-up call per configuration;
- the two renderers' timed calls interleaved in one process, the same budget back to back
  (A B, B A, A B, ...: the order alternates so neither always runs second);
- ``--runs`` (>= 3) runs per row, different seeds, the same seeds for both renderers;
- one finite-difference reference (limn, eps 5e-3, ``--fd-spp`` in all) made of two independent
  halves (seeds 12345 and 777, cached): the reference is their mean and its own noise
  RMS(a - b) / 2 (the mean of two independent estimates has a quarter of the variance of their
  difference); errors within 2x of it are flagged as capped by the reference.

Wall-clock times of the whole call (limn: guide set-up included; Mitsuba: its guide build,
forward-mode propagation and the transfer of the image included). The primal images are compared
first so that the reference means the same for both. Mitsuba is a comparison peer for this report
only, never a dependency. Results per scene go to <out dir>/mitsuba_data/<scene>.json; the
report is written from every scene file there (``--report-only`` rewrites it without measuring).

Regenerate (after ./bootstrap.sh):
    .venv/bin/pip install mitsuba==3.7.1 && nice .venv/bin/python tests/bench/mitsuba_compare.py

Mitsuba 3.7.1 (Dr.Jit 1.2.0): 3.9 emits an LLVM intrinsic (fminimum) that Debian 12's
LLVM 14/15 cannot compile for x86 ("LLVM ERROR: Cannot select"), and 3.5-3.6 fail to compile
prb_projective on meshes ("use of undefined value"); llvm_ad_rgb uses the system LLVM.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
import warnings

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENES = os.path.join(ROOT, "scenes", "projective")
WORK = os.path.join(tempfile.gettempdir(), "limn_mitsuba_compare")  # reference and primal handed to the workers
GUIDINGS = ("none", "grid", "octree", "auto")  # "auto": limn's default, no Mitsuba counterpart
LIMN_LABEL = {"none": "none", "grid": "projective grid", "octree": "octree", "auto": "auto (default)"}
CAP = 2.0  # an error within CAP x the reference's noise is flagged: the reference's noise is >= 1/4 of its square


def import_mitsuba():
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError:
        sys.exit("Mitsuba 3 is not installed: .venv/bin/pip install mitsuba==3.7.1")
    mi.set_variant("llvm_ad_rgb")
    return dr, mi


def transform(mi, spec):
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


def mitsuba_sensor(mi, s: dict) -> dict:
    """limn's perspective sensor as Mitsuba's (box filter, as limn's pixels)."""
    return {"type": "perspective", "fov": s["fov"], "to_world": transform(mi, s["to_world"]),
            "film": {"type": "hdrfilm", "width": s["film"]["width"], "height": s["film"]["height"],
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": 4}}


def mitsuba_scene(mi, desc: dict, guiding: str) -> dict:
    # sppc/sppp/sppi unset: each call's spp sets all three (Mitsuba's override_spp).
    out = {"type": "scene",
           "integrator": {"type": "prb_projective", "max_depth": desc["integrator"]["max_depth"], "guiding": guiding},
           "sensor": mitsuba_sensor(mi, desc["sensor"])}
    for key in ("plane", "emitter", "shape"):
        sh = desc[key]
        m = {"type": sh["type"], "bsdf": bsdf(sh["bsdf"])}
        if sh["type"] == "sphere":
            m.update(center=sh["center"], radius=sh["radius"])
        elif sh["type"] == "ply":
            m.update(filename=os.path.join(SCENES, sh["filename"]), face_normals=sh.get("face_normals", False))
        if "to_world" in sh:
            m["to_world"] = transform(mi, sh["to_world"])
        if "emitter" in sh:
            m["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": [sh["emitter"]["radiance"]] * 3}}
        out[key] = m
    return out


class MitsubaPeer:
    """One Mitsuba configuration: forward-mode derivative images along an x translation of the shape."""

    def __init__(self, desc: dict, guiding: str):
        self.dr, self.mi = dr, mi = import_mitsuba()
        self.scene = mi.load_dict(mitsuba_scene(mi, desc, guiding))
        self.params = mi.traverse(self.scene)
        self.sphere = desc["shape"]["type"] == "sphere"
        self.key = "shape.to_world" if self.sphere else "shape.vertex_positions"
        self.base = type(self.params[self.key])(self.params[self.key])

    def primal(self, spp: int, seed: int) -> np.ndarray:
        self.params[self.key] = type(self.base)(self.base)
        self.params.update()
        return np.array(self.mi.render(self.scene, spp=spp, seed=seed))[..., :3].astype(np.float64)

    def moved(self, theta):
        """The shape's parameter translated by theta along x."""
        mi, dr = self.mi, self.dr
        if self.sphere:
            return mi.Transform4f().translate(mi.Vector3f(theta, 0.0, 0.0)) @ self.base
        return self.base + theta * dr.tile(mi.Float([1.0, 0.0, 0.0]), dr.width(self.base) // 3)

    def gradient(self, spp: int, seed: int) -> np.ndarray:
        dr, mi = self.dr, self.mi
        theta = mi.Float(0.0)
        dr.enable_grad(theta)
        self.params[self.key] = self.moved(theta)
        self.params.update()
        dr.forward(theta, dr.ADFlag.ClearEdges)
        image = mi.render(self.scene, self.params, spp=spp, seed=seed)
        dr.forward_to(image)
        g = dr.grad(image)
        dr.eval(g)
        return np.array(g)[..., :3].astype(np.float64)


def limn_scene(name: str):
    import limn
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
    return desc, scene, {param: t}


def interleaved(out: dict, run_limn, run_mi, budgets: list[int], runs: int, tag: str) -> None:
    """The timed calls by the project's rules: limn's warm-up once, Mitsuba's once per budget (Dr.Jit
    compiles per call shape), then ``runs`` runs per budget with seeds 7, 107, 207 ..., the two
    renderers back to back in alternating order. run_limn / run_mi(budget, seed) -> (seconds, error);
    either None: the other alone. Fills out["runs"] and out["warmup"]."""
    out.setdefault("runs", {"limn": {}, "mitsuba": {}})
    out.setdefault("warmup", {"limn": {}, "mitsuba": {}})
    if run_limn is not None:
        out["warmup"]["limn"][str(budgets[0])] = run_limn(budgets[0], 999)[0]
    for b in budgets:
        if run_mi is not None:
            out["warmup"]["mitsuba"][str(b)] = run_mi(b, 999)[0]  # compiles this budget's kernels
        L, M = [], []
        for r in range(runs):
            seed = 7 + 100 * r
            order = (("limn", "mitsuba") if r % 2 == 0 else ("mitsuba", "limn"))
            for who in order:
                if who == "limn" and run_limn is not None:
                    L.append(run_limn(b, seed))
                elif who == "mitsuba" and run_mi is not None:
                    M.append(run_mi(b, seed))
        if run_limn is not None:
            out["runs"]["limn"][str(b)] = L
        if run_mi is not None:
            out["runs"]["mitsuba"][str(b)] = M
        print(f"# {tag} {b} spp: limn {L}, mitsuba {M}", file=sys.stderr, flush=True)


def reference_halves(scene, tangent: dict, eps: float, fd_spp: int):
    """limn's central difference in two independent halves of fd_spp / 2 each (seeds 12345 and 777,
    cached by limn.fd): their mean, its own relative noise RMS(a - b) / 2 / RMS(mean) (the mean of
    two independent estimates has a quarter of the variance of their difference), and the halves."""
    import limn
    a, b = (limn.fd(scene, tangent, eps=eps, spp=fd_spp // 2, seed=s).astype(np.float64) for s in (12345, 777))
    ref = 0.5 * (a + b)
    noise = float(np.sqrt(((a - b) ** 2).mean())) / 2.0 / float(np.sqrt((ref ** 2).mean()))
    return ref, noise, a, b


def worker(name: str, guiding: str, budgets: list[int], runs: int, with_mitsuba: bool, primal: bool) -> int:
    """One guiding for both renderers, interleaved; prints one JSON line."""
    desc, scene, tangent = limn_scene(name)
    ref = np.load(os.path.join(WORK, f"{name}_reference.npy"))
    rms = float(np.sqrt((ref ** 2).mean()))
    out = {"guiding": guiding}
    peer = MitsubaPeer(desc, guiding) if with_mitsuba else None
    if peer is not None and primal:  # the primal check once per scene
        primal_limn = np.load(os.path.join(WORK, f"{name}_primal.npy"))
        primal_mi = peer.primal(1024, 5)
        out["primal_ratio"] = float(primal_mi.mean() / primal_limn.mean())
        out["primal_diff"] = float(np.sqrt(((primal_mi - primal_limn) ** 2).mean()) / np.sqrt((primal_limn ** 2).mean()))

    def run_limn(b, seed):
        t0 = time.perf_counter()
        img = scene.render_forward(tangent, spp=b, seed=seed, guiding=guiding)
        s = time.perf_counter() - t0
        return s, float(np.sqrt(((img.astype(np.float64) - ref) ** 2).mean()) / rms)

    def run_mi(b, seed):
        t0 = time.perf_counter()
        g = peer.gradient(b, seed)
        s = time.perf_counter() - t0
        return s, float(np.sqrt(((g - ref) ** 2).mean()) / rms)

    interleaved(out, run_limn, run_mi if peer is not None else None, budgets, runs, f"{name} {guiding}")
    print("RESULT " + json.dumps(out), flush=True)
    return 0


# ---------------------------------------------------------------------------------------------------
# The report


def rows_of(data: dict):
    """(renderer, guiding, budget, median seconds, mean error, sd of error, [runs]) per row."""
    rows = []
    for renderer in ("mitsuba", "limn"):
        for g in GUIDINGS:
            if g not in data["configs"]:
                continue
            for b, runs in data["configs"][g]["runs"][renderer].items():
                if not runs:
                    continue
                secs = [r[0] for r in runs]
                errs = [r[1] for r in runs]
                rows.append((renderer, g, int(b), float(np.median(secs)), float(np.mean(errs)),
                             float(np.std(errs, ddof=1)) if len(errs) > 1 else float("nan"), runs))
    return rows


def interp_loglog(pts, t):
    """Error at time t on the polyline through pts (sorted by time), in log-log; None outside."""
    pts = sorted(pts)
    if not pts or t < pts[0][0] or t > pts[-1][0]:
        return None
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if t0 <= t <= t1:
            if t1 == t0:
                return min(e0, e1)
            w = (math.log(t) - math.log(t0)) / (math.log(t1) - math.log(t0))
            return math.exp((1 - w) * math.log(e0) + w * math.log(e1))
    return pts[-1][1] if t == pts[-1][0] else None


def pareto(pts):
    """The points no other point beats in both time and error: under a shared machine's load a larger
    budget can take less time than a smaller one (Mitsuba's octree, whose guide build dominates);
    the slower and worse point is dropped, so each renderer is compared at its best."""
    out = []
    for t, e in sorted(pts):
        if not out or e < out[-1][1]:
            out.append((t, e))
    return out


def best_at(curves: dict, t):
    """The lowest error any of a renderer's configurations reaches at time t (interpolated), and which."""
    best = None
    for g, pts in curves.items():
        e = interp_loglog(pts, t)
        if e is not None and (best is None or e < best[0]):
            best = (e, g)
    return best


def equal_time(rows, floor):
    """Per guiding and for each renderer's best configuration: ratios Mitsuba error / limn error at
    equal time, each renderer's points interpolated at the other's times (log-log, no extrapolation)."""
    curves = {r: {g: [(x[3], x[4]) for x in rows if x[0] == r and x[1] == g] for g in GUIDINGS} for r in ("limn", "mitsuba")}
    curves = {r: {g: pareto(p) for g, p in c.items() if p} for r, c in curves.items()}
    out = []
    for g in GUIDINGS:
        if g not in curves["limn"] or g not in curves["mitsuba"]:
            continue
        ratios = []
        for t, e in curves["limn"][g]:
            em = interp_loglog(curves["mitsuba"][g], t)
            if em is not None:
                ratios.append((t, em / e, e < CAP * floor or em < CAP * floor))
        for t, em in curves["mitsuba"][g]:
            e = interp_loglog(curves["limn"][g], t)
            if e is not None:
                ratios.append((t, em / e, e < CAP * floor or em < CAP * floor))
        out.append((f"{g} (both)", sorted(ratios) or disjoint(curves["limn"][g], curves["mitsuba"][g], floor)))
    ratios = []
    for t in sorted({p[0] for c in curves.values() for pts in c.values() for p in pts}):
        bl, bm = best_at(curves["limn"], t), best_at(curves["mitsuba"], t)
        if bl and bm:
            ratios.append((t, bm[0] / bl[0], bl[0] < CAP * floor or bm[0] < CAP * floor, bl[1], bm[1]))
    out.append(("best of each", ratios))
    return out


def disjoint(limn_pts, mi_pts, floor):
    """Time ranges that do not overlap: the faster renderer's slowest point against the slower one's
    fastest. If the faster one also has the lower error there, it is ahead at the slower one's time
    by at least that ratio (its error does not grow with more time); otherwise nothing follows."""
    fl, sl = max(limn_pts), min(mi_pts)
    fm, sm = max(mi_pts), min(limn_pts)
    if fl[0] < sl[0] and fl[1] < sl[1]:
        return [(sl[0], sl[1] / fl[1], fl[1] < CAP * floor, "bound")]
    if fm[0] < sm[0] and fm[1] < sm[1]:
        return [(sm[0], fm[1] / sm[1], fm[1] < CAP * floor, "bound")]
    return []


def fmt_ratio(x):
    return f"{x:.2g}x" if x < 10 else f"{x:.0f}x"


def summarize(ratios):
    if not ratios:
        return "no overlapping times"
    if ratios[0][3:] == ("bound",):
        t, x, capped = ratios[0][:3]
        who = "limn" if x > 1 else "Mitsuba"
        return (f"no overlapping times; {who} is faster and more accurate: at {t:.2g} s, the other's fastest time, "
                f"{who} is ahead by at least {fmt_ratio(max(x, 1 / x))} (its slowest point against the other's fastest; "
                "more time does not raise its error)" + (f" (capped by the reference: within {CAP:g}x of its noise)" if capped else ""))
    lo, hi = min(r[1] for r in ratios), max(r[1] for r in ratios)
    ahead = "limn ahead" if lo > 1 else ("Mitsuba ahead" if hi < 1 else "mixed")
    capped = sum(1 for r in ratios if r[2])
    if len(ratios) == 1:
        s = f"{ahead}: Mitsuba's error / limn's {fmt_ratio(lo)} at {ratios[0][0]:.2g} s (the only shared time)"
    else:
        s = (f"{ahead}: Mitsuba's error / limn's {fmt_ratio(lo)} to {fmt_ratio(hi)} over "
             f"{ratios[0][0]:.2g}-{ratios[-1][0]:.2g} s ({len(ratios)} times)")
    if capped:
        s += f"; {capped} of them with an error within {CAP:g}x of the reference's noise (capped: the true ratio is further from 1)"
    return s


def plot(name, rows, floor, png):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4.2))
    colors = {"none": "tab:gray", "grid": "tab:blue", "octree": "tab:red", "auto": "tab:green"}
    for renderer, style in (("limn", "o-"), ("mitsuba", "s--")):
        for g in GUIDINGS:
            pts = sorted((x[3], x[4], x[5], x[2]) for x in rows if x[0] == renderer and x[1] == g)
            if not pts:
                continue
            label = f"limn {LIMN_LABEL[g]}" if renderer == "limn" else f"Mitsuba {g}"
            ax.errorbar([p[0] for p in pts], [p[1] for p in pts], yerr=[0 if math.isnan(p[2]) else p[2] for p in pts],
                        fmt=style, color=colors[g], mfc="none" if renderer == "mitsuba" else colors[g], ms=5,
                        capsize=2, label=label)
            for p in pts:
                ax.annotate(str(p[3]), (p[0], p[1]), fontsize=5, xytext=(2, 2), textcoords="offset points")
    ax.axhline(floor, color="k", lw=0.8, ls=":", label="reference's own noise")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("seconds per derivative image (median of runs)")
    ax.set_ylabel("relative RMSE vs FD (mean of runs)")
    ax.set_title(f"{name}: limn (filled) and Mitsuba 3.7.1 (open); labels: spp")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def scene_section(n: str, d: dict, out_dir: str, prefix: str = "mitsuba_"):
    """One scene's equal-time summary lines and its table + plot (<out_dir>/<prefix><n>.png)."""
    summary, body = [], []
    floor = d["ref_noise"]
    rows = rows_of(d)
    body += [f"## {n}", ""]
    if "primal_ratio" in d:
        body += [f"Primal images at 1024 spp: Mitsuba / limn mean {d['primal_ratio']:.4f}, relative RMS "
                 f"difference {d['primal_diff']:.4f}. Reference's own relative noise: **{floor:.4f}**.", ""]
    else:
        body += [f"Reference's own relative noise: **{floor:.4f}**.", ""]
    body += [f"- {f}" for f in d.get("failures", [])] + ([""] if d.get("failures") else [])
    body += ["| renderer | guiding | budget (spp) | median time (s) | relative RMSE (mean ± sd) | runs: time (s) / error |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        mark = " †" if r[4] < CAP * floor else ""
        runs = ", ".join(f"{s:.2f}/{e:.3f}" for s, e in r[6])
        g = LIMN_LABEL[r[1]] if r[0] == "limn" else r[1]
        body.append(f"| {'limn' if r[0] == 'limn' else 'Mitsuba'} | {g} | {r[2]} | {r[3]:.3f} | "
                    f"{r[4]:.4f} ± {r[5]:.4f}{mark} | {runs} |")
    body.append("")
    png = f"{prefix}{n}.png"
    try:
        plot(n, rows, floor, os.path.join(out_dir, png))
        body += [f"![{n}]({png})", ""]
    except ImportError:
        pass
    summary += [f"**{n}** (reference noise {floor:.4f}):", ""]
    for label, ratios in equal_time(rows, floor):
        summary.append(f"- {label}: {summarize(ratios)}.")
        if label == "best of each" and ratios:
            summary.append("  " + "; ".join(f"{t:.2g} s: {fmt_ratio(x)}{' †' if c else ''} ({LIMN_LABEL[gl]} / {gm})"
                                             for t, x, c, gl, gm in ratios) + ".")
    summary.append("")
    return summary, body


def report(out_path: str, data_dir: str, command: str):
    names = sorted(f[:-5] for f in os.listdir(data_dir) if f.endswith(".json"))
    order = ["sphere", "torus", "cube_hole", "bunny"]
    names.sort(key=lambda n: order.index(n) if n in order else 99)
    datas = {}
    for n in names:
        with open(os.path.join(data_dir, n + ".json")) as f:
            datas[n] = json.load(f)
    any_d = next(iter(datas.values()))
    lines = ["# limn and Mitsuba 3 on the projective-sampling test scenes", "",
             f"Regenerate: `{command}` "
             "(Mitsuba 3.7.1: 3.9 needs a newer LLVM than Debian 12's, 3.5-3.6 fail on meshes; "
             "`--report-only` rewrites this page from mitsuba_data/ without measuring).", "",
             f"Mitsuba {any_d['mitsuba_version']} (`llvm_ad_rgb`, integrator `prb_projective`, forward mode) and limn "
             f"on {any_d['machine']}, {any_d['date']}. Each guiding runs both renderers in one process, their timed "
             "calls interleaved, the same budget back to back (A B, B A, A B: the order alternates). "
             "Budget: samples per pixel for every term, the same for both (Mitsuba: the call's spp sets sppc = sppp = sppi; "
             "limn: spp sets the interior, primary and indirect boundary counts). Mitsuba gets a warm-up call "
             "per budget and guiding before its timed calls (Dr.Jit compiles per call); limn one per guiding. "
             f"Times: wall clock of the whole call, median over {any_d['runs']} runs (seeds 7, 107, 207 ..., "
             "the same for both); limn's include its guide set-up, Mitsuba's its guide build and forward-mode "
             "propagation. Relative RMSE: RMSE against the reference / RMS of the reference, mean ± standard "
             "deviation over the runs. The machine was shared with other jobs (load average "
             f"{any_d.get('load', '?')} at the start on 2 cores): absolute times are slower than an idle machine's; "
             "the interleaving puts both renderers under the same load.", "",
             f"Reference: limn's central finite difference (eps {any_d['eps']}), the mean of two independent halves "
             f"of {any_d['fd_spp'] // 2} spp each (seeds 12345 and 777). Its own noise, stated per scene, is RMS(half A - "
             "half B) / 2 relative to the reference's RMS (the mean of two independent estimates has a quarter of the "
             "variance of their difference). Measured errors include it "
             f"(error^2 = true error^2 + noise^2): rows marked † are within {CAP:g}x of it, their true error is lower "
             "than shown and the comparison there is capped by the reference. The eps bias of the reference is not "
             "in this floor (docs/reports/projective/reference.md: about 0.009 on the sphere).", ""]
    summary = ["## Equal-time comparison", "",
               "Mitsuba's error / limn's at equal time: each renderer's (median time, mean error) points, without those "
               "another of its points beats in both, joined in log-log and interpolated at the other's measured times "
               "(no extrapolation). Above 1: limn ahead. †: an error within 2x of the reference's noise (limn's, in "
               "every such case here), so the true ratio is larger.", ""]
    body = []
    for n, d in datas.items():
        su, bo = scene_section(n, d, os.path.dirname(out_path))
        summary += su
        body += bo
    with open(out_path, "w") as f:
        f.write("\n".join(lines + summary + body) + "\n")
    print("wrote", out_path)


def run_worker(base: list[str], guiding: str, data: dict):
    """Runs a worker process (a Dr.Jit compiler failure aborts it); on failure again with --no-mitsuba
    (limn alone), the failure noted in data["failures"]. Its RESULT dict, or None."""
    for cmd in (base, base + ["--no-mitsuba"]):
        res = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=None, text=True)
        out = [l[l.index("RESULT ") + 7:] for l in res.stdout.splitlines() if "RESULT " in l]
        if res.returncode == 0 and out:
            return json.loads(out[-1])
        err = [l for l in res.stdout.splitlines() if "error" in l.lower() or "failure" in l.lower()]
        data["failures"].append(f"Mitsuba with guiding '{guiding}' failed (exit {res.returncode}): "
                                f"{(err or ['no output'])[0].strip()[:200]}; limn alone")
    return None


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="+", default=["sphere", "torus", "bunny"])
    ap.add_argument("--budgets", type=int, nargs="+", default=[4, 16, 64, 256, 1024], help="both renderers'")
    ap.add_argument("--guidings", nargs="+", default=["octree", "grid"], choices=GUIDINGS,
                    help="'none' (no guide for the indirect term) is the baseline of neither renderer's best")
    ap.add_argument("--fd-spp", type=int, default=32768, help="the reference's, both halves together")
    ap.add_argument("--eps", type=float, default=5e-3, help="the reference's, as in the bench reports")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "reports", "projective", "mitsuba.md"))
    ap.add_argument("--report-only", action="store_true")
    ap.add_argument("--worker", nargs=2, metavar=("SCENE", "GUIDING"), help=argparse.SUPPRESS)
    ap.add_argument("--no-mitsuba", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--primal", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        return worker(args.worker[0], args.worker[1], args.budgets, args.runs, not args.no_mitsuba, args.primal)
    if args.runs < 3:
        ap.error("--runs must be at least 3 (the project's measurement rules)")
    data_dir = os.path.join(os.path.dirname(args.out), "mitsuba_data")
    command = "nice .venv/bin/python tests/bench/mitsuba_compare.py " + " ".join(sys.argv[1:])
    if args.report_only:
        report(args.out, data_dir, command.replace(" --report-only", ""))
        return 0
    import limn
    _, mi = import_mitsuba()
    os.makedirs(WORK, exist_ok=True)
    os.makedirs(data_dir, exist_ok=True)
    warnings.simplefilter("ignore")
    for name in args.scenes:
        desc, scene, tangent = limn_scene(name)
        t0 = time.perf_counter()
        ref, noise, _, _ = reference_halves(scene, tangent, args.eps, args.fd_spp)
        print(f"{name}: references in {time.perf_counter() - t0:.0f} s, reference noise {noise:.4f}", flush=True)
        np.save(os.path.join(WORK, f"{name}_reference.npy"), ref)
        np.save(os.path.join(WORK, f"{name}_primal.npy"), scene.render(spp=1024, seed=5).astype(np.float64))
        data = {"scene": name, "mitsuba_version": mi.__version__, "eps": args.eps, "fd_spp": args.fd_spp,
                "ref_noise": noise, "runs": args.runs, "budgets": args.budgets,
                "machine": f"{platform.node()} ({os.cpu_count()} cores)", "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                "load": f"{os.getloadavg()[0]:.0f}", "configs": {}, "failures": []}
        for guiding in args.guidings:
            base = [sys.executable, os.path.abspath(__file__), "--worker", name, guiding, "--runs", str(args.runs),
                    "--budgets", *map(str, args.budgets)] + (["--primal"] if "primal_ratio" not in data else [])
            # Each guiding in a process of its own: a Dr.Jit compiler failure aborts it; limn alone then.
            r = run_worker(base, guiding, data)
            if r is not None:
                for k in ("primal_ratio", "primal_diff"):
                    if k in r:
                        data[k] = r[k]
                data["configs"][guiding] = r
            with open(os.path.join(data_dir, name + ".json"), "w") as f:  # partial results survive an interruption
                json.dump(data, f, indent=1)
        with open(os.path.join(data_dir, name + ".json"), "w") as f:
            json.dump(data, f, indent=1)
        print(f"{name}: done", flush=True)
        report(args.out, data_dir, command)
    return 0


if __name__ == "__main__":
    sys.exit(main())
