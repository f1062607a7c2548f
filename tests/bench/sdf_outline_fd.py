"""The outline of a black 16^3 bumpy SDF ball against a constant sky (the image is 1 - coverage, so
its derivative is the primary term alone), seen from where the outline runs along voxel faces and
nearly along the graph lines of some voxels: the primary term's image sum against central
differences at high precision (docs/derivatives.md, "SDF grids in the primary term").

  .venv/bin/python tests/bench/sdf_outline_fd.py [--seeds 16] [--fd-spp 16384] [--spp 8192]

Prints the sums with their standard errors, the largest block z-score and the pixels farthest off.
Takes about 15 minutes on a loaded 2-core machine at the defaults.
"""
from __future__ import annotations

import argparse
import os
import sys
import warnings

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
import limn  # noqa: E402
from test_derivatives import block_z  # noqa: E402
from test_sdfgrid import ball, random_tangent  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=16)
    ap.add_argument("--fd-spp", type=int, default=16384)
    ap.add_argument("--spp", type=int, default=8192, help="primary-term samples per pixel")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    scene = limn.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 2},
        "sensor": {"type": "perspective", "fov": 20, "film": {"type": "hdrfilm", "width": 16, "height": 16},
                   "to_world": {"look_at": {"origin": [0, -4, 3], "target": [0.4, 0.2, 1.2], "up": [0, 0, 1]}}},
        "sky": {"type": "constant", "radiance": 1.0},
        "blob": {"type": "sdfgrid", "data": ball(16), "to_world": [{"translate": [-0.5, -0.5, -0.5]}, {"translate": [0.4, 0.2, 1.2]}],
                 "bsdf": {"type": "diffuse", "reflectance": 0.0}}})
    name = "blob.data"
    scene.set_differentiable([name])
    t = random_tangent(scene, name, 3)
    fd = np.stack([limn.fd(scene, {name: t}, eps=2e-3, spp=args.fd_spp, seed=k, cache=False) for k in range(args.seeds)])
    est = np.stack([scene.render_forward({name: t}, seed=50 + k, spp=4, spp_boundary=0, spp_primary=args.spp) for k in range(args.seeds)])
    a, b = est.sum(axis=(1, 2, 3)), fd.sum(axis=(1, 2, 3))
    n = np.sqrt(args.seeds)
    print(f"primary term {a.mean():.2f} +- {a.std(ddof=1) / n:.2f}, FD {b.mean():.2f} +- {b.std(ddof=1) / n:.2f} "
          f"(ratio {a.mean() / b.mean():.4f}); max block |z| {np.abs(block_z(est, fd)).max():.2f}")
    d = est.mean(0)[..., 0] - fd.mean(0)[..., 0]
    se = np.sqrt(est.var(0, ddof=1)[..., 0] / args.seeds + fd.var(0, ddof=1)[..., 0] / args.seeds) + 1e-12
    for flat in np.argsort(-np.abs(d / se).ravel())[:4]:
        p = np.unravel_index(flat, d.shape)
        print(f"  pixel {tuple(int(i) for i in p)}: {est.mean(0)[p][0]:.3f} against FD {fd.mean(0)[p][0]:.3f} (z {(d / se)[p]:.1f})")


if __name__ == "__main__":
    main()
