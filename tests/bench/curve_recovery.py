"""Recover a small hair tuft (fibre curves with varying radius) from 3 views (issue 36, "an
optimisation": a hair or wire shape recovered from 2-3 views, loss and geometric error against time).

The target: 4 bent curves of 6 control points each, rooted on a small patch, radius tapering from
root to tip, rendered by limn at 64x64 from 3 cameras around it under a uniform environment light
(the curves diffuse, darker than the sky). The start: the same roots and point counts, straight
vertical curves of the same heights, one constant radius. Optimised with limn.optim.fit (Adam on
all three views together, a multi-resolution L2 loss):

- Large Steps along each curve: limn.optim.curve_faces gives LargeSteps the path Laplacian of each
  curve (no edge joins two curves), u = (I + lambda L) x for positions and radii;
- the roots (each curve's first control point) are held (fit's mask), as a scalp would;
- radii stay positive by a clamp (fit's project): after every step r >= RADIUS_FLOOR (0.01, a
  fifth of the thinnest target radius). A clamp, not a reparameterisation (r = exp s): fit and
  LargeSteps work on the scene parameter itself, and the clamp is what the Blender add-on does;
- radii get a smaller learning rate than positions (a per-column lr, their scale being ~10x smaller).

Geometric error: the control points' RMS distance to the target's (positions), and the symmetric
mean distance between the two centre lines (each curve's B-spline sampled at 32 points per span,
each sample's distance to the nearest sample of the other curve's centre line, averaged both ways
and over the curves), plus the radii's RMS error.

Usage: nice .venv/bin/python tests/bench/curve_recovery.py [--iterations 100] [--out docs/reports/curves]
Writes <out>/recovery.md, recovery_curves.png (loss and geometric error against time) and
recovery.png (rows: the 3 views; columns: target | start | result).
"""
from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np

import limn
from limn.optim import curve_faces, fit

RADIUS_FLOOR = 0.01
NAME = "tuft.control_points"


def tuft(curves=4, points=6, height=1.2):
    """(target, start, offsets): control points (N x 4) of the bent, tapering tuft and of the
    straight start with the same roots and point counts."""
    rng = np.random.default_rng(7)
    target, start = [], []
    for c in range(curves):
        a = 2 * np.pi * c / curves + 0.4
        root = np.array([0.18 * np.cos(a), 0.18 * np.sin(a), 0.0])
        s = np.linspace(0.0, 1.0, points)
        lean = 0.55 + 0.15 * rng.random()                      # how far the tip leans outwards
        turn = a + 0.5 * (rng.random() - 0.5)
        side = 0.25 * (rng.random() - 0.5)                      # a sideways S-bend
        xy = root[:2] + lean * s[:, None] ** 2 * np.array([np.cos(turn), np.sin(turn)]) \
            + side * np.sin(np.pi * s)[:, None] * np.array([-np.sin(turn), np.cos(turn)])
        z = height * (s - 0.25 * s ** 2) * (0.9 + 0.2 * rng.random())
        r = 0.075 - 0.035 * s                                    # 0.075 at the root .. 0.04 at the tip
        target.append(np.column_stack([xy, z, r]))
        zs = np.linspace(0.0, z[-1], points)
        start.append(np.column_stack([np.repeat(root[None, :2], points, 0), zs, np.full(points, 0.055)]))
    offsets = np.arange(curves) * points
    return np.concatenate(target).astype(np.float32), np.concatenate(start).astype(np.float32), offsets


def cameras(views=3):
    """Cameras around the tuft, 35 degrees apart in elevation from a level view and looking at its middle."""
    out = []
    for k in range(views):
        az = np.deg2rad(-90 + 120 * k)
        el = np.deg2rad([15, 35, 55][k % 3])
        d = 3.4
        out.append([d * np.cos(el) * np.cos(az), d * np.cos(el) * np.sin(az), 0.55 + d * np.sin(el)])
    return out


def scene_dict(points, offsets, origin, size=64):
    return {"type": "scene", "integrator": {"type": "direct"},
            "sensor": {"type": "perspective", "fov": 26,
                       "to_world": {"look_at": {"origin": list(map(float, origin)), "target": [0, 0, 0.55], "up": [0, 0, 1]}},
                       "film": {"type": "hdrfilm", "width": size, "height": size},
                       "sampler": {"type": "independent", "sample_count": 16}},
            "sky": {"type": "constant", "radiance": 1.0},
            "tuft": {"type": "bsplinecurve", "control_points": np.asarray(points, np.float32),
                     "curve_offsets": np.asarray(offsets, np.int32),
                     "bsdf": {"type": "diffuse", "reflectance": [0.55, 0.35, 0.2]}}}


def pyramid_l2(levels=4):
    """L2 on the image and on 2x2-averaged copies of it (levels in all): the coarse levels see a
    curve that is a few pixels off its target and pull it over (plain L2 only sees where the
    silhouettes overlap). Returns loss(image, target) -> (value, adjoint) as limn.optim.l2."""
    def down(a):
        h, w = a.shape[0] // 2 * 2, a.shape[1] // 2 * 2
        return 0.25 * (a[0:h:2, 0:w:2] + a[1:h:2, 0:w:2] + a[0:h:2, 1:w:2] + a[1:h:2, 1:w:2])

    def loss(image, target):
        a, b = image.astype(np.float64), target.astype(np.float64)
        value, adj, f = 0.0, np.zeros_like(a), 1
        for _ in range(levels):
            d = a - b
            value += float((d * d).mean())
            g = 2.0 * d / d.size / (f * f)                      # d(mean)/d(each fine pixel of the block)
            adj += np.repeat(np.repeat(g, f, 0), f, 1)[: adj.shape[0], : adj.shape[1]]
            if min(a.shape[:2]) < 4:
                break
            a, b, f = down(a), down(b), 2 * f
        return value, adj.astype(np.float32)
    return loss


def centre_line(points, offsets, per_span=32):
    """Samples of each curve's uniform cubic B-spline centre line (a list of (M, 3) arrays)."""
    t = np.linspace(0.0, 1.0, per_span, endpoint=False)
    basis = np.stack([(1 - t) ** 3, 3 * t ** 3 - 6 * t ** 2 + 4, -3 * t ** 3 + 3 * t ** 2 + 3 * t + 1, t ** 3], 1) / 6.0
    ends = list(offsets[1:]) + [len(points)]
    lines = []
    for a, b in zip(offsets, ends):
        p = np.asarray(points[a:b, :3], np.float64)
        spans = [basis @ p[s:s + 4] for s in range(len(p) - 3)]
        last = np.array([1.0, 4.0, 1.0]) / 6.0 @ p[-3:]        # t = 1 of the last span
        lines.append(np.vstack(spans + [last[None]]))
    return lines


def geometric_error(points, target, offsets):
    """(control-point RMS of positions, symmetric mean centre-line distance, radius RMS)."""
    cp = float(np.sqrt(((points[:, :3] - target[:, :3]) ** 2).sum(1).mean()))
    dist = []
    for a, b in zip(centre_line(points, offsets), centre_line(target, offsets)):
        d = np.linalg.norm(a[:, None] - b[None], axis=2)
        dist.append(0.5 * (d.min(1).mean() + d.min(0).mean()))
    rad = float(np.sqrt(((points[:, 3] - target[:, 3]) ** 2).mean()))
    return cp, float(np.mean(dist)), rad


def run(iterations=100, size=64, views=3, curves=4, points=6, lr=0.03, lr_radius=0.003, lambda_=4.0, spp=4,
        spp_boundary=16, levels=4, target_spp=256, zero_gradient=False, seed=0, log=None):
    """Optimise from the start to the targets; returns a dict of rows (iteration, seconds, loss,
    control-point RMS, centre-line distance, radius RMS, smallest radius), the images and the final points.
    zero_gradient: the gradient is replaced by zeros (the test's check that the recovery comes
    from the derivatives)."""
    target, start, offsets = tuft(curves, points)
    origins = cameras(views)
    targets = [limn.load_dict(scene_dict(target, offsets, o, size)).render(spp=target_spp, seed=999 + k)
               for k, o in enumerate(origins)]
    scenes = [limn.load_dict(scene_dict(start, offsets, o, size)) for o in origins]
    start_images = [s.render(spp=64, seed=1) for s in scenes]
    mask = np.ones(len(start))
    mask[offsets] = 0.0                                          # roots held

    def clamp(x):
        x[:, 3] = np.maximum(x[:, 3], RADIUS_FLOOR)
        return x

    rows = []

    def callback(it, loss, x):
        rows.append((it, time.perf_counter() - t0, loss) + geometric_error(x, target, offsets) + (float(x[:, 3].min()),))
        if log and it % 10 == 0:
            log(f"it {it:4d}  {rows[-1][1]:7.1f} s  loss {loss:.4e}  cp {rows[-1][3]:.4f}  line {rows[-1][4]:.4f}  r {rows[-1][5]:.4f}")

    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = fit(list(zip(scenes, targets)), NAME, iterations=iterations, lr=np.array([lr, lr, lr, lr_radius]),
                     lambda_=lambda_, faces=curve_faces(offsets, len(start)), loss=pyramid_l2(levels), spp=spp,
                     spp_boundary=spp_boundary, mask=mask, project=clamp, callback=callback, seed=seed,
                     gradient=(lambda g: np.zeros_like(g)) if zero_gradient else None)
    final = scenes[0].params[NAME].copy()
    loss_fn = pyramid_l2(levels)
    end_images = [s.render(spp=64, seed=1) for s in scenes]
    rows.append((len(rows), time.perf_counter() - t0, float(np.mean([loss_fn(s.render(spp=spp, seed=12345), t)[0]
                                                                       for s, t in zip(scenes, targets)])))
                + geometric_error(final, target, offsets) + (float(final[:, 3].min()),))
    return {"rows": rows, "diverged": result.diverged, "target": target, "start": start, "final": final,
            "offsets": offsets, "images": (targets, start_images, end_images)}


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    r = np.array(rows, dtype=np.float64)
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
    ax[0].semilogy(r[:, 1], r[:, 2], lw=1)
    ax[0].set_xlabel("wall time (s)")
    ax[0].set_ylabel("loss (multi-resolution L2, 3 views)")
    ax[1].semilogy(r[:, 1], r[:, 3], label="control-point RMS")
    ax[1].semilogy(r[:, 1], r[:, 4], label="centre-line distance")
    ax[1].semilogy(r[:, 1], r[:, 5], label="radius RMS")
    ax[1].set_xlabel("wall time (s)")
    ax[1].set_ylabel("geometric error")
    ax[1].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--iterations", type=int, default=100)
    ap.add_argument("--lr", type=float, default=0.03)
    ap.add_argument("--lr-radius", type=float, default=0.003)
    ap.add_argument("--lambda", dest="lambda_", type=float, default=4.0)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--spp-boundary", type=int, default=16)
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--zero-gradient", action="store_true")
    ap.add_argument("--out", default="docs/reports/curves")
    args = ap.parse_args(argv)
    out = run(args.iterations, args.size, lr=args.lr, lr_radius=args.lr_radius, lambda_=args.lambda_, spp=args.spp,
              spp_boundary=args.spp_boundary, zero_gradient=args.zero_gradient, log=print)
    rows = out["rows"]
    os.makedirs(args.out, exist_ok=True)
    targets, starts, ends = out["images"]
    grid = np.concatenate([np.concatenate([t, s, e], 1) for t, s, e in zip(targets, starts, ends)], 0)
    limn.write_image(os.path.join(args.out, "recovery.png"), np.clip(grid, 0, 1).astype(np.float32))
    plot(rows, os.path.join(args.out, "recovery_curves.png"))
    first, last = rows[0], rows[-1]
    summary = (f"loss {first[2]:.3e} -> {last[2]:.3e}, control-point RMS {first[3]:.4f} -> {last[3]:.4f} "
               f"({first[3] / last[3]:.1f}x), centre-line distance {first[4]:.4f} -> {last[4]:.4f} ({first[4] / last[4]:.1f}x), "
               f"radius RMS {first[5]:.4f} -> {last[5]:.4f}, smallest radius during the run {min(r[6] for r in rows):.4f} "
               f"(clamp at {RADIUS_FLOOR}), {last[1]:.0f} s")
    with open(os.path.join(args.out, "recovery.md"), "w") as f:
        f.write("# Recovering a hair tuft from 3 views\n\n")
        cmd = (f"nice .venv/bin/python tests/bench/curve_recovery.py --iterations {args.iterations} --lr {args.lr} "
               f"--lr-radius {args.lr_radius} --lambda {args.lambda_} --spp {args.spp} --spp-boundary {args.spp_boundary} "
               f"--size {args.size}" + (" --zero-gradient" if args.zero_gradient else ""))
        f.write(f"Regenerate: `{cmd}` (the set-up is in the script's docstring).\n\n")
        f.write(f"Result: {summary}" + (f"; fit stopped early: {out['diverged']}" if out["diverged"] else "") + ".\n\n")
        f.write("| iteration | time (s) | loss | control-point RMS | centre-line distance | radius RMS |\n|---|---|---|---|---|---|\n")
        step = max(1, len(rows) // 12)
        for r in rows[::step] + ([rows[-1]] if (len(rows) - 1) % step else []):
            f.write(f"| {r[0]} | {r[1]:.1f} | {r[2]:.3e} | {r[3]:.4f} | {r[4]:.4f} | {r[5]:.4f} |\n")
        f.write("\nThe last row is after the last step (loss from one render per view at the same spp).\n\n")
        target, start, final, offsets = out["target"], out["start"], out["final"], out["offsets"]
        k = np.arange(len(target)) - np.repeat(offsets, np.diff(list(offsets) + [len(target)]))
        f.write("Error by control point along the curves (index 0 the held root; mean over the curves):\n\n"
                "| index | position error, start | position error, result | radius, target | radius, result |\n"
                "|---|---|---|---|---|\n")
        for i in range(int(k.max()) + 1):
            sel = k == i
            e0 = np.linalg.norm(start[sel, :3] - target[sel, :3], axis=1).mean()
            e1 = np.linalg.norm(final[sel, :3] - target[sel, :3], axis=1).mean()
            f.write(f"| {i} | {e0:.4f} | {e1:.4f} | {target[sel, 3].mean():.4f} | {final[sel, 3].mean():.4f} |\n")
        f.write("\n")
        f.write("![loss and geometric error against time](recovery_curves.png)\n\n")
        f.write("![rows: the 3 views; columns: target, start, result](recovery.png)\n")
    print(summary)


if __name__ == "__main__":
    main()
