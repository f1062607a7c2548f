"""Signed-distance grids from meshes and back (issue 37).

    data, to_world = limn.sdf_from_mesh(vertices, faces, resolution=64)[:2]
    scene_dict["shape"] = {"type": "sdfgrid", "data": data, "to_world": to_world, ...}
    vertices, faces = limn.mesh_from_sdf(data, to_world)

sdf_from_mesh voxelises in C++ (core/io/sdf_from_mesh.h: Embree point queries for the
distance, ray parity along three directions for the sign); mesh_from_sdf is scikit-image's
marching cubes (Debian: python3-skimage), placed with the grid's corner-sample convention."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from . import _core


class MeshSdf(NamedTuple):
    data: np.ndarray          # (nz, ny, nx) float32 signed distances in the mesh's units, < 0 inside
    to_world: np.ndarray      # (4, 4): the unit cube [0,1]^3 onto the grid's box (translation, scale)
    voxel: float              # sample spacing (world units; voxels are cubes)
    sign_disagreements: int   # samples where the three parity rays disagreed (majority taken)


def sdf_from_mesh(vertices, faces, resolution: int = 64, padding: float = 0.1, progress=None,
                  name: str = "mesh") -> MeshSdf:
    """Signed distances of the closed triangle mesh (vertices (N, 3), faces (F, 3) indices) on the
    corners of a grid of cubic voxels: ``resolution`` samples along the bounding box's longest
    side, the box grown by ``padding`` times that side on every side, the grid centred on the
    mesh. The mesh must be closed and consistently oriented (every edge shared by two triangles in
    opposite directions); ValueError otherwise, and for empty meshes, non-finite vertices,
    resolution outside [2, 1024]. ``progress(fraction)`` returning False cancels
    (limn.RenderCancelled); ``name`` names the mesh in errors. Returns a MeshSdf whose ``data``
    and ``to_world`` are an ``sdfgrid`` shape's (data indexed [z, y, x])."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if f.size and not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"sdf_from_mesh: {name}: faces must be integers (got dtype {f.dtype})")
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)):
        raise ValueError(f"sdf_from_mesh: {name}: resolution must be an integer (got {resolution!r})")
    data, origin, extent, voxel, disagreements = _core.sdf_from_mesh(
        v.reshape(-1, 3) if v.size == 0 else v, f.astype(np.int64).reshape(-1, 3) if f.size == 0 else f.astype(np.int64),
        int(resolution), float(padding), name, progress)
    to_world = np.eye(4)
    to_world[:3, :3] = np.diag(extent)
    to_world[:3, 3] = origin
    return MeshSdf(data, to_world, float(voxel), int(disagreements))


def mesh_from_sdf(data, to_world, level: float = 0.0):
    """The surface f = level of an ``sdfgrid`` (data indexed [z, y, x], corner samples over the
    unit cube, ``to_world`` 4 x 4) as a triangle mesh: (vertices (N, 3) float64 in world space,
    faces (F, 3) int64), counter-clockwise seen from outside (f > level). Marching cubes
    (scikit-image); where the surface reaches the grid's faces the mesh is open, as the sdfgrid
    shape is. ValueError when the grid holds no surface."""
    try:
        from skimage.measure import marching_cubes
    except ImportError as e:
        raise ImportError("limn.mesh_from_sdf needs scikit-image (Debian: apt install python3-skimage; "
                          f"pip: scikit-image): {e}") from None
    f = np.asarray(data, dtype=np.float32)
    if f.ndim != 3 or min(f.shape) < 2:
        raise ValueError(f"mesh_from_sdf: data must be a 3D array with at least 2 samples per axis (got shape {f.shape})")
    if not np.isfinite(f).all():
        raise ValueError("mesh_from_sdf: data holds non-finite values")
    m = np.asarray(to_world, dtype=np.float64)
    if m.shape != (4, 4) or not np.isfinite(m).all() or abs(np.linalg.det(m[:3, :3])) == 0.0:
        raise ValueError(f"mesh_from_sdf: to_world must be an invertible finite 4 x 4 matrix (got shape {m.shape})")
    if not (f.min() < level < f.max()):
        raise ValueError(f"mesh_from_sdf: the grid holds no surface: its values lie in [{f.min():g}, {f.max():g}], "
                         f"level {level:g} is not strictly inside")
    nz, ny, nx = f.shape
    # Array axes are (z, y, x); spacing puts vertices in local unit-cube coordinates (corner samples).
    verts, faces, _, _ = marching_cubes(f, level=level, spacing=(1.0 / (nz - 1), 1.0 / (ny - 1), 1.0 / (nx - 1)),
                                        allow_degenerate=False)
    local = verts[:, ::-1].astype(np.float64)  # (z, y, x) -> (x, y, z)
    world = local @ m[:3, :3].T + m[:3, 3]
    faces = faces.astype(np.int64)
    # With scikit-image's default winding and the axes reversed to (x, y, z), the triangles face
    # the inside of a surface with f < 0 inside; reversed, they face out (the enclosed volume's sign
    # is checked in tests/python/test_sdf_from_mesh.py). A mirroring to_world reverses them again.
    faces = faces[:, ::-1].copy()
    if np.linalg.det(m[:3, :3]) < 0:
        faces = faces[:, ::-1].copy()
    return world, faces


# ---- the zero set, redistancing and gradient smoothing of a grid's values ---------------------------
# Used by the optimisations of sdfgrid values (tests/bench/sdf_optimise.py, the Blender add-on's SDF
# mode). Grids are indexed [z, y, x] with corner samples over the unit cube (docs/scene-format.md);
# points are local (x, y, z) in [0, 1]^3. ``extent`` (x, y, z), where a function takes it, is the
# box's size in world units (the diagonal of an axis-aligned ``to_world``), so that distances are
# world distances; None: local units (the unit cube).

def _upsample(a: np.ndarray, axis: int, m: int) -> np.ndarray:
    """Linear interpolation along ``axis`` at m - 1 extra points per interval (exact for a trilinear field)."""
    n = a.shape[axis]
    t = np.arange((n - 1) * m + 1) / m
    i = np.minimum(t.astype(int), n - 2)
    w = (t - i).reshape([-1 if k == axis else 1 for k in range(a.ndim)])
    return np.take(a, i, axis) * (1 - w) + np.take(a, i + 1, axis) * w


def upsample(data: np.ndarray) -> np.ndarray:
    """The same trilinear field on a grid with twice the voxels per axis (n -> 2n - 1 samples):
    the old corners stay, the new ones are the interpolant's values (exact, the surface is unchanged)."""
    a = data.astype(np.float64)
    for axis in range(3):
        a = _upsample(a, axis, 2)
    return a.astype(data.dtype)


def zero_set(data: np.ndarray, m: int = 3) -> np.ndarray:
    """Points (P, 3), local (x, y, z) in [0, 1]^3, on the zero set of the trilinear interpolant of
    ``data`` ([z, y, x]): the exact roots on lines parallel to each axis, m lines per voxel and
    direction of the other two axes (along such a line the interpolant is piecewise linear)."""
    f = data.astype(np.float64)
    size = np.array(f.shape[::-1], dtype=np.float64) - 1  # voxels along x, y, z
    points = []
    for axis in range(3):  # array axis: 0 = z, 1 = y, 2 = x
        a = f
        for other in range(3):
            if other != axis:
                a = _upsample(a, other, m)
        a = np.moveaxis(a, axis, -1)
        f0, f1 = a[..., :-1], a[..., 1:]
        cross = (f0 < 0) != (f1 < 0)  # f < 0 is inside (docs/scene-format.md)
        idx = np.nonzero(cross)
        t = f0[idx] / (f0[idx] - f1[idx])  # the root of the linear piece
        coords = [None, None, None]  # array-axis coordinates in samples
        rest = [k for k in range(3) if k != axis]
        coords[rest[0]] = idx[0] / m
        coords[rest[1]] = idx[1] / m
        coords[axis] = idx[2] + t
        points.append(np.stack([coords[2], coords[1], coords[0]], axis=1) / size)
    return np.concatenate(points) if points else np.zeros((0, 3))


def trilinear_gradient(data: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Gradient (P, 3) of the trilinear interpolant of ``data`` at local points p (P, 3), per local unit."""
    f = data.astype(np.float64)
    size = np.array(f.shape[::-1], dtype=np.float64) - 1
    q = np.clip(p * size, 0, size)
    i = np.minimum(q.astype(int), (size - 1).astype(int))
    u, v, w = (q - i).T
    x, y, z = i.T
    c = lambda dz, dy, dx: f[z + dz, y + dy, x + dx]
    # d/du of sum_corners f * (u or 1-u)(v or 1-v)(w or 1-w), likewise v, w
    gx = ((c(0, 0, 1) - c(0, 0, 0)) * (1 - v) * (1 - w) + (c(0, 1, 1) - c(0, 1, 0)) * v * (1 - w)
          + (c(1, 0, 1) - c(1, 0, 0)) * (1 - v) * w + (c(1, 1, 1) - c(1, 1, 0)) * v * w)
    gy = ((c(0, 1, 0) - c(0, 0, 0)) * (1 - u) * (1 - w) + (c(0, 1, 1) - c(0, 0, 1)) * u * (1 - w)
          + (c(1, 1, 0) - c(1, 0, 0)) * (1 - u) * w + (c(1, 1, 1) - c(1, 0, 1)) * u * w)
    gz = ((c(1, 0, 0) - c(0, 0, 0)) * (1 - u) * (1 - v) + (c(1, 0, 1) - c(0, 0, 1)) * u * (1 - v)
          + (c(1, 1, 0) - c(0, 1, 0)) * (1 - u) * v + (c(1, 1, 1) - c(0, 1, 1)) * u * v)
    return np.stack([gx, gy, gz], axis=1) * size


def nearest(queries: np.ndarray, points: np.ndarray):
    """Index of and distance to the nearest of ``points`` for every query (exact; brute force in
    chunks, or scipy's k-d tree when scipy is installed)."""
    try:
        from scipy.spatial import cKDTree
    except ImportError:
        cKDTree = None
    if cKDTree is not None:
        d, j = cKDTree(points).query(queries)
        return j, d
    j = np.empty(len(queries), dtype=np.int64)
    pp = (points * points).sum(axis=1)
    for s in range(0, len(queries), 512):
        q = queries[s:s + 512]
        # |q - p|^2 = |q|^2 - 2 q.p + |p|^2; |q|^2 is the same for every p: left out of the argmin
        j[s:s + 512] = (pp[None, :] - 2.0 * (q @ points.T)).argmin(axis=1)
    return j, np.linalg.norm(queries - points[j], axis=1)


def _extent(extent, name: str):
    if extent is None:
        return None
    e = np.asarray(extent, dtype=np.float64).reshape(-1)
    if e.shape != (3,) or not np.isfinite(e).all() or (e <= 0).any():
        raise ValueError(f"{name}: extent must be three finite sizes > 0 (x, y, z; got {extent!r})")
    return e


def redistance(data: np.ndarray, m: int = 3, extent=None) -> np.ndarray:
    """The signed distance from every grid corner to the zero set of the trilinear interpolant of
    ``data``, with the sign of ``data``: a brute-force distance transform. Points on the zero set
    are found exactly on m lines per voxel and axis (:func:`zero_set`); every value becomes the
    distance to the nearest of them, except at nodes with a sign change to a neighbour along an
    axis, which take the distance to the tangent plane at their nearest point (the point spacing
    would otherwise move the zero set by up to half that spacing). Each pass re-samples the
    surface trilinearly, which moves a convex part of curvature radius r inwards by up to
    h^2 / (8 r) (h the voxel). Distances in local units, or in world units when ``extent`` gives
    the box's size (x, y, z). A grid without a zero crossing is returned unchanged."""
    scale = _extent(extent, "redistance")
    f = data.astype(np.float64)
    if not np.isfinite(f).all():
        raise ValueError("redistance: the grid holds non-finite values")
    pts = zero_set(f, m)
    if len(pts) == 0:
        return data.copy()
    nz, ny, nx = f.shape
    z, y, x = np.meshgrid(np.linspace(0, 1, nz), np.linspace(0, 1, ny), np.linspace(0, 1, nx), indexing="ij")
    nodes = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    local = pts
    if scale is not None:  # world units
        nodes, pts = nodes * scale, pts * scale
    j, dist = nearest(nodes, pts)
    inside = f < 0
    band = np.zeros_like(inside)
    for axis in range(3):
        change = np.diff(inside, axis=axis)
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        band[tuple(lo)] |= change
        band[tuple(hi)] |= change
    b = band.ravel()
    g = trilinear_gradient(f, local[j[b]])
    if scale is not None:
        g = g / scale  # per world unit
    norm = np.linalg.norm(g, axis=1)
    ok = norm > 1e-12  # a flat spot: keep the point distance (no plane to measure to)
    plane = np.abs(((nodes[b] - pts[j[b]]) * g).sum(axis=1)) / np.where(ok, norm, 1.0)
    dist_b = dist[b]
    dist_b[ok] = np.minimum(plane[ok], dist_b[ok])  # the plane distance never exceeds the point distance
    dist[b] = dist_b
    out = np.where(inside.ravel(), -dist, dist).reshape(f.shape)
    return out.astype(data.dtype)


def gradient_norm(data: np.ndarray, extent=None) -> np.ndarray:
    """|grad f| by central differences at the interior corners (per local unit, or per world unit
    with ``extent``), shaped (nz-2, ny-2, nx-2)."""
    scale = _extent(extent, "gradient_norm")
    f = data.astype(np.float64)
    h = [1.0 / (n - 1) for n in f.shape]
    if scale is not None:
        h = [hz * s for hz, s in zip(h, scale[::-1])]  # array axes are z, y, x
    gz = (f[2:, 1:-1, 1:-1] - f[:-2, 1:-1, 1:-1]) / (2 * h[0])
    gy = (f[1:-1, 2:, 1:-1] - f[1:-1, :-2, 1:-1]) / (2 * h[1])
    gx = (f[1:-1, 1:-1, 2:] - f[1:-1, 1:-1, :-2]) / (2 * h[2])
    return np.sqrt(gx * gx + gy * gy + gz * gz)


def distance_field_error(data: np.ndarray, extent=None) -> float:
    """Median of | |grad f| - 1 | over the interior corners more than two voxels from the zero set
    (by |f|), where central differences straddle no surface: 0 for a distance field (in the units
    of ``extent``, as :func:`gradient_norm`; NaN when no corner is that far)."""
    scale = _extent(extent, "distance_field_error")
    g = gradient_norm(data, extent)
    # two voxels along z (local units: the bench's expression, unchanged)
    limit = 2.0 / (data.shape[0] - 1) if scale is None else 2.0 * float(scale[2]) / (data.shape[0] - 1)
    far = np.abs(data[1:-1, 1:-1, 1:-1]) > limit
    return float(np.median(np.abs(g[far] - 1))) if far.any() else float("nan")


def smooth_gradient(grad: np.ndarray, lambda_: float) -> np.ndarray:
    """(I + lambda L)^-1 grad on the grid, L the 7-point Laplacian in voxel units: the Sobolev
    preconditioner of Large Steps (Nicolet et al. 2021, Eq. 7) on grid values instead of vertices,
    solved exactly by FFT. Periodic wrap-around at the grid's faces: the gradient is zero there
    (the surface stays inside the cube), so the wrap only couples zeros. lambda 0: unchanged."""
    if lambda_ <= 0:
        return grad
    eig = 0.0
    for axis, n in enumerate(grad.shape):
        k = 2.0 - 2.0 * np.cos(2.0 * np.pi * np.arange(n) / n)  # eigenvalues of the 1D periodic Laplacian
        eig = eig + k.reshape([-1 if a == axis else 1 for a in range(grad.ndim)])
    return np.real(np.fft.ifftn(np.fft.fftn(grad) / (1.0 + lambda_ * eig)))
