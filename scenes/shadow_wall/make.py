"""Regenerates the meshes of scenes/shadow_wall: `python3 scenes/shadow_wall/make.py`.

wall.ply: a 120-degree section of a cylinder (radius 4, axis along z through y = -1), facing the
object; initial.ply: an icosphere of radius 0.5 (162 vertices); truth.ply: the same icosphere
stretched and bent (the shape the demo recovers from its shadows)."""
import os

import numpy as np

import limn
from limn.shapes import icosphere

here = os.path.dirname(os.path.abspath(__file__))


def wall(nphi=24, nz=22, radius=4.0):
    phi = np.linspace(-np.pi / 3, np.pi / 3, nphi + 1)
    z = np.linspace(-8.0, 3.0, nz + 1)
    P, Z = np.meshgrid(phi, z, indexing="ij")
    v = np.stack([radius * np.sin(P), -1 + radius * np.cos(P), Z], -1).reshape(-1, 3).astype(np.float32)
    f = []
    for i in range(nphi):
        for j in range(nz):
            a, b = i * (nz + 1) + j, (i + 1) * (nz + 1) + j
            f += [[a, a + 1, b + 1], [a, b + 1, b]]
    return v, np.int32(f)


def truth(v):
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    return np.stack([1.35 * x, 0.75 * y, 0.8 * z + 0.35 * x * x - 0.1], 1).astype(np.float32)


if __name__ == "__main__":
    sphere, faces = icosphere(2, 0.5)
    limn.write_ply(os.path.join(here, "wall.ply"), *wall())
    limn.write_ply(os.path.join(here, "initial.ply"), sphere, faces)
    limn.write_ply(os.path.join(here, "truth.ply"), truth(sphere), faces)
