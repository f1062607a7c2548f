"""limn.sdf_from_mesh and limn.mesh_from_sdf (issue 37): a mesh's signed-distance grid against the
exact distance of the sphere it approximates, its placement (the sdfgrid it feeds renders where
the mesh does), the marching-cubes round trip (volume, centroid, outward winding, also under a
mirroring to_world) and bad input."""
from __future__ import annotations

import numpy as np
import pytest

import limn
from conftest import camera
from limn.shapes import icosphere


def sphere_mesh(radius=0.5, centre=(0.1, -0.2, 0.3), subdivisions=3):
    v, f = icosphere(subdivisions, radius)
    return v.astype(np.float64) + np.asarray(centre), f


def grid_points(g):
    nz, ny, nx = g.data.shape
    z, y, x = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    local = np.stack([x / (nx - 1), y / (ny - 1), z / (nz - 1)], axis=-1)
    return local @ g.to_world[:3, :3].T + g.to_world[:3, 3]


def volume_and_centroid(v, f):
    """Enclosed signed volume and centroid of a closed triangle mesh (divergence theorem)."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    vol6 = np.einsum("ij,ij->i", a, np.cross(b, c))
    return vol6.sum() / 6, (vol6[:, None] * (a + b + c)).sum(0) / (4 * vol6.sum())


def test_distances_of_a_sphere_mesh_are_within_its_chord_error():
    centre, r = np.array([0.1, -0.2, 0.3]), 0.5
    v, f = sphere_mesh(r, centre)
    g = limn.sdf_from_mesh(v, f, resolution=24, padding=0.2)
    assert g.data.dtype == np.float32 and g.data.ndim == 3 and g.sign_disagreements == 0
    # Vertices lie on the sphere, faces inside it: the surfaces are within H = r - (the closest
    # face plane's distance to the centre), and so are their signed distances.
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    H = r - np.min(np.abs(np.einsum("ij,ij->i", n / np.linalg.norm(n, axis=1)[:, None], v[f[:, 0]] - centre)))
    assert 0 < H < 0.01
    exact = np.linalg.norm(grid_points(g) - centre, axis=-1) - r
    err = np.abs(g.data - exact).max()
    print(f"sdf_from_mesh: 24 samples across, H = {H:.5f}, worst error {err:.5f}")
    assert err <= H + 1e-6  # 1e-6: float storage
    assert (g.data < 0).sum() > 0 and ((g.data < 0) == (exact < 0))[np.abs(exact) > H].all()


def test_grid_layout_is_z_y_x_and_to_world_places_it():
    """A box twice as long in x as in y and z: more samples along x, the last array axis; the
    sdfgrid built from it renders the box as the mesh does."""
    lo, hi = np.array([-0.6, -0.3, -0.3]), np.array([0.6, 0.3, 0.3])
    corners = np.array([[hi[0] if i & 1 else lo[0], hi[1] if i & 2 else lo[1], hi[2] if i & 4 else lo[2]] for i in range(8)])
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    faces = np.array([t for q in quads for t in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))])
    g = limn.sdf_from_mesh(corners, faces, resolution=25, padding=0.1)
    nz, ny, nx = g.data.shape
    assert nx == 25 and ny == nz and ny < nx
    bsdf = {"type": "diffuse", "reflectance": 0.5}
    def coverage(shape):
        d = {"type": "scene", "integrator": {"type": "path", "max_depth": 2},
             "sensor": camera((0.4, -3, 1.2), (0, 0, 0), fov=35, width=48, height=32, spp=4),
             "obj": shape, "sky": {"type": "constant", "radiance": 1.0}}
        return limn.load_dict(d).render(seed=0)[..., 0] < 0.9
    mesh = coverage({"type": "mesh", "vertex_positions": corners, "faces": faces, "face_normals": True, "bsdf": bsdf})
    grid = coverage({"type": "sdfgrid", "data": g.data, "to_world": g.to_world.tolist(), "bsdf": bsdf})
    assert mesh.sum() > 200
    # The trilinear box has rounded edges within a voxel of the mesh's: the silhouettes differ by a
    # pixel-wide band at most (48 pixels span ~1.9 units here, a voxel is 0.06 units).
    differ = (mesh != grid).sum()
    print(f"box coverage: mesh {mesh.sum()} px, sdfgrid {grid.sum()} px, {differ} differ")
    assert differ < 0.1 * mesh.sum()


@pytest.mark.parametrize("mirror", [False, True])
def test_marching_cubes_round_trip_keeps_volume_centroid_and_faces_outwards(mirror):
    centre, r = np.array([0.1, -0.2, 0.3]), 0.5
    v, f = sphere_mesh(r, centre)
    g = limn.sdf_from_mesh(v, f, resolution=40)
    to_world = g.to_world.copy()
    if mirror:  # the same box, x reversed: local x -> 1 - x
        to_world[:3, 3] += to_world[:3, 0]
        to_world[:3, 0] *= -1
    data = g.data[:, :, ::-1].copy() if mirror else g.data
    mv, mf = limn.mesh_from_sdf(data, to_world)
    vol, cen = volume_and_centroid(mv, mf)
    vol0, cen0 = volume_and_centroid(v, f)
    print(f"round trip: volume {vol:.5f} (mesh {vol0:.5f}), centroid {cen} (mesh {cen0})")
    # Marching cubes cuts corners of the trilinear surface: a voxel is 1.2 / 39 = 0.031, the
    # volume is within 2 % (measured 0.4 %), the centroid within a tenth of a voxel.
    assert vol == pytest.approx(vol0, rel=0.02)
    assert np.abs(cen - cen0).max() < 0.003
    assert np.abs(np.linalg.norm(mv - centre, axis=1) - r).max() < 0.5 * g.voxel


def test_bad_input_is_refused_naming_the_mesh():
    v, f = sphere_mesh()
    with pytest.raises(ValueError, match="ball: the mesh has no triangles"):
        limn.sdf_from_mesh(np.zeros((0, 3)), np.zeros((0, 3), int), 8, name="ball")
    bad = v.copy()
    bad[5, 1] = np.nan
    with pytest.raises(ValueError, match="vertex 5 has a non-finite coordinate"):
        limn.sdf_from_mesh(bad, f, 8)
    for res in (1, 0, -3, 5000):
        with pytest.raises(ValueError, match=rf"resolution must be within \[2, 1024\].*got {res}\)"):
            limn.sdf_from_mesh(v, f, res)
    with pytest.raises(ValueError, match="resolution must be an integer"):
        limn.sdf_from_mesh(v, f, 8.5)
    with pytest.raises(ValueError, match="faces must be integers"):
        limn.sdf_from_mesh(v, f.astype(float), 8)
    with pytest.raises(ValueError, match="not closed and consistently oriented"):
        limn.sdf_from_mesh(v, f[1:], 8)
    with pytest.raises(ValueError, match=r"vertices must have shape \(N, 3\)"):
        limn.sdf_from_mesh(v[:, :2], f, 8)
    with pytest.raises(ValueError, match="padding"):
        limn.sdf_from_mesh(v, f, 8, padding=-1)


def test_progress_cancels_and_its_errors_propagate():
    v, f = sphere_mesh()
    seen = []
    with pytest.raises(limn.RenderCancelled):
        limn.sdf_from_mesh(v, f, 16, progress=lambda x: seen.append(x) or len(seen) < 2)
    assert len(seen) == 2
    def boom(_):
        raise KeyError("from the callback")
    with pytest.raises(KeyError, match="from the callback"):
        limn.sdf_from_mesh(v, f, 16, progress=boom)


def test_mesh_from_sdf_refuses_grids_without_a_surface():
    with pytest.raises(ValueError, match="holds no surface"):
        limn.mesh_from_sdf(np.ones((4, 4, 4), np.float32), np.eye(4))
    with pytest.raises(ValueError, match="non-finite"):
        limn.mesh_from_sdf(np.full((4, 4, 4), np.nan, np.float32), np.eye(4))
    with pytest.raises(ValueError, match="invertible"):
        limn.mesh_from_sdf(np.linspace(-1, 1, 64).reshape(4, 4, 4), np.zeros((4, 4)))
