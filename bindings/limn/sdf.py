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
