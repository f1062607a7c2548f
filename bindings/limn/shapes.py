"""Small procedural meshes (numpy) for demos and tests."""
from __future__ import annotations

import numpy as np


def icosphere(subdivisions: int = 2, radius: float = 1.0):
    """Vertices (N x 3, float32) and faces (F x 3) of a geodesic sphere, counter-clockwise outward."""
    t = (1.0 + 5 ** 0.5) / 2.0
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6),
         (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7),
         (9, 8, 1)]
    verts = [np.array(p, dtype=np.float64) / np.linalg.norm(p) for p in v]
    faces = list(f)
    for _ in range(subdivisions):
        cache: dict = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = verts[a] + verts[b]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    return (np.array(verts) * radius).astype(np.float32), np.array(faces, dtype=np.int64)


# ---- heightfields: rows x columns arrays, row 0 at the far edge y = +1 (as limn's heightfield) ----
def _grid(n: int):
    x = np.linspace(-1.0, 1.0, n)
    return np.meshgrid(x, -x)


def cone_heights(n: int = 33, radius: float = 0.6) -> np.ndarray:
    """The heightfield paper's Figure 7 cone: 1 at the centre, 0 beyond `radius`."""
    X, Y = _grid(n)
    return np.maximum(0.0, 1.0 - np.sqrt(X ** 2 + Y ** 2) / radius).astype(np.float32)


def terrain_heights(n: int = 65, seed: int = 3) -> np.ndarray:
    """A smooth random terrain: a sum of a few waves, scaled to [0, 1]."""
    rng = np.random.default_rng(seed)
    X, Y = _grid(n)
    z = np.zeros_like(X)
    for _ in range(12):
        f = rng.uniform(1.0, 5.0)
        a = rng.uniform(0, 2 * np.pi)
        z += rng.uniform(0.3, 1.0) / f * np.sin(f * (np.cos(a) * X + np.sin(a) * Y) * np.pi + rng.uniform(0, 2 * np.pi))
    return ((z - z.min()) / (z.max() - z.min())).astype(np.float32)


def bump_heights(n: int = 65, sigma: float = 0.35) -> np.ndarray:
    """A Gaussian bump (Figure A2's worst case for the peak search)."""
    X, Y = _grid(n)
    return np.exp(-(X ** 2 + Y ** 2) / (2 * sigma ** 2)).astype(np.float32)


def bspline_at_grid(heights: np.ndarray) -> np.ndarray:
    """limn's heightfield surface (uniform cubic B-spline, edge rows repeated) at its grid points:
    1/6, 4/6, 1/6 of the neighbouring control heights in each direction."""
    p = np.pad(np.asarray(heights, np.float64), 1, mode="edge")
    rows = (p[:-2] + 4 * p[1:-1] + p[2:]) / 6.0
    return (rows[:, :-2] + 4 * rows[:, 1:-1] + rows[:, 2:]) / 6.0


def heightfield_as_mesh(heights: np.ndarray, size=(2.0, 2.0), height_scale: float = 1.0):
    """Vertices (N x 3, float32, local frame) and faces (F x 3, facing +z) of a heightfield's surface
    sampled at its grid points: the same surface as a triangle mesh (for comparisons and export)."""
    from .optim import grid_faces
    n_r, n_c = np.shape(heights)
    x = (np.arange(n_c) / (n_c - 1) - 0.5) * size[0]
    y = (0.5 - np.arange(n_r) / (n_r - 1)) * size[1]
    X, Y = np.meshgrid(x, y)
    Z = height_scale * bspline_at_grid(heights)
    return np.stack([X, Y, Z], -1).reshape(-1, 3).astype(np.float32), grid_faces(n_r, n_c)
