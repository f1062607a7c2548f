"""Speed of limn against Blender's Cycles (CPU) on the same scene, at 2 threads; writes
docs/performance.md. Run from the repository root after ./bootstrap.sh:

    blender -b --factory-startup -noaudio --python tests/bench/cycles_vs_limn.py -- --out docs/performance.md

Both renderers get the scene built by tests/blender/scene_builder.build_cornell() (limn through the
add-on's exporter), the same resolution, samples per pixel and bounces, box-like pixel filter, no
denoising, no adaptive sampling, no clamping. Equal time: each renderer's error against its own
converged image (so differences in light units or BSDF details between the two do not count)."""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "tests", "blender"))
sys.path.insert(0, os.path.join(ROOT, "build", "addon"))

import addon_utils  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402

import scene_builder  # noqa: E402

THREADS = 2


def cycles_render(scene, spp: int, path: str) -> float:
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.samples = spp
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.filter_width = 0.01          # as close to a box filter over the pixel as Cycles allows
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.seed = 1 + spp  # references use other random numbers than the budgets they are compared with
    scene.render.threads_mode = "FIXED"
    scene.render.threads = THREADS
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = path
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    return time.perf_counter() - t0


MASK = None  # pixels compared: those that see neither the lamp nor its edge (set in main)


def rmse(a, b):
    return float(np.sqrt(np.mean(((a - b) ** 2)[MASK])))


def main() -> int:
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default=os.path.join(ROOT, "docs", "performance.md"))
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--budgets", type=int, nargs="+", default=[16, 64, 256])
    parser.add_argument("--reference-spp", type=int, default=4096)
    args = parser.parse_args(argv)

    scene = scene_builder.build_cornell(size=args.size)
    addon_utils.enable("limn_blender", default_set=True)
    import limn_blender
    from limn_blender.render_ops import _limn
    limn = _limn()
    tmp = tempfile.mkdtemp(prefix="limn-bench-")

    # 1. limn on the default scene: throughput at 2 threads (median of 3).
    default = limn.load(os.path.join(ROOT, "scenes", "default.json"))
    runs = []
    for seed in range(3):
        default.render(spp=64, seed=seed, threads=THREADS)
        runs.append(default.last_stats)
    med = sorted(runs, key=lambda s: s["seconds"])[1]
    default_rows = (med["seconds"], med["samples"] / med["seconds"] / 1e6, med["rays"] / med["seconds"] / 1e6,
                    med["rays"] / med["samples"])

    # 2. The Cornell box in both renderers at equal spp.
    t0 = time.perf_counter()
    lscene, warnings = limn_blender.load_blender_scene(scene, spp=16)
    limn_load = time.perf_counter() - t0
    ref_limn = lscene.render(spp=args.reference_spp, seed=99, threads=THREADS)
    # Cycles 3.4 does not show the lamp to the camera, limn does: leave out the lamp and a one-pixel
    # rim around it from every comparison.
    global MASK
    lamp = ref_limn.max(axis=-1) > 2.0
    rim = lamp.copy()
    for axis in (0, 1):
        for shift in (-1, 1):
            rim |= np.roll(lamp, shift, axis=axis)
    MASK = ~rim
    t_ref_cycles = cycles_render(scene, args.reference_spp // 4, os.path.join(tmp, "cycles_ref.exr"))
    ref_cycles = limn.read_image(os.path.join(tmp, "cycles_ref.exr"))
    rows = []
    for spp in args.budgets:
        t_c = cycles_render(scene, spp, os.path.join(tmp, f"cycles_{spp}.exr"))
        img_c = limn.read_image(os.path.join(tmp, f"cycles_{spp}.exr"))
        times = []
        for seed in range(3):
            img_l = lscene.render(spp=spp, seed=seed, threads=THREADS)
            times.append(lscene.last_stats["seconds"])
        t_l = statistics.median(times)
        rows.append((spp, t_c, t_l, rmse(img_c, ref_cycles), rmse(img_l, ref_limn)))

    # 3. Equal time: limn's spp in the time Cycles took for the largest budget.
    spp_c, t_c = rows[-1][0], rows[-1][1]
    per_sample = rows[-1][2] / spp_c
    spp_eq = max(1, int(t_c / per_sample))
    img_eq = lscene.render(spp=spp_eq, seed=7, threads=THREADS)
    eq = (spp_c, t_c, rows[-1][3], spp_eq, lscene.last_stats["seconds"], rmse(img_eq, ref_limn))
    ratio = ref_cycles[MASK].sum(0) / ref_limn[MASK].sum(0)

    cpu = subprocess.run(["sh", "-c", "grep -m1 'model name' /proc/cpuinfo | cut -d: -f2"], capture_output=True, text=True).stdout.strip()
    lines = [
        "# Performance", "",
        "Regenerate (after `./bootstrap.sh`):", "",
        "```", "blender -b --factory-startup -noaudio --python tests/bench/cycles_vs_limn.py -- --out docs/performance.md", "```", "",
        f"Measured {time.strftime('%Y-%m-%d')} on {cpu or platform.processor()}, {THREADS} threads, "
        f"Blender {bpy.app.version_string} (Cycles CPU), limn {limn.__version__}. Times are wall-clock seconds "
        "on a shared machine; ratios come from the same run.", "",
        "## Default scene (scenes/default.json, 256x256, 64 spp, path tracer, max_depth 8)", "",
        "| render time (s) | samples/s (M) | rays/s (M) | rays per sample |", "|---|---|---|---|",
        "| {:.2f} | {:.2f} | {:.2f} | {:.2f} |".format(*default_rows), "",
        "Rays are intersection plus shadow rays, counted by the integrator.", "",
        f"## limn against Cycles: Cornell box built in Blender ({args.size}x{args.size}, diffuse, one area light, max_depth 8 = 6 Cycles bounces)", "",
        "The scene is made by `tests/blender/scene_builder.build_cornell()`; limn renders what the add-on exports "
        f"(load and export: {limn_load:.2f} s, not included below). Cycles' time is its whole `render.render` call "
        "(scene sync and BVH build included, a few tenths of a second); limn's is the render call alone. "
        "RMSE is over the pixels that see neither the lamp nor its edge, against each renderer's own converged image "
        f"(limn {args.reference_spp} spp, Cycles {args.reference_spp // 4} spp, {t_ref_cycles:.1f} s).", "",
        "| spp | Cycles time (s) | limn time (s) | Cycles / limn time | Cycles RMSE | limn RMSE |", "|---|---|---|---|---|---|",
    ]
    for spp, tc, tl, ec, el in rows:
        lines.append(f"| {spp} | {tc:.2f} | {tl:.2f} | {tc / tl:.2f} | {ec:.4f} | {el:.4f} |")
    lines += [
        "", "### Equal time", "",
        f"In the {eq[1]:.2f} s Cycles took for {eq[0]} spp, limn renders {eq[3]} spp ({eq[4]:.2f} s): "
        f"RMSE {eq[5]:.4f} against Cycles' {eq[2]:.4f}.",
        "limn draws independent random samples; Cycles uses stratified (progressive multi-jittered) samples, "
        "which lowers its error per sample on smooth diffuse lighting. Each RMSE includes the noise of its "
        f"reference, which is larger for Cycles' (only {args.reference_spp // 4} spp).", "",
        "### Do the two renderers agree?", "",
        "Sum of Cycles' converged image over limn's, per channel, over the pixels that do not see the lamp "
        "(1 is perfect agreement of light units, materials and bounce counts): " + ", ".join(f"{r:.3f}" for r in ratio) + ".",
        "The exporter's light conversions are in docs/blender.md.", "",
        "## Derivatives", "",
        "Cost of render_backward against render and memory: docs/reports/derivative_cost.md "
        "(`.venv/bin/python tests/bench/derivative_cost.py`).", "",
    ]
    if warnings:
        lines += ["Exporter warnings:", ""] + [f"- {w}" for w in warnings] + [""]
    with open(args.out, "w") as f:
        f.write("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    os._exit(code)
