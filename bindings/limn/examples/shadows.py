"""Shape from shadows: ``python3 -m limn demo shadows``.

In the spirit of the projective-sampling paper's Figures 15/16: an object lit by two small area
lights casts two shadows on a curved diffuse wall (scenes/shadow_wall/). One camera sees the object
from the front and both shadows; the shadows carry the object's outline as seen from each light.
The optimisation starts from a sphere and recovers the ground-truth shape (scenes/shadow_wall/
truth.ply) from that single image: interior, primary-visibility and indirect boundary derivatives
(the shadows), Adam with the Large-Steps preconditioner. ``report(folder)`` runs it with the shadow
term on and off and with both guiding modes over several seeds and writes
<folder>/shadow_reconstruction.md with a plot.

The scene is read from the copy installed with the package (limn/examples/scenes/shadow_wall,
installed from the repository's scenes/shadow_wall by CMakeLists.txt), so the demo runs from any
working directory without the source tree."""
from __future__ import annotations

import json
import os
import time
import warnings
from importlib import resources

import numpy as np

from .. import load_dict, optim, write_image, write_ply
from .multiview import chamfer, surface_points


def scene_dir() -> str:
    """The shadow_wall scene's folder: package data of limn.examples (scenes/shadow_wall)."""
    d = resources.files(__package__) / "scenes" / "shadow_wall"
    if not (d / "scene.json").is_file():
        raise FileNotFoundError(f"{d}/scene.json is missing: this limn was installed without the example scenes "
                                f"(CMakeLists.txt installs scenes/shadow_wall there; reinstall with pip install .)")
    return os.fspath(d)


def _load(shape_file: str, size: int):
    d = scene_dir()
    with open(os.path.join(d, "scene.json")) as f:
        desc = json.load(f)
    desc["shape"]["filename"] = shape_file
    desc["sensor"]["film"]["width"] = size
    desc["sensor"]["film"]["height"] = size * 3 // 4
    return load_dict(desc, base_dir=d, source=os.path.join(d, "scene.json"))


def _mesh(scene, name="shape"):
    return scene.params[f"{name}.vertex_positions"].copy(), scene.faces(name)


def run(out: str | None = "out/shadows", iterations: int = 150, size: int = 64, spp: int = 8, spp_boundary: int = 64,
        guiding: str = "none", lr: float = 0.02, lambda_: float = 20.0, seed: int = 0, verbose: bool = True,
        options: dict | None = None) -> dict:
    """One reconstruction. Returns the summary with a history of (iteration, seconds, loss,
    Chamfer distance) every 10 iterations; the loss there is measured on a 64-spp render so that
    it is not dominated by the optimisation's own 8-spp noise."""
    truth_scene = _load("truth.ply", size)
    target = truth_scene.render(spp=1024, seed=12345)
    truth_points = surface_points(*_mesh(truth_scene))
    scene = _load("initial.ply", size)
    start, faces = _mesh(scene)
    history = []
    t0 = time.perf_counter()
    eval_seconds = 0.0

    def evaluate(it, x):
        nonlocal eval_seconds
        t = time.perf_counter()
        loss = optim.l2(scene.render(spp=64, seed=777), target)[0]
        err = chamfer(surface_points(x, faces, seed=1), truth_points)
        eval_seconds += time.perf_counter() - t
        history.append({"iteration": it, "seconds": time.perf_counter() - t0 - eval_seconds, "loss": loss, "chamfer": err})
        if verbose:
            print(f"iteration {it:4d}  loss {loss:.6f}  Chamfer {err:.4f}  {history[-1]['seconds']:6.1f} s", flush=True)

    def callback(it, loss, x):
        if it % 10 == 0:
            evaluate(it, x)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # summary lines about terms switched off on purpose
        optim.fit([(scene, target)], "shape.vertex_positions", iterations=iterations, lr=lr, lambda_=lambda_, spp=spp,
                  spp_primary=spp, spp_boundary=spp_boundary, faces=faces, callback=callback, seed=seed,
                  options=dict({"guiding": guiding}, **(options or {})))
    final = scene.params["shape.vertex_positions"].copy()
    evaluate(iterations, final)
    summary = {"guiding": guiding, "options": options or {}, "spp_boundary": spp_boundary, "seed": seed, "iterations": iterations,
               "initial_loss": history[0]["loss"], "final_loss": history[-1]["loss"],
               "initial_chamfer": history[0]["chamfer"], "final_chamfer": history[-1]["chamfer"],
               "seconds": history[-1]["seconds"], "history": history}
    if out:
        os.makedirs(out, exist_ok=True)
        write_ply(os.path.join(out, "result.ply"), final, faces)
        write_image(os.path.join(out, "result.png"), scene.render(spp=256))
        write_image(os.path.join(out, "target.png"), target)
        scene.params["shape.vertex_positions"][:] = start
        scene.update()
        write_image(os.path.join(out, "initial.png"), scene.render(spp=256))
        with open(os.path.join(out, "history.json"), "w") as f:
            json.dump(summary, f, indent=1)
    if verbose:
        print(f"loss {summary['initial_loss']:.6f} -> {summary['final_loss']:.6f}, Chamfer distance "
              f"{summary['initial_chamfer']:.4f} -> {summary['final_chamfer']:.4f} in {summary['seconds']:.1f} s"
              + (f"; wrote {os.path.abspath(out)}" if out else ""))
    return summary


CONFIGS = [("shadow term on, guiding none", {"spp_boundary": 64, "guiding": "none"}),
           ("baseline grid (random points per cell)", {"spp_boundary": 64, "guiding": "grid", "options": {"projective": False}}),
           ("projective grid", {"spp_boundary": 64, "guiding": "grid"}),
           ("octree", {"spp_boundary": 64, "guiding": "octree"}),
           ("octree, rebuilt every 10 iterations", {"spp_boundary": 64, "guiding": "octree", "options": {"guide_refresh": 10}}),
           ("shadow term off (spp_boundary = 0)", {"spp_boundary": 0, "guiding": "none"})]


def report(folder: str, seeds: int = 3, iterations: int = 150, argv: str = "") -> str:
    """Every configuration of CONFIGS over `seeds` seeds: a table and a plot of loss and Chamfer
    distance against iterations and time, written to <folder>/shadow_reconstruction.md and .png.
    `argv` is the command line the report names to regenerate it."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = {label: [run(out=None, iterations=iterations, seed=1000 * k, verbose=False, **cfg) for k in range(seeds)]
            for label, cfg in CONFIGS}
    os.makedirs(folder, exist_ok=True)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    for label, rs in runs.items():
        its = [h["iteration"] for h in rs[0]["history"]]
        loss = np.mean([[h["loss"] for h in r["history"]] for r in rs], axis=0)
        cham = np.mean([[h["chamfer"] for h in r["history"]] for r in rs], axis=0)
        secs = np.mean([[h["seconds"] for h in r["history"]] for r in rs], axis=0)
        axes[0].plot(its, loss, label=label)
        axes[1].plot(its, cham, label=label)
        axes[2].plot(secs, cham, label=label)
    axes[0].set(xlabel="iteration", ylabel="image loss (L2, 64-spp render)", yscale="log")
    axes[1].set(xlabel="iteration", ylabel="Chamfer distance to the ground truth")
    axes[2].set(xlabel="seconds (optimisation only)", ylabel="Chamfer distance to the ground truth")
    axes[1].legend()
    fig.suptitle(f"Shape from two shadows on a curved wall (scenes/shadow_wall), mean of {seeds} seeds")
    fig.tight_layout()
    png = os.path.join(folder, "shadow_reconstruction.png")
    fig.savefig(png, dpi=110)
    lines = ["# Shape from shadows on a curved wall", "",
             f"Regenerate: `{argv or 'python3 -m limn demo shadows --report ' + folder}`", "",
             "Scene: scenes/shadow_wall (a flat-shaded icosphere, 162 vertices, optimised towards truth.ply; two small "
             "area lights cast its shadows on a curved diffuse wall; one 64x48 camera). Target: 1024 spp. Each "
             f"iteration: one 8-spp render and one backward pass (8 interior paths and 8 primary samples per pixel), "
             f"Adam lr 0.02 with Large Steps lambda 20, {iterations} iterations. Loss: L2 on a 64-spp render; Chamfer: "
             "symmetric mean nearest-neighbour distance between 3000 surface points (the initial sphere has radius 0.5). "
             f"Mean (min - max) over {seeds} seeds; time excludes the evaluation renders. Machine: 2 cores, shared. "
             "Guides (grid, octree) are rebuilt for every backward pass unless said otherwise; the last-but-one row "
             "keeps the octree for 10 iterations (guide_refresh), which is what reuse saves.", "",
             "| configuration | final loss | initial Chamfer | final Chamfer | seconds |", "|---|---|---|---|---|"]
    for label, rs in runs.items():
        fc = [r["final_chamfer"] for r in rs]
        fl = [r["final_loss"] for r in rs]
        lines.append(f"| {label} | {np.mean(fl):.6f} | {rs[0]['initial_chamfer']:.4f} | {np.mean(fc):.4f} "
                     f"({min(fc):.4f} - {max(fc):.4f}) | {np.mean([r['seconds'] for r in rs]):.1f} |")
    lines += ["", "![loss and Chamfer distance](shadow_reconstruction.png)", "",
              "Per iteration (seed 0):", "", "| configuration | " + " | ".join(
                  str(h["iteration"]) for h in runs[CONFIGS[0][0]][0]["history"]) + " |",
              "|---|" + "---|" * len(runs[CONFIGS[0][0]][0]["history"])]
    for label, rs in runs.items():
        lines.append(f"| {label} (Chamfer) | " + " | ".join(f"{h['chamfer']:.4f}" for h in rs[0]["history"]) + " |")
    md = os.path.join(folder, "shadow_reconstruction.md")
    with open(md, "w") as f:
        f.write("\n".join(lines) + "\n")
    return md
