"""Regenerates docs/reports/sdf/README.md: signed-distance grids (issue 37).

  PYTHONPATH=<dir with the limn package> python3 tests/bench/sdf_report.py [--quick]

1. FD agreement: the render-level scenes of tests/python/test_sdfgrid.py (a black SDF ball against a
   sky: primary visibility; an SDF ball's shadow under a point and an area light, camera on the
   floor: the indirect boundary term) at several grid resolutions; block z-scores with the term on
   and off, and the image sums.
2. Error against run time of the indirect term on the area-light shadow scene: uniform sampling of
   the boundary sample space at B and 10 B samples per pixel, the projective grid and the octree
   at B, against a central-difference reference (the image is the boundary term alone there: the
   camera does not see the SDF, so the interior term is zero).
3. The projection operator: how many seed segments project onto silhouettes (interior patch,
   crease, fallback), from the guides' own counters.
4. Voxel BVH (Embree user primitives) build time, primitive counts and memory, and one backward
   pass, at 64^3, 128^3, 256^3 (each size in its own process).
5., 6. The paper's Figure 17 (tests/bench/sdf_fig17.py): the perimeter and interior parts of Eq. 4
   against FD for an SDF seen in the reflection test scene and for its shadow, 64^3 and 128^3.

`--only 4,5,6` regenerates those sections and keeps the others of the existing README.
"""
from __future__ import annotations

import json
import os
import sys
import time
import warnings

import numpy as np

import limn

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "tests", "python"))
from test_derivatives import block_z  # noqa: E402
from test_sdfgrid import ball, shadow_scene, sky_scene, sdf  # noqa: E402
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sdf_fig17  # noqa: E402

OUT = os.path.join(ROOT, "docs", "reports", "sdf")
QUICK = "--quick" in sys.argv


def quiet(fn, *a, **k):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*a, **k)


def silhouette_scene(n):
    d = sky_scene(sdf(ball(n)))
    d["obj"]["bsdf"] = {"type": "diffuse", "reflectance": 0.0}
    return limn.load_dict(d), "obj.data"


def lit_scene(n):
    """The SDF ball under the point light, seen directly (no floor): interior + primary terms."""
    with open(os.path.join(ROOT, "scenes", "validation", "sphere_occluder_point.json")) as f:
        d = json.load(f)
    del d["floor"], d["ball"]
    d["sensor"]["to_world"]["look_at"]["target"] = [0.4, 0.2, 1.2]
    d["sensor"]["fov"] = 20
    d["blob"] = {"type": "sdfgrid", "data": ball(n), "to_world": [{"translate": [-0.5, -0.5, -0.5]}, {"translate": [0.4, 0.2, 1.2]}],
                 "bsdf": {"type": "diffuse", "reflectance": 0.4}}
    return limn.load_dict(d), "blob.data"


def shadow(light, n):
    s = shadow_scene(light, n)
    return s, "blob.data"


def tangent(scene, name, seed):
    rng = np.random.default_rng(seed)
    return (-1.0 + 0.5 * rng.standard_normal(scene.params[name].shape)).astype(np.float32)


def fd_agreement(lines):
    lines += ["## 1. Finite-difference agreement", "",
              "Block (4 x 4 px) z-scores of the derivative image against central differences (eps 2e-3 on every",
              "grid value, 1024 spp per seed), 8 seeds each; tangent -1 + 0.5 N(0, 1) per grid value (the ball grows,",
              "unevenly). `on`: the term under test on; `off`: switched off (spp_primary = 0 or spp_boundary = 0).", "",
              "| scene | grid | max abs z (on) | max abs z (off) | sum FD +- s.e. | sum on +- s.e. | time on (s) |", "|---|---|---|---|---|---|---|"]
    seeds = 4 if QUICK else 8
    for label, make, kw_on, kw_off in [
        ("silhouette (primary)", silhouette_scene, dict(spp=128, spp_primary=128), dict(spp=128, spp_primary=0)),
        ("shadow, point light (indirect)", lambda n: shadow("point", n), dict(spp=64, spp_boundary=16), dict(spp=64, spp_boundary=0)),
        ("shadow, area light (indirect)", lambda n: shadow("area", n), dict(spp=64, spp_boundary=512), dict(spp=64, spp_boundary=0)),
        ("shadow, area light (indirect), 8x samples", lambda n: shadow("area", n), dict(spp=64, spp_boundary=4096), dict(spp=64, spp_boundary=0)),
        ("lit ball seen directly (interior + primary)", lit_scene, dict(spp=128, spp_primary=128, spp_boundary=16),
         dict(spp=128, spp_primary=0, spp_boundary=16)),
    ]:
        for n in ((16,) if QUICK else (16, 32, 64)):
            if "8x" in label and n != 64:
                continue
            scene, name = make(n)
            scene.set_differentiable([name])
            t = tangent(scene, name, 3)
            fd = np.stack([limn.fd(scene, {name: t}, eps=2e-3, spp=1024, seed=k, cache=False) for k in range(seeds)])
            t0 = time.time()
            on = np.stack([quiet(scene.render_forward, {name: t}, seed=50 + k, **kw_on) for k in range(seeds)])
            t_on = (time.time() - t0) / seeds
            off = np.stack([quiet(scene.render_forward, {name: t}, seed=50 + k, **kw_off) for k in range(seeds)])
            z_on, z_off = block_z(on, fd), block_z(off, fd)
            se = lambda a: a.sum(axis=(1, 2, 3)).std(ddof=1) / np.sqrt(len(a))  # noqa: E731
            lines.append(f"| {label} | {n}^3 | {np.abs(z_on).max():.2f} | {np.abs(z_off).max():.1f} | {fd.mean(0).sum():.2f} +- {se(fd):.2f} | "
                         f"{on.mean(0).sum():.2f} +- {se(on):.2f} | {t_on:.2f} |")
            print(lines[-1], flush=True)
    lines.append("")


def parts_agreement(lines):
    lines += ["## 1b. The two parts of Eq. 4 separately", "",
              "Shadow scenes, indirect term with `boundary_parts` = perimeter (creases) or interior (patches,",
              "curvature) alone, 8 seeds, against the same FD reference as above (sums of the derivative image).", "",
              "| scene | grid | sum FD +- s.e. | perimeter | interior | perimeter + interior | max abs z: sum / perimeter alone / interior alone |",
              "|---|---|---|---|---|---|---|"]
    seeds = 4 if QUICK else 8
    for light, spp_b in (("point", 16), ("area", 512)):
        for n in ((16,) if QUICK else (16, 32, 64)):
            scene, name = shadow(light, n)
            scene.set_differentiable([name])
            t = tangent(scene, name, 3)
            b = spp_b if (light == "point" or n < 64) else 4096
            fd = np.stack([limn.fd(scene, {name: t}, eps=2e-3, spp=1024, seed=k, cache=False) for k in range(seeds)])
            part = {p: np.stack([quiet(scene.render_forward, {name: t}, spp=64, spp_boundary=b, boundary_parts=p, seed=50 + k)
                                 for k in range(seeds)]) for p in ("perimeter", "interior")}
            se = fd.sum(axis=(1, 2, 3)).std(ddof=1) / np.sqrt(seeds)
            zs = [np.abs(block_z(x, fd)).max() for x in (part["perimeter"] + part["interior"], part["perimeter"], part["interior"])]
            lines.append(f"| {light} light, spp_boundary {b} | {n}^3 | {fd.mean(0).sum():.2f} +- {se:.2f} | {part['perimeter'].mean(0).sum():.2f} | "
                         f"{part['interior'].mean(0).sum():.2f} | {(part['perimeter'] + part['interior']).mean(0).sum():.2f} | "
                         f"{zs[0]:.2f} / {zs[1]:.2f} / {zs[2]:.2f} |")
            print(lines[-1], flush=True)
    lines.append("")


def error_vs_time(lines):
    n = 16 if QUICK else 32
    scene, name = shadow("area", n)
    scene.set_differentiable([name])
    t = tangent(scene, name, 3)
    ref_seeds = 4 if QUICK else 16
    refs = np.stack([limn.fd(scene, {name: t}, eps=2e-3, spp=2048, seed=100 + k, cache=False) for k in range(ref_seeds)])
    ref = refs.mean(0)
    ref_noise = np.sqrt((refs.std(0, ddof=1) ** 2 / ref_seeds).mean())
    scale = np.sqrt((ref ** 2).mean())
    B = 64
    methods = [("uniform 1x", dict(spp_boundary=B)), ("uniform 10x", dict(spp_boundary=10 * B)),
               ("projective grid", dict(spp_boundary=B, guiding="grid")), ("octree", dict(spp_boundary=B, guiding="octree"))]
    lines += ["## 2. Error against run time (indirect term)", "",
              f"Area-light shadow scene, {n}^3 grid, 16 x 16 px; the camera does not see the SDF, so the derivative",
              "image is the indirect boundary term alone (spp_interior = spp_primary = 0 here). Reference: central",
              f"differences, {ref_seeds} x 2048 spp (its own noise: {ref_noise / scale:.3f} of the reference's RMS). RMSE relative to",
              f"the reference's RMS over 6 seeds; time per call, guide set-up included (nothing reused: a fresh",
              "guide every call). One run, side by side.", "",
              "| method | spp_boundary | time per call (s) | relative RMSE | RMSE x sqrt(time) |", "|---|---|---|---|---|"]
    for label, kw in methods:
        imgs, times = [], []
        for k in range(3 if QUICK else 6):
            t0 = time.time()
            imgs.append(quiet(scene.render_forward, {name: t}, spp_interior=0, spp_primary=0, seed=200 + k, **kw))
            times.append(time.time() - t0)
        err = np.sqrt(np.mean([((im - ref) ** 2).mean() for im in imgs])) / scale
        tt = float(np.mean(times))
        lines.append(f"| {label} | {kw['spp_boundary']} | {tt:.2f} | {err:.3f} | {err * np.sqrt(tt):.3f} |")
        print(lines[-1], flush=True)
        if label == "octree":
            summary = next(l for l in scene.last_stats["summary"] if l.startswith("indirect boundary"))
    lines += ["", "Octree summary of the last call: `" + summary + "`", ""]


def projection_stats(lines):
    n = 16 if QUICK else 32
    scene, name = shadow("area", n)
    scene.set_differentiable([name])
    t = tangent(scene, name, 3)
    quiet(scene.render_forward, {name: t}, spp=1, spp_boundary=16, guiding="grid", seed=1)
    summary = next(l for l in scene.last_stats["summary"] if l.startswith("indirect boundary"))
    import re
    m = re.search(r"(\d+) seed paths.*?: (\d+) segments, (\d+) projected, (\d+) onto silhouettes", summary)
    lines += ["## 3. The projection operator", "",
              f"Area-light shadow scene, {n}^3: from the grid guide's seeding (its summary): " +
              (f"{m.group(2)} seed segments hit the SDF or the floor, {m.group(3)} were projected, {m.group(4)} landed on silhouettes "
               f"({100 * int(m.group(4)) / max(int(m.group(3)), 1):.0f} %)." if m else summary),
              "The C++ battery (tests/cpp/shapes/test_battery.cpp, `SdfKind`) checks that every projected point it can",
              "check is a true silhouette (the line along w beside x_b meets the surface on one side only).", ""]


def _status_kib(field):
    with open("/proc/self/status") as f:
        return next(int(l.split()[1]) for l in f if l.startswith(field + ":"))


def _reset_peak():
    """Linux: writing 5 to clear_refs resets VmHWM to the current RSS (proc(5))."""
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")


def bvh_child(n):
    """One size of section 4 in a fresh process (so peaks and caches of other sizes do not count):
    times and memory (RSS, VmHWM from /proc/self/status) as JSON on stdout."""
    d = sky_scene(sdf(ball(n)), spp=4)
    d["sensor"]["film"] = {"type": "hdrfilm", "width": 32, "height": 32}
    d["lamp"] = {"type": "rectangle", "to_world": [{"scale": 0.5}, {"rotate": {"axis": [1, 0, 0], "angle": 180}}, {"translate": [0.5, -0.5, 3]}],
                 "emitter": {"type": "area", "radiance": 10.0}}
    data = d["obj"]["data"]
    # limn's own per-voxel arrays, exactly: values and built_values (float32 per sample) and one
    # 32-byte Prim (uint32 voxel, uint8 axis + 3 padding, 6 floats) per voxel the surface can pass
    # through (SdfGrid::straddles: min <= 0 <= max over the 8 corners, not all zero).
    c = [data[z:z + n - 1, y:y + n - 1, x:x + n - 1] for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    lo, hi = np.minimum.reduce(c), np.maximum.reduce(c)
    prims = int(((lo <= 0) & (hi >= 0) & ~((lo == 0) & (hi == 0))).sum())
    del c, lo, hi
    import gc
    gc.collect()
    _reset_peak()
    rss0 = _status_kib("VmRSS")
    t0 = time.time()
    scene = limn.load_dict(d)
    t_load = time.time() - t0
    load_peak, load_kept = _status_kib("VmHWM") - rss0, _status_kib("VmRSS") - rss0
    name = "obj.data"
    v = scene.params[name].copy()
    scene.params[name] = v - 1e-3
    t0 = time.time()
    scene.update()
    t_update = time.time() - t0
    scene.set_differentiable([name])
    _reset_peak()
    rss1 = _status_kib("VmRSS")
    t0 = time.time()
    quiet(scene.render_backward, np.ones((32, 32, 3), np.float32), spp=4, spp_boundary=16, seed=0)
    t_bwd = time.time() - t0
    bwd_peak = _status_kib("VmHWM") - rss1
    summary = next((l for l in scene.last_stats["summary"] if l.startswith("indirect boundary")), "")
    import re
    m = re.search(r"over (\d+) SDF voxels and creases", summary)
    print(json.dumps(dict(n=n, segments=int(m.group(1)) if m else -1, prims=prims, own_bytes=8 * n ** 3 + 32 * prims,
                          t_load=t_load, t_update=t_update, t_bwd=t_bwd, load_peak_kib=load_peak, load_kept_kib=load_kept,
                          bwd_peak_kib=bwd_peak)))


def bvh_and_backward(lines):
    import subprocess
    lines += ["## 4. Voxel BVH and one backward pass", "",
              "The bumpy ball at n^3 samples, 32 x 32 px, area light, spp 4, spp_boundary 16 (uniform). Each size",
              "in a fresh process. Memory: the process's resident set (/proc/self/status) around the call, with the",
              "peak (VmHWM) reset just before it (`echo 5 > /proc/self/clear_refs`), so the peak is the call's own",
              "high-water mark above what was resident before (the input array, Python, limn's module). `kept`: RSS",
              "after the load minus before: the scene as it stays (grid values twice, the prims, Embree's BVH, the",
              "rest of the scene). `limn's arrays`: the exact size of the grid's own vectors (values and built_values,",
              "4 bytes per sample each, and one 32-byte Prim per voxel the surface can pass through); Embree 3 has",
              "no query for its BVH's size, so Embree's share is in `kept` only (kept minus limn's arrays is an",
              "upper bound on it and the rest of the scene, allocator slack included).", "",
              "| grid | boundary segments (surface voxels + creases) | voxel prims | load + BVH build (s) | update after changing every value (s) | backward pass (s) | limn's arrays (MiB) | load: peak / kept (MiB) | backward: peak (MiB) |",
              "|---|---|---|---|---|---|---|---|---|"]
    for n in ((32, 64) if QUICK else (64, 128, 256)):
        out = subprocess.run([sys.executable, os.path.abspath(__file__), "--bvh-child", str(n)], check=True,
                             capture_output=True, text=True).stdout
        r = json.loads(out.strip().splitlines()[-1])
        mib = lambda kib: kib / 1024  # noqa: E731
        lines.append(f"| {n}^3 | {r['segments']} | {r['prims']} | {r['t_load']:.2f} | {r['t_update']:.2f} | {r['t_bwd']:.2f} | "
                     f"{r['own_bytes'] / 2 ** 20:.1f} | {mib(r['load_peak_kib']):.1f} / {mib(r['load_kept_kib']):.1f} | "
                     f"{mib(r['bwd_peak_kib']):.1f} |")
        print(lines[-1], flush=True)
    lines.append("")


def fig17_reflection(lines):
    sdf_fig17.section(lines, "reflection", (16,) if QUICK else (64, 128), 4 if QUICK else 8, OUT,
                      "## 5. Figure 17 (a): an SDF seen in the reflection test scene, perimeter and interior parts",
                      "The projective-sampling paper's test scene (scenes/projective/make.py `base`: a GGX alpha = 0.005\n"
                      "conductor plane before a large emitter) with the bumpy ball as an `sdfgrid` in place of its sphere\n"
                      "(radius 0.25), the camera zoomed onto the reflection (32 x 32 px, fov 14): the SDF is seen only in the\n"
                      "plane, so the derivative image is the indirect boundary term (and a small interior term: the\n"
                      "reflected SDF is lit by the emitter's light off the plane).")


def fig17_shadow(lines):
    sdf_fig17.section(lines, "shadow", (16,) if QUICK else (64, 128), 4 if QUICK else 8, OUT,
                      "## 6. Figure 17 (b): an SDF casting a shadow, perimeter and interior parts",
                      "Section 1's point-light shadow scene (tests/python/test_sdfgrid.py `shadow_scene`: the camera sees\n"
                      "the floor only, so the derivative image is the indirect boundary term alone) at 64^3 and 128^3.")


SECTIONS = {"1": fd_agreement, "1b": parts_agreement, "2": error_vs_time, "3": projection_stats, "4": bvh_and_backward,
            "5": fig17_reflection, "6": fig17_shadow}


def split_sections(text):
    """The README's header and its sections by number ("## 1b. ..." -> "1b")."""
    import re
    parts = re.split(r"(?m)^(?=## )", text)
    head, secs = parts[0], {}
    for p in parts[1:]:
        secs[re.match(r"## (\w+)\.", p).group(1)] = p
    return head, secs


def main():
    """`--only 4,5` regenerates those sections and keeps the others of the existing README."""
    os.makedirs(OUT, exist_ok=True)
    only = sys.argv[sys.argv.index("--only") + 1].split(",") if "--only" in sys.argv else list(SECTIONS)
    path = os.path.join(OUT, "README.md" if not QUICK else "quick.md")
    old = {}
    if "--only" in sys.argv and os.path.exists(path):
        old = split_sections(open(path).read())[1]
    load0 = os.getloadavg()
    stamp = time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())
    new = {}
    for key, part in SECTIONS.items():
        if key not in only:
            continue
        sec = []
        t0 = time.time()
        part(sec)
        new[key] = "\n".join(sec) + "\n" + (f"(Section generated {stamp} in {time.time() - t0:.0f} s; machine load average "
                                             f"{load0[0]:.1f} at the start, {os.getloadavg()[0]:.1f} at the end.)\n\n")
        secs = {**old, **new}
        head = ["# Signed-distance grids (`sdfgrid`): measurements", "",
                "Generated by `tests/bench/sdf_report.py`" + (" --quick" if QUICK else "") +
                f" (sections {', '.join(k for k in SECTIONS if k in new)} on {stamp}" +
                (", the others earlier" if set(old) - set(new) else "") + ");",
                "2-core machine shared with other work (timings are indicative). What the numbers say, and what is",
                "still open (the lit ball's sums, the 64^3 area light at 512 samples, the 64^3 point-light shadow of section 6,",
                "the heavy-tailed perimeter estimates in section 5's reflection): docs/derivatives.md, \"Known gaps\"; docs/sdf.md.",
                "`python3 tests/bench/sdf_report.py --only 4,5` regenerates those sections alone.", ""]
        with open(path, "w") as f:
            f.write("\n".join(head) + "\n" + "".join(secs[k] for k in SECTIONS if k in secs))


if __name__ == "__main__":
    if "--bvh-child" in sys.argv:
        bvh_child(int(sys.argv[sys.argv.index("--bvh-child") + 1]))
    else:
        main()
