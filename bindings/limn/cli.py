"""Command line: ``python3 -m limn render scene.json -o out.exr --spp N``."""
from __future__ import annotations

import argparse
import os
import sys
import time

from .images import write_image
from .progress import ProgressBar
from .scene import load
from . import RenderCancelled


def cmd_render(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    scene = load(args.scene)
    t_load = time.perf_counter() - t0
    bar = ProgressBar(f"rendering {os.path.basename(args.scene)}")
    try:
        image = scene.render(spp=args.spp, seed=args.seed, threads=args.threads, progress=bar)
    finally:
        bar.close()
    stats = scene.last_stats
    outputs = [args.output]
    if args.output.lower().endswith((".exr", ".hdr")) and not args.no_preview:
        outputs.append(os.path.splitext(args.output)[0] + ".png")
    for path in outputs:
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        write_image(path, image)
    seconds = stats["seconds"]
    print(f"scene     {args.scene} ({scene.width}x{scene.height}, {stats['spp']} spp, loaded in {t_load:.2f} s)")
    print(f"render    {seconds:.2f} s, {stats['samples'] / seconds / 1e6:.2f} M samples/s, "
          f"{stats['rays'] / seconds / 1e6:.2f} M rays/s, {stats['invalid_samples']} invalid samples")
    for path in outputs:
        print(f"wrote     {os.path.abspath(path)}")
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    import warnings
    if args.which == "heightfield":
        from .examples import heightfield
        if args.report:
            md = heightfield.report(args.report, iterations=args.iterations or 80,
                                    argv="python3 -m limn " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["demo"] else "")
            print(f"wrote {os.path.abspath(md)}")
            return 0
        summary = heightfield.run(args.task, out=args.output or "out/heightfield", iterations=args.iterations or 80,
                                  spp=args.spp if args.spp != 8 else 4)
        return 0 if summary["final_loss"] < summary["initial_loss"] else 1
    if args.which == "shadows":
        from .examples import shadows
        if args.report:
            md = shadows.report(args.report, seeds=args.seeds, iterations=args.iterations or 150,
                                argv="python3 -m limn " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["demo"] else "")
            print(f"wrote {os.path.abspath(md)}")
            return 0
        summary = shadows.run(out=args.output or "out/shadows", iterations=args.iterations or 150, spp=args.spp,
                              guiding=args.guiding)
        return 0 if summary["final_chamfer"] < summary["initial_chamfer"] else 1
    from .examples import multiview
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the summary lines about the sphere-free scene are not news here
        summary = multiview.run(out=args.output or "out/demo", iterations=args.iterations or 80, spp=args.spp)
    return 0 if summary["final_loss"] < summary["initial_loss"] else 1


def cmd_bench(args: argparse.Namespace) -> int:
    from .examples import bench
    md = bench.run(args.scene, args.param, args.methods.split(","), args.budgets, args.fd_spp, args.eps, args.out,
                   tangent=args.tangent, argv=args.argv, runs=args.runs)
    print(f"wrote {os.path.abspath(md)}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python3 -m limn", description="limn differentiable renderer")
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a scene description to an image")
    r.add_argument("scene", help="scene description (.json)")
    r.add_argument("-o", "--output", default="out.exr", help="output image (.exr, .hdr, .png, ...); default out.exr")
    r.add_argument("--spp", type=int, default=None, help="samples per pixel (default: the scene's sampler)")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--threads", type=int, default=0, help="worker threads (0: all cores)")
    r.add_argument("--no-preview", action="store_true", help="do not write a .png next to an .exr/.hdr output")
    r.set_defaults(func=cmd_render)
    d = sub.add_parser("demo", help="inverse shape optimisation demos with a known ground truth")
    d.add_argument("which", nargs="?", default="multiview", choices=["multiview", "shadows", "heightfield"],
                   help="multiview: a bumpy shape from three images (default); shadows: a shape from its two "
                        "shadows on a curved wall (scenes/shadow_wall); heightfield: the heightfield paper's "
                        "optimisations (--task)")
    d.add_argument("--task", default="terrain", choices=["terrain", "shadow_art", "two_lights"],
                   help="heightfield: terrain from four views, shadow art, or one field for two lights")
    d.add_argument("-o", "--output", default=None, help="folder for the result (PLY, renders, history.json); "
                                                        "default out/demo, out/shadows or out/heightfield")
    d.add_argument("--iterations", type=int, default=None, help="default 80 (multiview), 150 (shadows), 80 (heightfield)")
    d.add_argument("--spp", type=int, default=8)
    d.add_argument("--guiding", default="none", choices=["none", "grid"], help="shadows: boundary guiding")
    d.add_argument("--report", default=None, metavar="DIR",
                   help="shadows: run shadow term on/off and both guiding modes over several seeds, write "
                        "DIR/shadow_reconstruction.md; heightfield: all three tasks, write DIR/optimisation.md")
    d.add_argument("--seeds", type=int, default=3, help="with --report")
    d.set_defaults(func=cmd_demo)
    b = sub.add_parser("bench", help="gradient error against run time, against a finite-difference reference")
    b.add_argument("scene")
    b.add_argument("--param", required=True, help="parameter name, e.g. box.vertex_positions")
    b.add_argument("--tangent", default="x", choices=["x", "ones"], help="x: translate along x; ones: all ones")
    b.add_argument("--methods", default="interior,primary,full")
    b.add_argument("--budgets", type=int, nargs="+", default=[4, 16, 64])
    b.add_argument("--fd-spp", type=int, default=4096)
    b.add_argument("--eps", type=float, default=1e-2)
    b.add_argument("--runs", type=int, default=1, help="runs per method and budget (different seeds); errors are averaged")
    b.add_argument("--out", default="out/bench", metavar="DIR",
                   help="folder for the report: DIR/<scene>.md and DIR/<scene>.png; default out/bench")
    b.set_defaults(func=cmd_bench)
    args = parser.parse_args(argv)
    args.argv = list(argv if argv is not None else sys.argv[1:])
    try:
        return args.func(args)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, RenderCancelled):
        print("cancelled", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
