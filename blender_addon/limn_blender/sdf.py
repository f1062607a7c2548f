"""A mesh object optimised as a limn signed-distance grid (`sdfgrid`, issue 37), and the way back.

The object's mesh (its own vertices and triangles, in world space) is voxelised by
limn.sdf_from_mesh: `resolution` samples along its bounding box's longest side, the box grown by
`padding` times that side (room for the shape to grow). The grid replaces the mesh in the limn
scene, its values are optimised, and the result is written back into the same mesh by marching
cubes (limn.mesh_from_sdf: scikit-image, Debian's python3-skimage), replacing its vertices and
faces (materials stay; faces are flat shaded). The grid itself is not kept: a second run
voxelises the mesh again.

Voxelising runs on the optimisation's worker thread (it needs no bpy), cancellable like a render.

The optimisation (optimize_ops) steps the grid values with Adam at a learning rate given in voxels
per iteration (SdfSource.step_size: times the voxel size), on the gradient smoothed by the Sobolev
preconditioner (I + lambda L)^-1 of Large Steps on the grid (limn.sdf.smooth_gradient, lambda in
voxels^2), and redistances the grid every k iterations (limn.sdf.redistance, a brute-force
distance transform to exact points on the trilinear zero set, in world units), so that it stays a
distance field and a step of the values moves the surface by as much (|grad f| = 1)."""
from __future__ import annotations

import numpy as np

# Defaults of the panel and of optimize(mode="SDF"), chosen on the add-on test's ball (docs/blender.md).
LEARNING_RATE = 0.1    # voxels per iteration (Adam's step size, times the voxel)
SMOOTHING = 10.0       # lambda of the Sobolev preconditioner, voxels^2
REDISTANCE_EVERY = 5   # iterations between redistancings (0: never)


def _matrix(m) -> np.ndarray:
    return np.array([list(row) for row in m], dtype=np.float64)


class SdfSource:
    """The triangles of a mesh object in world space (main thread), voxelised later by voxelise()
    (any thread). Attributes: obj, vertices (N, 3) and faces (F, 3) in world space, resolution,
    padding, world (4 x 4), and after voxelise(): data, to_world, voxel."""

    def __init__(self, obj, resolution: int, padding: float, smoothing: float = SMOOTHING,
                 redistance_every: int = REDISTANCE_EVERY):
        if obj is None or obj.type != "MESH":
            raise ValueError(f"'{getattr(obj, 'name', obj)}' is not a mesh object; a limn SDF is made from a closed mesh")
        active = [m.name for m in obj.modifiers if m.show_render]
        if active:
            raise ValueError(f"object '{obj.name}': its modifiers ({', '.join(active)}) would be lost when the "
                             "optimised SDF is written back as a mesh; apply or remove them first")
        if not 2 <= int(resolution) <= 1024:
            raise ValueError(f"object '{obj.name}': SDF resolution must be within [2, 1024] samples (got {resolution})")
        if not (np.isfinite(smoothing) and smoothing >= 0):
            raise ValueError(f"object '{obj.name}': SDF smoothing must be >= 0 (got {smoothing})")
        if isinstance(redistance_every, bool) or int(redistance_every) != redistance_every or redistance_every < 0:
            raise ValueError(f"object '{obj.name}': SDF redistance interval must be an integer >= 0 (got {redistance_every})")
        self.smoothing, self.redistance_every = float(smoothing), int(redistance_every)
        self.steps = 0  # optimiser steps seen by project()
        self.redistanced = 0
        self.obj = obj
        self.label = f"object '{obj.name}'"  # for errors raised on the worker thread, which never touches bpy
        self.resolution, self.padding = int(resolution), float(padding)
        mesh = obj.data
        mesh.calc_loop_triangles()
        co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
        mesh.loop_triangles.foreach_get("vertices", tris)
        self.world = _matrix(obj.matrix_world)
        if abs(np.linalg.det(self.world[:3, :3])) == 0.0:
            raise ValueError(f"object '{obj.name}': its transform has a zero scale")
        self.vertices = co.reshape(-1, 3).astype(np.float64) @ self.world[:3, :3].T + self.world[:3, 3]
        self.faces = tris.reshape(-1, 3).astype(np.int64)
        if np.linalg.det(self.world[:3, :3]) < 0:  # mirrored object: keep the winding outward
            self.faces = self.faces[:, [0, 2, 1]]
        self.data = self.to_world = None
        self.voxel = 0.0

    def voxelise(self, limn, progress=None) -> None:
        """limn.sdf_from_mesh on the world-space triangles (any thread: no bpy); errors name the object."""
        g = limn.sdf_from_mesh(self.vertices, self.faces, self.resolution, self.padding, progress=progress,
                               name=self.label)
        self.data, self.to_world, self.voxel = g.data, g.to_world, g.voxel

    def step_size(self, lr: float) -> float:
        """Adam's learning rate in world units for ``lr`` voxels per iteration (after voxelise())."""
        return float(lr) * self.voxel

    def gradient(self, limn, grad: np.ndarray) -> np.ndarray:
        """The Sobolev-smoothed gradient (I + lambda L)^-1 grad of the grid values (any thread)."""
        return limn.sdf.smooth_gradient(grad, self.smoothing)

    def project(self, limn, x: np.ndarray) -> np.ndarray:
        """After each optimiser step: every ``redistance_every``-th call redistances the grid (world
        units: the box's extent from to_world), the others return x (any thread)."""
        self.steps += 1
        if self.redistance_every and self.steps % self.redistance_every == 0:
            self.redistanced += 1
            return limn.sdf.redistance(x, extent=np.diag(self.to_world)[:3])
        return x

    def shape(self, exported: dict) -> dict:
        """The sdfgrid that replaces the exported mesh shape (its material kept)."""
        if "emitter" in exported:
            raise ValueError(f"{self.label}: its material emits light, and a limn SDF cannot be an area emitter")
        return {"type": "sdfgrid", "data": self.data, "to_world": self.to_world.tolist(), "bsdf": exported["bsdf"]}

    def write_back(self, limn, data) -> None:
        """Marching cubes of the grid `data` into the object's mesh (local space), replacing its
        geometry. A grid without a surface (the shape vanished or filled the box) raises ValueError."""
        verts, faces = limn.mesh_from_sdf(np.asarray(data, dtype=np.float32).reshape(self.data.shape), self.to_world)
        inv = np.linalg.inv(self.world)
        local = verts @ inv[:3, :3].T + inv[:3, 3]
        if np.linalg.det(self.world[:3, :3]) < 0:
            faces = faces[:, ::-1]
        mesh = self.obj.data
        mesh.clear_geometry()
        mesh.from_pydata(local.astype(np.float32).tolist(), [], faces.tolist())
        mesh.validate(clean_customdata=False)
        mesh.update()
