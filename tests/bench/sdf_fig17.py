"""The projective-sampling paper's Figure 17 for `sdfgrid` (issue 37): the perimeter and interior
parts of Eq. 4 separately and summed, against central differences, for

  (a) an SDF in front of the paper's reflection test scene (scenes/projective/make.py `base`: a
      GGX alpha = 0.005 conductor plane before a large emitter; the SDF is seen only in the
      reflection, so the derivative image is the indirect boundary term alone), and
  (b) the SDF casting a shadow (tests/python/test_sdfgrid.py `shadow_scene`, point light; the
      camera sees only the floor),

on 64^3 and 128^3 grids, with the tangent of the report's sections 1 and 1b.

Called by tests/bench/sdf_report.py (sections 5 and 6); writes docs/reports/sdf/fig17_*.png.
"""
from __future__ import annotations

import importlib.util
import os
import sys
import time
import warnings

import numpy as np

import limn

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "tests", "python"))
from test_derivatives import block_z, projection_z  # noqa: E402
from test_sdfgrid import ball, shadow_scene  # noqa: E402


def _projective_make():
    """scenes/projective/make.py, the paper's test scene builder (imported, not copied)."""
    spec = importlib.util.spec_from_file_location("projective_make", os.path.join(ROOT, "scenes", "projective", "make.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def quiet(fn, *a, **k):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*a, **k)


# The bumpy ball (radius 0.35 of the unit cube) scaled to the paper's sphere (radius 0.25) at its
# place in the reflection scene.
REFLECTION_PLACE = [{"translate": [-0.5, -0.5, -0.5]}, {"scale": 0.25 / 0.35}, {"rotate": {"axis": [0, 0, 1], "angle": 20}},
                    {"translate": [0.05, 1.0, 1.2]}]


def reflection_scene(n, size=32):
    d = _projective_make().base({"type": "sdfgrid", "data": ball(n), "to_world": REFLECTION_PLACE,
                                 "bsdf": {"type": "diffuse", "reflectance": 0.1}})
    d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = size
    # Zoomed onto the reflection (the shape's centre mirrored in the plane z = 0), so that the
    # derivative covers most of the film rather than 8 x 8 of the builder's 48 x 48 pixels.
    d["sensor"]["to_world"]["look_at"]["target"] = [0.05, 1.0, -1.2]
    d["sensor"]["fov"] = 14
    return limn.load_dict(d), "shape.data"


def shadow(n):
    return shadow_scene("point", n), "blob.data"


def tangent(scene, name, seed=3):
    """Sections 1 and 1b's tangent: -1 + 0.5 N(0, 1) per grid value (the shape grows, unevenly). An x
    translation (-df/dx) would do too, but its image sums to about zero (left and right edges cancel),
    which leaves the sums below nothing to say."""
    rng = np.random.default_rng(seed)
    return (-1.0 + 0.5 * rng.standard_normal(scene.params[name].shape)).astype(np.float32)


# Per scene: sample counts. The reflection is near-specular: uniform sampling of the boundary
# sample space is hopeless there (tests/python/test_indirect_boundary.py), so the projective grid.
SETTINGS = {
    "reflection": dict(make=reflection_scene, eps=2e-3, fd_spp=512, kw=dict(spp=16, spp_boundary=256, guiding="grid", guiding_seeds=128, guide_refresh=0)),
    "shadow": dict(make=shadow, eps=2e-3, fd_spp=1024, kw=dict(spp=64, spp_boundary=128)),
}


def blocks(s, block=4):
    n, h, w, c = s.shape
    return s.reshape(n, h // block, block, w // block, block, c).mean(axis=(2, 4))


def run_case(kind, n, seeds, out_dir):
    """FD reference, the perimeter and interior parts alone, their sum, the whole term switched off;
    returns a dict of the measured numbers and writes the side-by-side image."""
    cfg = SETTINGS[kind]
    scene, name = cfg["make"](n)
    scene.set_differentiable([name])
    t = tangent(scene, name)
    t0 = time.time()
    fd = np.stack([limn.fd(scene, {name: t}, eps=cfg["eps"], spp=cfg["fd_spp"], seed=k, cache=False) for k in range(seeds)])
    t_fd = (time.time() - t0) / seeds
    part, t_part = {}, {}
    for p in ("perimeter", "interior"):
        t0 = time.time()
        part[p] = np.stack([quiet(scene.render_forward, {name: t}, boundary_parts=p, seed=50 + k, **cfg["kw"]) for k in range(seeds)])
        t_part[p] = (time.time() - t0) / seeds
    summary = next((l for l in scene.last_stats["summary"] if l.startswith("indirect boundary")), "")
    # The interior part from seeds no tested run uses: the weights of projection_z, which sums the
    # blocks along that part's image (a part a few per cent of the image is below any single block's
    # noise, but shifts this projection by |part|^2 summed over all blocks it touches).
    weights = np.stack([quiet(scene.render_forward, {name: t}, boundary_parts="interior", seed=500 + k, **cfg["kw"])
                        for k in range(max(seeds // 2, 2))])
    kw_off = dict(cfg["kw"], spp_boundary=0)
    for k in ("guiding", "guiding_seeds", "guide_refresh"):
        kw_off.pop(k, None)
    off = np.stack([quiet(scene.render_forward, {name: t}, seed=50 + k, **kw_off) for k in range(seeds)])
    total = part["perimeter"] + part["interior"]
    sums = lambda a: a.sum(axis=(1, 2, 3))  # noqa: E731
    se = lambda a: sums(a).std(ddof=1) / np.sqrt(len(a))  # noqa: E731
    z = {"sum": block_z(total, fd), "perimeter alone (interior off)": block_z(part["perimeter"], fd),
         "interior alone (perimeter off)": block_z(part["interior"], fd), "both off": block_z(off, fd)}
    # The FD reference's own noise: its per-block standard error against the tested estimate's. Where
    # the FD's dominates, |z| says as much about the reference as about limn (FD-capped).
    se_fd = blocks(fd).std(0, ddof=1) / np.sqrt(seeds)
    se_on = blocks(total).std(0, ddof=1) / np.sqrt(seeds)
    signal = np.abs(blocks(fd).mean(0))
    live = signal > 2 * se_fd  # blocks where FD sees the derivative
    res = dict(kind=kind, n=n, seeds=seeds, fd=fd, part=part, total=total, z=z,
               fd_sum=sums(fd).mean(), fd_se=se(fd), sum=sums(total).mean(), sum_se=se(total),
               per=sums(part["perimeter"]).mean(), per_se=se(part["perimeter"]),
               inn=sums(part["interior"]).mean(), inn_se=se(part["interior"]),
               fd_rel_noise=float(np.sqrt((se_fd ** 2).mean()) / np.sqrt((blocks(fd).mean(0) ** 2).mean())),
               se_ratio=float(np.median(se_fd[live] / np.maximum(se_on[live], 1e-30))) if live.any() else float("nan"),
               live=int(live.sum()), nblocks=int(live.size),
               t_fd=t_fd, t_per=t_part["perimeter"], t_inn=t_part["interior"],
               summary=summary,
               pz={"sum": projection_z(total, fd, weights), "perimeter alone (interior off)": projection_z(part["perimeter"], fd, weights)})
    save_image(res, os.path.join(out_dir, f"fig17_{kind}_{n}.png"))
    return res


def save_image(res, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    imgs = [("FD", res["fd"].mean(0)), ("limn: perimeter + interior", res["total"].mean(0)),
            ("perimeter part", res["part"]["perimeter"].mean(0)), ("interior part", res["part"]["interior"].mean(0))]
    lum = [im.mean(-1) for _, im in imgs]
    vmax = max(np.percentile(np.abs(lum[0]), 99.5), np.percentile(np.abs(lum[1]), 99.5), 1e-12)
    fig, axes = plt.subplots(1, 4, figsize=(12, 3.3))
    for ax, (title, _), im in zip(axes, imgs, lum):
        h = ax.imshow(im, cmap="coolwarm", vmin=-vmax, vmax=vmax, interpolation="nearest")
        ax.set_title(title, fontsize=10)
        ax.set_xticks([]), ax.set_yticks([])
    fig.colorbar(h, ax=axes, shrink=0.8)
    fig.suptitle(f"{res['kind']}, {res['n']}^3 sdfgrid: derivative image (mean over RGB, {res['seeds']} seeds)", fontsize=10)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def section(lines, kind, sizes, seeds, out_dir, title, scene_text):
    cfg = SETTINGS[kind]
    kw = ", ".join(f"{k} {v}" for k, v in cfg["kw"].items())
    lines += [title, "", scene_text, "",
              f"Tangent: -1 + 0.5 N(0, 1) per grid value (the shape grows, unevenly). Reference: central differences, "
              f"eps {cfg['eps']}, {cfg['fd_spp']} spp per seed; limn: {kw}, `boundary_parts` perimeter and interior in "
              f"separate calls (same seeds), {seeds} seeds each. Block (4 x 4 px) z-scores against FD; `both off`: "
              "spp_boundary = 0 (the derivative image is then zero: no other term sees the motion).", ""]
    results = []
    for n in sizes:
        r = run_case(kind, n, seeds, out_dir)
        results.append(r)
        print(kind, n, {k: float(np.abs(v).max()) for k, v in r["z"].items()}, flush=True)
    lines += ["| grid | sum FD +- s.e. | perimeter +- s.e. | interior +- s.e. | perimeter + interior +- s.e. | time FD / perimeter / interior per seed (s) |",
              "|---|---|---|---|---|---|"]
    for r in results:
        lines.append(f"| {r['n']}^3 | {r['fd_sum']:.3f} +- {r['fd_se']:.3f} | {r['per']:.3f} +- {r['per_se']:.3f} | "
                     f"{r['inn']:.3f} +- {r['inn_se']:.3f} | {r['sum']:.3f} +- {r['sum_se']:.3f} | "
                     f"{r['t_fd']:.1f} / {r['t_per']:.1f} / {r['t_inn']:.1f} |")
    lines += ["", "Block z-scores (max |z| over the blocks, and the number of blocks with |z| > 3 of all blocks; for a",
              "correct estimate about 0.3 % of the blocks FD sees, i.e. 0-1 here, if the noise were Gaussian and its",
              "s.e. known). `projected`: one z for the whole image, forward and FD projected onto the interior part's",
              f"mean image from {max(seeds // 2, 2)} further seeds (test_derivatives.projection_z): the test that sees a part of a",
              "few per cent.", "",
              "| grid | perimeter + interior | perimeter alone (interior off) | interior alone (perimeter off) | both off | "
              "projected z: sum / perimeter alone | FD noise: block s.e. RMS / FD RMS | FD s.e. / limn s.e. (median over blocks FD sees) |",
              "|---|---|---|---|---|---|---|---|"]
    for r in results:
        cells = [f"{np.abs(z).max():.2f} ({int((np.abs(z) > 3).sum())}/{z.size})" for z in r["z"].values()]
        pz = " / ".join(f"{v:.2f}" for v in r["pz"].values())
        lines.append(f"| {r['n']}^3 | " + " | ".join(cells) + f" | {pz} | {r['fd_rel_noise']:.3f} | {r['se_ratio']:.2f} ({r['live']} blocks) |")
    lines.append("")
    for r in results:
        lines.append(f"![{kind} {r['n']}^3: FD, limn, perimeter, interior](fig17_{kind}_{r['n']}.png)")
    lines += ["", f"Summary of the interior-part call ({results[-1]['n']}^3): `{results[-1]['summary']}`", ""]
    return results
