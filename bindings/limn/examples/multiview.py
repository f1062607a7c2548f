"""The inverse shape optimisation demo: ``python3 -m limn demo``.

A bumpy ground-truth shape (an icosphere displaced along its normals) is rendered from three views
under an environment and a sun; the optimisation starts from the plain sphere with the same
topology and recovers the shape from the images alone (interior + primary-visibility + indirect
boundary derivatives, Adam with the Large-Steps preconditioner). Prints the image loss and the
geometric error (symmetric Chamfer distance between points sampled on both surfaces) as it goes and
writes the result (PLY and renders) to the output folder."""
from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

from .. import load_dict, optim, write_image, write_ply
from ..shapes import icosphere


def ground_truth(vertices: np.ndarray) -> np.ndarray:
    n = vertices / np.linalg.norm(vertices, axis=1, keepdims=True)
    bump = 0.18 * np.sin(3.0 * n[:, 0]) * np.cos(2.0 * n[:, 1]) + 0.12 * n[:, 2] ** 2
    return (vertices * (1.0 + bump)[:, None]).astype(np.float32)


def surface_points(vertices: np.ndarray, faces: np.ndarray, n: int = 3000, seed: int = 0) -> np.ndarray:
    """n points uniformly distributed over the mesh surface (area-weighted triangles)."""
    rng = np.random.default_rng(seed)
    v = vertices[faces].astype(np.float64)
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    tri = rng.choice(len(faces), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    b0, b1, b2 = 1 - s, s * (1 - r2), s * r2
    return b0[:, None] * v[tri, 0] + b1[:, None] * v[tri, 1] + b2[:, None] * v[tri, 2]


def chamfer(a: np.ndarray, b: np.ndarray) -> float:
    """Symmetric Chamfer distance between two point sets: mean nearest-neighbour distance, both ways."""
    def nearest(p, q):
        return np.concatenate([np.linalg.norm(p[i:i + 500, None] - q[None], axis=2).min(axis=1) for i in range(0, len(p), 500)])
    return float(0.5 * (nearest(a, b).mean() + nearest(b, a).mean()))


# Flat shading: its derivatives are complete here. Smooth shading would add a discontinuity the
# boundary terms do not sample yet (the one-sided BSDF's cut-off where the interpolated normal
# turns away from the camera next to the silhouette; docs/derivatives.md).
FLAT = True


def view(vertices, faces, origin, size):
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 35,
                   "to_world": {"look_at": {"origin": list(origin), "target": [0, 0, 0], "up": [0, 0, 1]}},
                   "film": {"type": "hdrfilm", "width": size, "height": size},
                   "sampler": {"type": "independent", "sample_count": 16}},
        "shape": {"type": "mesh", "vertex_positions": vertices, "faces": faces, "face_normals": FLAT,
                  "bsdf": {"type": "diffuse", "reflectance": [0.7, 0.55, 0.4]}},
        "sun": {"type": "directional", "direction": [-0.4, 0.6, -0.7], "irradiance": 2.5},
        "sky": {"type": "constant", "radiance": 0.25},
    }


def run(out: str = "out/demo", iterations: int = 80, size: int = 48, spp: int = 8, lr: float = 0.01,
        lambda_: float = 15.0, subdivisions: int = 2, verbose: bool = True) -> dict:
    os.makedirs(out, exist_ok=True)
    sphere, faces = icosphere(subdivisions)
    truth = ground_truth(sphere)
    origins = [(0, -4.5, 1.2), (3.9, 2.25, 1.2), (-3.9, 2.25, 1.2)]
    targets = [load_dict(view(truth, faces, o, size)).render(spp=256, seed=1000 + i) for i, o in enumerate(origins)]
    views = [(load_dict(view(sphere.copy(), faces, o, size)), t) for o, t in zip(origins, targets)]

    truth_points = surface_points(truth, faces)

    def geometric_error(x):
        return chamfer(surface_points(x, faces, seed=1), truth_points)

    history = []
    t0 = time.perf_counter()

    def report(it, loss, x):
        # The Chamfer distance costs about as much as an iteration: every 10 iterations only.
        err = geometric_error(x) if (it % 10 == 0 or it == iterations - 1) else None
        history.append({"iteration": it, "loss": loss, "chamfer": err, "seconds": time.perf_counter() - t0})
        if verbose and err is not None:
            print(f"iteration {it:4d}  loss {loss:.5f}  Chamfer {err:.4f}  {time.perf_counter() - t0:6.1f} s", flush=True)

    result = optim.fit(views, "shape.vertex_positions", iterations=iterations, lr=lr, lambda_=lambda_, spp=spp,
                       faces=faces, callback=report)
    final = views[0][0].params["shape.vertex_positions"].copy()
    summary = {"initial_chamfer": geometric_error(sphere), "final_chamfer": geometric_error(final),
               "initial_loss": result.losses[0], "final_loss": result.losses[-1],
               "seconds": time.perf_counter() - t0, "iterations": len(result.losses), "history": history}
    write_ply(os.path.join(out, "result.ply"), final, faces)
    write_ply(os.path.join(out, "ground_truth.ply"), truth, faces)
    for i, (s, t) in enumerate(views):
        write_image(os.path.join(out, f"view{i}_result.png"), s.render(spp=64))
        write_image(os.path.join(out, f"view{i}_target.png"), t)
    with open(os.path.join(out, "history.json"), "w") as f:
        json.dump(summary, f, indent=1)
    if verbose:
        print(f"loss {summary['initial_loss']:.5f} -> {summary['final_loss']:.5f}, Chamfer distance "
              f"{summary['initial_chamfer']:.4f} -> {summary['final_chamfer']:.4f} in {summary['seconds']:.1f} s; "
              f"wrote {os.path.abspath(out)}")
    return summary


if __name__ == "__main__":
    run()
    sys.exit(0)
