"""Primary-visibility boundary term: silhouettes seen directly by the camera."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import limn
from conftest import camera
from test_derivatives import block_z

W, FOV, D = 32, 30.0, 4.0


def emitting(shape):
    return {"type": "scene", "integrator": {"type": "path", "max_depth": 1},
            "sensor": camera((0, -D, 0), (0, 0, 0), fov=FOV, width=W, height=W, spp=16), "obj": shape}


def pixels_per_unit_on_plane_at_D():
    return W / (2 * np.tan(np.radians(FOV) / 2)) / D


def quiet(fn, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kw)


@pytest.mark.term("primary")
def test_sphere_silhouette_matches_the_analytic_derivative():
    """An emitting sphere against black: the image is L times its projected area, so the sum of the
    derivative image is L dA/dr (the interior term is zero here)."""
    r, L = 0.7, 2.0
    scene = limn.load_dict(emitting({"type": "sphere", "radius": r, "emitter": {"type": "area", "radiance": L}}))
    scene.set_differentiable(["obj.radius"])
    f = quiet(scene.render_forward, {"obj.radius": np.float32(1.0)}, spp_interior=4, spp_primary=16, seed=0)
    tx = np.tan(np.radians(FOV) / 2)
    # Projected disk: tan(alpha) = r / sqrt(D^2 - r^2) on the z = 1 plane; A = pi tan^2 (W / 2 tx)^2.
    dA = np.pi * (W / (2 * tx)) ** 2 * 2 * r * D * D / (D * D - r * r) ** 2
    assert f[..., 0].sum() == pytest.approx(L * dA, rel=1e-4)
    off = quiet(scene.render_forward, {"obj.radius": np.float32(1.0)}, spp_interior=4, spp_primary=0, seed=0)
    assert abs(off.sum()) < 1e-3 * L * dA  # switched off, nothing is left: the whole effect is the boundary


@pytest.mark.term("primary")
def test_mesh_silhouette_matches_the_analytic_derivative():
    """An emitting square facing the camera, scaled about its centre: d(area)/d(scale) = 2 area."""
    L = 2.0
    scene = limn.load_dict(emitting({"type": "rectangle", "to_world": [{"scale": 0.5}, {"rotate": {"axis": [1, 0, 0], "angle": 90}}],
                                     "emitter": {"type": "area", "radiance": L}}))
    v = scene.params["obj.vertex_positions"]
    scene.set_differentiable(["obj.vertex_positions"])
    f = quiet(scene.render_forward, {"obj.vertex_positions": v.copy()}, spp_interior=4, spp_primary=16, seed=0)
    area = (1.0 * pixels_per_unit_on_plane_at_D()) ** 2
    assert f[..., 0].sum() == pytest.approx(L * 2 * area, rel=1e-4)
    assert any("silhouette curves" in line for line in scene.last_stats["summary"])


def envmap_scene(tmp_path, shape):
    env = np.ones((16, 32, 3), np.float32) * np.linspace(0.2, 1.0, 16)[:, None, None]
    limn.write_image(tmp_path / "sky.exr", env)
    return {"type": "scene", "integrator": {"type": "path", "max_depth": 3},
            "sensor": camera((0, -4, 0), (0, 0, 0), fov=35, width=16, height=16, spp=64),
            "obj": shape, "sky": {"type": "envmap", "filename": "sky.exr", "to_world": {"rotate": {"axis": [1, 0, 0], "angle": 90}}}}


SHAPES = {
    "sphere": ({"type": "sphere", "radius": 0.8, "bsdf": {"type": "diffuse", "reflectance": 0.3}}, "obj.center"),
    "cube": ({"type": "cube", "to_world": [{"scale": 0.6}, {"rotate": {"axis": [1, 1, 0], "angle": 30}}],
              "bsdf": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.2}}, "obj.vertex_positions"),
}


@pytest.mark.term("primary")
@pytest.mark.parametrize("kind", list(SHAPES))
def test_silhouettes_against_finite_differences(tmp_path, kind):
    """A convex object alone in an environment: moving it changes only what the camera sees
    directly (no shadows, no reflections of it), so interior + primary must agree with FD; the
    same check fails with the primary term switched off."""
    shape, name = SHAPES[kind]
    scene = limn.load_dict(envmap_scene(tmp_path, shape), base_dir=tmp_path)
    t = np.zeros_like(scene.params[name])
    t[..., 0], t[..., 2] = 1.0, 0.3
    scene.set_differentiable([name])
    fd = np.stack([limn.fd(scene, {name: t}, eps=2e-2, spp=1024, seed=30 + k, cache=False) for k in range(6)])
    on = np.stack([quiet(scene.render_forward, {name: t}, spp=128, spp_primary=128, seed=40 + k) for k in range(6)])
    off = np.stack([quiet(scene.render_forward, {name: t}, spp=128, spp_primary=0, seed=40 + k) for k in range(6)])
    z_on, z_off = block_z(on, fd), block_z(off, fd)
    assert np.abs(z_on).max() < 4.5, z_on
    assert np.abs(z_off).max() > 10, z_off  # without the boundary term the silhouettes' blocks are far off


def sphere_behind_a_wall(wall_x):
    """The emitting sphere (radius 0.5, L = 2) before a sky of radiance 1, and a wall between it and
    the camera covering world x < wall_x + 3 (image left is world -x): wall_x = 0 covers the whole
    view, -3 the image's left half exactly (its edge projects onto the centre column), None: no wall."""
    d = {**emitting({"type": "sphere", "radius": 0.5, "emitter": {"type": "area", "radiance": 2.0}}),
         "sky": {"type": "constant", "radiance": 1.0}}
    if wall_x is not None:
        d["wall"] = {"type": "rectangle", "to_world": [{"scale": 3}, {"rotate": {"axis": [1, 0, 0], "angle": 90}},
                                                       {"translate": [wall_x, -1.5, 0]}],
                     "bsdf": {"type": "diffuse", "reflectance": 0.5}}
    return limn.load_dict(d)


@pytest.mark.term("primary")
def test_occluded_silhouettes_contribute_nothing():
    """Behind a wall the sphere's outline contributes nothing (both probes see the wall), for its
    motion and its growth. Positive controls, which fail with the primary term scaled or off: with
    no wall the growth gives L_d dA/dr exactly (L_d = 2 - 1 against the sky; as
    test_sphere_silhouette_matches_the_analytic_derivative), and with the wall over the left half
    the visible half of the outline gives the same derivative pixels as with no wall, half of
    L_d dA/dr in all (over 4 seeds; per seed the share of the curve samples on either side varies
    by about 1 %)."""
    r, L_d = 0.5, 2.0 - 1.0
    tx = np.tan(np.radians(FOV) / 2)
    dA = np.pi * (W / (2 * tx)) ** 2 * 2 * r * D * D / (D * D - r * r) ** 2
    tangents = {"obj.radius": np.float32(1.0), "obj.center": np.float32([1, 0, 0])}
    walled, half, free = sphere_behind_a_wall(0.0), sphere_behind_a_wall(-3.0), sphere_behind_a_wall(None)
    for name, t in tangents.items():
        for scene in (walled, half, free):
            scene.set_differentiable([name])
        for seed in range(4):
            f = quiet(walled.render_forward, {name: t}, spp_interior=4, spp_primary=16, seed=seed)
            assert np.abs(f).max() < 1e-6, (name, np.abs(f).max())
    sums = []
    for scene in (half, free):
        scene.set_differentiable(["obj.radius"])
    for seed in range(4):
        g = quiet(free.render_forward, {"obj.radius": np.float32(1.0)}, spp_interior=4, spp_primary=16, seed=seed)
        h = quiet(half.render_forward, {"obj.radius": np.float32(1.0)}, spp_interior=4, spp_primary=16, seed=seed)
        assert g[..., 0].sum() == pytest.approx(L_d * dA, rel=1e-4)      # measured 1e-8
        assert np.abs(h[:, :W // 2]).max() < 1e-6                        # the covered half
        np.testing.assert_allclose(h[:, W // 2:], g[:, W // 2:], rtol=1e-5, atol=1e-5 * np.abs(g).max())
        sums.append(h[..., 0].sum())
    assert np.mean(sums) == pytest.approx(0.5 * L_d * dA, rel=0.02), np.array(sums) / (L_d * dA)  # measured 0.491, 0.498 (seeds 0, 1)


def test_backward_matches_forward_with_the_boundary_term(tmp_path):
    shape, name = SHAPES["cube"]
    scene = limn.load_dict(envmap_scene(tmp_path, shape), base_dir=tmp_path)
    scene.set_differentiable([name, "obj.alpha"])
    rng = np.random.default_rng(2)
    t = {name: rng.normal(size=scene.params[name].shape).astype(np.float32), "obj.alpha": np.float32(0.5)}
    adjoint = rng.normal(size=(16, 16, 3)).astype(np.float32)
    fwd = quiet(scene.render_forward, t, spp=32, seed=3)
    grads = quiet(scene.render_backward, adjoint, spp=32, seed=3)
    lhs = float((adjoint.astype(np.float64) * fwd).sum())
    rhs = sum(float((grads[n].astype(np.float64) * t[n]).sum()) for n in t)
    assert abs(lhs - rhs) <= 1e-3 * abs(rhs), (lhs, rhs)
