"""Interior derivative term (render_forward / render_backward) against finite differences.

Every scene here is chosen so that the perturbation changes no visibility, and the boundary terms
are switched off where geometry moves: a bumpy floor that fills the view under a lamp lit through
next-event estimation, and a camera and a point light inside a closed sphere. The boundary terms
have their own tests (test_primary_visibility.py, test_indirect_boundary.py)."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import limn
from conftest import camera


def rel_rmse(a, b):
    return float(np.sqrt(((a - b) ** 2).mean()) / np.sqrt((b ** 2).mean()))


def grid_floor(n=8, half=4.0):
    xs = np.linspace(-half, half, n + 1)
    X, Y = np.meshgrid(xs, xs)
    V = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1).astype(np.float32)
    F = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            F += [[a, a + 1, a + n + 2], [a, a + n + 2, a + n + 1]]
    return V, np.array(F)


def floor_scene(bsdf, integrator=None, smooth=True):
    """Flat shading gives the image a discontinuity along every edge where the normal jumps, a
    boundary term of its own: the flat variant starts coplanar, where those jumps are zero."""
    V, F = grid_floor()
    if smooth:
        V[:, 2] = 0.05 * np.sin(V[:, 0] * 1.3) * np.cos(V[:, 1])  # bumps: smooth normals vary
    uv = (V[F][..., :2] + 4.0) / 8.0  # continuous texture coordinates across triangles
    return {"type": "scene", "integrator": integrator or {"type": "direct", "bsdf_samples": 0},
            "sensor": camera((0, -0.5, 3), (0, 0, 0), fov=50, width=24, height=24, spp=32),
            "floor": {"type": "mesh", "vertex_positions": V, "faces": F, "corner_uvs": uv.astype(np.float32),
                      "face_normals": not smooth, "bsdf": bsdf},
            "lamp": {"type": "rectangle",
                     "to_world": [{"scale": 0.5}, {"rotate": {"axis": [1, 0, 0], "angle": 180}}, {"translate": [0.3, 1.5, 2.5]}],
                     "emitter": {"type": "area", "radiance": 20.0}}}


def inside_sphere(bsdf, max_depth=4):
    return {"type": "scene", "integrator": {"type": "path", "max_depth": max_depth, "rr_depth": 100},
            "sensor": camera((0.3, -0.6, 0.1), (0, 1, 0), fov=70, width=16, height=16, spp=64),
            "dome": {"type": "sphere", "radius": 2.0, "center": [0.1, 0.2, 0.0], "bsdf": {"type": "twosided", "bsdf": bsdf}},
            "bulb": {"type": "point", "position": [0.2, 0.1, 0.6], "intensity": 3.0}}


DIFFUSE = {"type": "diffuse", "reflectance": [0.6, 0.5, 0.4]}
GLOSSY = {"type": "roughconductor", "distribution": "ggx", "alpha": 0.3, "material": "Cu"}


def random_z_tangent(scene, name, seed=0):
    t = np.zeros_like(scene.params[name])
    t[:, 2] = np.random.default_rng(seed).normal(size=len(t))
    return t


@pytest.mark.term("interior")
@pytest.mark.parametrize("bsdf", [DIFFUSE, GLOSSY], ids=["diffuse", "glossy"])
@pytest.mark.parametrize("smooth", [True, False], ids=["smooth", "flat"])
def test_vertex_derivatives_match_fd(bsdf, smooth):
    scene = limn.load_dict(floor_scene(bsdf, smooth=smooth))
    t = {"floor.vertex_positions": random_z_tangent(scene, "floor.vertex_positions")}
    scene.set_differentiable(list(t))
    # The interior term alone: nothing here changes visibility (boundary terms are tested elsewhere).
    # Flat: the normal jumps that open between the faces at theta +- eps make the finite difference
    # jump by O(1) / spp for each sample that changes face, and about eps * spp samples do: an error
    # of about sqrt(eps / spp) (seeds 1-4, max: 4.8e-3 at eps 3e-4 and 32 spp, the previous setting,
    # which passed on seed 1 alone; 1.6e-3 at 1e-4 and 128; 5.4e-4 at 1e-4 and 512), so it gets a
    # smaller eps and more samples.
    eps, spp = (1e-3, 32) if smooth else (1e-4, 512)
    fwd = scene.render_forward(t, seed=1, spp=spp, spp_primary=0, spp_boundary=0)
    assert any("switched off (spp_boundary = 0)" in line for line in scene.last_stats["summary"])
    ref = limn.fd(scene, t, eps=eps, spp=spp, seed=1, cache=False)
    assert np.abs(ref).mean() > 0.05
    assert rel_rmse(fwd, ref) < 2e-3, rel_rmse(fwd, ref)     # measured 1e-4 (smooth), 5e-4 (flat)


@pytest.mark.term("interior")
def test_smooth_normals_with_flipped_and_duplicated_triangles():
    """Smooth-shading normals turn a flipped triangle by the mesh's orientation and count a
    duplicated triangle once, in the image and in its derivative alike: the floor with every fifth
    triangle wound the other way and every seventh duplicated renders as the clean floor, and its
    derivative matches finite differences (two-sided: a one-sided bsdf is black behind a flipped
    triangle)."""
    bsdf = {"type": "twosided", "bsdf": GLOSSY}
    clean_dict = floor_scene(bsdf)
    V, F = clean_dict["floor"]["vertex_positions"], clean_dict["floor"]["faces"].copy()
    F[::5] = F[::5, ::-1]
    F = np.concatenate([F, F[1::7, [0, 2, 1]]])
    broken_dict = floor_scene(bsdf)
    broken_dict["floor"]["faces"] = F
    broken_dict["floor"]["corner_uvs"] = ((V[F][..., :2] + 4.0) / 8.0).astype(np.float32)
    clean, broken = limn.load_dict(clean_dict), limn.load_dict(broken_dict)
    a, b = clean.render(seed=1, spp=32), broken.render(seed=1, spp=32)
    assert rel_rmse(b, a) < 1e-4, rel_rmse(b, a)  # measured 2.8e-8 (duplicates counted twice: 7.7e-3)
    t = {"floor.vertex_positions": random_z_tangent(broken, "floor.vertex_positions")}
    broken.set_differentiable(list(t))
    fwd = broken.render_forward(t, seed=1, spp=32, spp_primary=0, spp_boundary=0)
    ref = limn.fd(broken, t, eps=1e-3, spp=32, seed=1, cache=False)
    assert np.abs(ref).mean() > 0.05
    assert rel_rmse(fwd, ref) < 2e-3, rel_rmse(fwd, ref)  # measured 1.0e-4 (flips unturned in the derivative: 5.6)


@pytest.mark.term("interior")
def test_moving_emitter_derivatives_match_fd():
    """The lamp moves and grows: the emitter point of next-event estimation is attached to it and
    its area Jacobian enters. (Growing both triangles alike keeps the triangle-selection CDF fixed;
    a general deformation gives both estimators far more variance, the same expectation.)"""
    scene = limn.load_dict(floor_scene(DIFFUSE))
    v = scene.params["lamp.vertex_positions"]
    t = {"lamp.vertex_positions": ((v - v.mean(0)) + np.float32([0.3, -0.2, 0.5])).astype(np.float32)}
    scene.set_differentiable(list(t))
    fwd = scene.render_forward(t, seed=6, spp_primary=0, spp_boundary=0)
    ref = limn.fd(scene, t, eps=1e-3, spp=32, seed=6, cache=False)
    assert np.abs(ref).mean() > 0.01
    assert rel_rmse(fwd, ref) < 2e-3, rel_rmse(fwd, ref)


@pytest.mark.parametrize("name,tangent,eps", [
    ("floor.alpha", 1.0, 1e-3),
    ("floor.reflectance", [1.0, 0.3, -0.5], 1e-2),
    ("lamp.radiance", [1.0, 2.0, 0.5], 1.0),
])
@pytest.mark.term("interior")
def test_material_and_emitter_derivatives_match_fd(name, tangent, eps):
    bsdf = GLOSSY if name == "floor.alpha" else DIFFUSE
    scene = limn.load_dict(floor_scene(bsdf))
    t = {name: np.asarray(tangent, np.float32).reshape(scene.params[name].shape)}
    scene.set_differentiable([name])
    fwd = scene.render_forward(t, seed=2)
    assert any("skipped, no differentiable geometry" in line for line in scene.last_stats["summary"])
    ref = limn.fd(scene, t, eps=eps, spp=32, seed=2, cache=False)
    assert rel_rmse(fwd, ref) < 3e-3, rel_rmse(fwd, ref)     # FD limited by float images


@pytest.mark.term("interior")
def test_texture_derivatives_match_fd(tmp_path):
    tex = np.random.default_rng(1).uniform(0.2, 0.8, size=(4, 4, 3)).astype(np.float32)
    limn.write_image(tmp_path / "tex.exr", tex)
    d = floor_scene({"type": "diffuse", "reflectance": {"type": "bitmap", "filename": "tex.exr"}})
    scene = limn.load_dict(d, base_dir=tmp_path)
    t = {"floor.reflectance": np.random.default_rng(2).normal(size=(4, 4, 3)).astype(np.float32),
         "floor.vertex_positions": random_z_tangent(scene, "floor.vertex_positions", 3)}
    scene.set_differentiable(list(t))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fwd = scene.render_forward(t, seed=3, spp_primary=0, spp_boundary=0)
    ref = limn.fd(scene, t, eps=1e-3, spp=32, seed=3, cache=False)
    assert rel_rmse(fwd, ref) < 3e-3, rel_rmse(fwd, ref)


def block_z(fwd_stack, fd_stack, block=4):
    """z-scores of block means: forward and FD estimates from independent seeds."""
    def blocks(s):
        n, h, w, c = s.shape
        return s.reshape(n, h // block, block, w // block, block, c).mean(axis=(2, 4))
    a, b = blocks(fwd_stack), blocks(fd_stack)
    sa, sb = a.std(0, ddof=1) / np.sqrt(len(a)), b.std(0, ddof=1) / np.sqrt(len(b))
    return (a.mean(0) - b.mean(0)) / np.sqrt(sa ** 2 + sb ** 2 + 1e-12)


def projection_z(fwd_stack, fd_stack, term_stack, block=4):
    """One z-score (Welch) for the whole image: forward and FD block means projected onto the
    mean of `term_stack`, an estimate of the term under test from seeds used by neither. A term
    scaled by k shifts the projection by (k - 1) |term|^2, summed over every block the term
    touches, so it shows here long before any single block's z does. The weights must not come
    from the tested runs: weights of the term over the runs' own spread (a matched filter) tripled
    the false alarms of |z| > 5 in a Gaussian simulation (2e-3 against 1.5e-4)."""
    def blocks(s):
        n, h, w, c = s.shape
        return s.reshape(n, h // block, block, w // block, block, c).mean(axis=(2, 4))
    w = blocks(term_stack).mean(0)
    p, q = (blocks(fwd_stack) * w).sum(axis=(1, 2, 3)), (blocks(fd_stack) * w).sum(axis=(1, 2, 3))
    return float((p.mean() - q.mean()) / np.sqrt(p.var(ddof=1) / len(p) + q.var(ddof=1) / len(q) + 1e-30))


@pytest.mark.term("interior")
@pytest.mark.parametrize("bsdf", [DIFFUSE, GLOSSY], ids=["diffuse", "glossy"])
@pytest.mark.parametrize("name,tangent", [("dome.radius", 1.0), ("dome.center", [0.3, -0.5, 1.0])])
def test_multi_bounce_derivatives_agree_with_fd_in_expectation(bsdf, name, tangent):
    """BSDF-sampled vertices are attached in the material form; finite differences hold the sampled
    directions fixed instead. Per path they differ, in expectation they agree: block means over
    independent seeds."""
    scene = limn.load_dict(inside_sphere(bsdf))
    t = {name: np.asarray(tangent, np.float32).reshape(scene.params[name].shape)}
    scene.set_differentiable([name])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fwd = np.stack([scene.render_forward(t, spp=128, spp_primary=0, spp_boundary=0, seed=10 + k) for k in range(6)])
    ref = np.stack([limn.fd(scene, t, eps=1e-3, spp=128, seed=20 + k, cache=False) for k in range(6)])
    z = block_z(fwd, ref)
    assert np.abs(z).max() < 4.5, z
    assert abs(fwd.mean() - ref.mean()) < 0.05 * abs(ref.mean()) + 4 * ref.mean(axis=(1, 2, 3)).std() / np.sqrt(6)


@pytest.mark.term("interior")
def test_max_depth_option_matches_fd_at_that_depth():
    """``max_depth`` overrides the path length of render, fd, render_forward and render_backward."""
    scene = limn.load_dict(inside_sphere(DIFFUSE, max_depth=4))
    t = {"dome.radius": np.float32(1.0)}
    scene.set_differentiable(list(t))
    short = scene.render(spp=16, max_depth=2)
    assert short.mean() < 0.8 * scene.render(spp=16).mean()  # the dome's interreflections are gone
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fwd = np.stack([scene.render_forward(t, spp=128, spp_primary=0, spp_boundary=0, seed=30 + k, max_depth=2) for k in range(6)])
        full = scene.render_forward(t, spp=128, spp_primary=0, spp_boundary=0, seed=30)
    ref = np.stack([limn.fd(scene, t, eps=1e-3, spp=128, seed=40 + k, cache=False, max_depth=2) for k in range(6)])
    assert np.abs(block_z(fwd, ref)).max() < 4.5
    assert abs(full.mean() - fwd[0].mean()) > 0.1 * abs(fwd[0].mean())
    adjoint = np.random.default_rng(3).normal(size=fwd[0].shape).astype(np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = scene.render_backward(adjoint, spp=128, spp_primary=0, spp_boundary=0, seed=30, max_depth=2)
    lhs, rhs = float((adjoint.astype(np.float64) * fwd[0]).sum()), float(g["dome.radius"])
    assert abs(lhs - rhs) <= 1e-3 * abs(rhs), (lhs, rhs)
    with pytest.raises(ValueError, match="max_depth must be >= -1"):
        scene.render(max_depth=-3)
    direct = limn.load_dict(floor_scene(DIFFUSE))
    direct.set_differentiable(["lamp.radiance"])
    with pytest.raises(ValueError, match="applies to the path integrator"):
        direct.render_forward({"lamp.radiance": np.ones(3, np.float32)}, spp=1, max_depth=3)


def test_backward_matches_forward():
    """sum(adjoint * forward image) == <gradient, tangent> for the same seed."""
    d = floor_scene(GLOSSY, integrator={"type": "path", "max_depth": 3})
    scene = limn.load_dict(d)
    names = ["floor.vertex_positions", "floor.alpha", "lamp.radiance"]
    scene.set_differentiable(names)
    rng = np.random.default_rng(5)
    t = {n: rng.normal(size=scene.params[n].shape).astype(np.float32) for n in names}
    adjoint = rng.normal(size=(scene.height, scene.width, 3)).astype(np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fwd = scene.render_forward(t, seed=4)
        grads = scene.render_backward(adjoint, seed=4)
    assert set(grads) == set(names)
    for n in names:
        assert grads[n].shape == scene.params[n].shape and np.isfinite(grads[n]).all()
    lhs = float((adjoint.astype(np.float64) * fwd).sum())
    rhs = sum(float((grads[n].astype(np.float64) * t[n]).sum()) for n in names)
    assert abs(lhs - rhs) <= 1e-3 * abs(rhs), (lhs, rhs)


def test_gradients_finite_on_extreme_cases():
    d = floor_scene({"type": "roughconductor", "distribution": "ggx", "alpha": 0.005}, integrator={"type": "path", "max_depth": 4})
    d["lamp"]["emitter"]["radiance"] = 1e4
    d["sliver"] = {"type": "mesh", "vertex_positions": np.array([[0, 0, 0.5], [1, 0, 0.5], [0.5, 1e-6, 0.5]], np.float32),
                   "faces": np.array([[0, 1, 2]])}
    d["sensor"] = camera((0, -4, 0.06), (0, 4, 0.0), fov=60, width=16, height=16, spp=16)  # grazing view
    scene = limn.load_dict(d)
    names = ["floor.vertex_positions", "floor.alpha", "sliver.vertex_positions"]
    scene.set_differentiable(names)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        grads = scene.render_backward(np.ones((16, 16, 3), np.float32), seed=0)
        img = scene.render_forward({n: np.ones_like(scene.params[n]) for n in names}, seed=0)
    assert all(np.isfinite(g).all() for g in grads.values())
    assert np.isfinite(img).all()
    assert scene.last_stats["invalid_paths"] == 0


def test_api_errors():
    scene = limn.load_dict(floor_scene(DIFFUSE))
    with pytest.raises(ValueError, match="set_differentiable"):
        scene.render_forward({})
    with pytest.raises(ValueError, match="unknown parameter 'nope'"):
        scene.set_differentiable(["nope"])
    scene.set_differentiable(["floor.reflectance"])
    with pytest.raises(ValueError, match="not differentiable"):
        scene.render_forward({"lamp.radiance": np.ones(3)})
    with pytest.raises(ValueError, match=r"expected shape \(3,\)"):
        scene.render_forward({"floor.reflectance": np.ones(4)})
    with pytest.raises(ValueError, match="spp_boundary must be >= 0"):
        scene.render_forward({"floor.reflectance": np.ones(3)}, spp_boundary=-1)
    with pytest.raises(ValueError, match="guiding must be 'auto', 'none', 'grid' or 'octree'"):
        scene.render_forward({"floor.reflectance": np.ones(3)}, guiding="kdtree")
    with pytest.raises(ValueError, match="boundary_sampler must be 'independent' or 'stratified' \\(got 'sobol'\\)"):
        scene.render_forward({"floor.reflectance": np.ones(3)}, boundary_sampler="sobol")
    with pytest.raises(ValueError, match="project_seed must be"):
        scene.render_forward({"floor.reflectance": np.ones(3)}, guiding="grid", project_seed="camera")
    with pytest.raises(TypeError, match="unknown derivative option"):
        scene.render_forward({"floor.reflectance": np.ones(3)}, guidance="grid")
    with pytest.raises(ValueError, match="adjoint must have shape"):
        scene.render_backward(np.ones((2, 2, 3)))


def test_fd_cache(tmp_path):
    scene = limn.load_dict(floor_scene(DIFFUSE))
    t = {"floor.reflectance": np.ones(3, np.float32)}
    a = limn.fd(scene, t, eps=1e-2, spp=4, seed=0, cache=str(tmp_path))
    assert len(list(tmp_path.iterdir())) == 1
    b = limn.fd(scene, t, eps=1e-2, spp=4, seed=0, cache=str(tmp_path))
    np.testing.assert_array_equal(a, b)
    limn.fd(scene, t, eps=2e-2, spp=4, seed=0, cache=str(tmp_path))
    assert len(list(tmp_path.iterdir())) == 2
    scene.params["floor.reflectance"] = [0.1, 0.1, 0.1]  # other parameter values: another entry
    limn.fd(scene, t, eps=1e-2, spp=4, seed=0, cache=str(tmp_path))
    assert len(list(tmp_path.iterdir())) == 3
    np.testing.assert_array_equal(scene.params["floor.reflectance"], np.float32([0.1, 0.1, 0.1]))  # restored


def test_fd_cache_key_holds_the_mesh_files_triangles_and_the_primal_revision(tmp_path, monkeypatch):
    """A scene file names its mesh file, so the scene's text does not show triangles changed there
    (same vertices); nor does it show a renderer whose primal images changed (PRIMAL_REVISION).
    Neither may be served the old reference."""
    import importlib
    import json
    fd_module = importlib.import_module("limn.fd")  # the attribute limn.fd is the function
    quad = "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
    (tmp_path / "quad.obj").write_text(quad + "f 1 2 3\nf 1 3 4\n")
    scene_file = tmp_path / "scene.json"
    scene_file.write_text(json.dumps({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": camera((0, -0.5, 3), (0, 0, 0), width=8, height=8, spp=4),
        "quad": {"type": "obj", "filename": "quad.obj", "bsdf": DIFFUSE},
        "lamp": {"type": "rectangle", "to_world": [{"rotate": {"axis": [1, 0, 0], "angle": 180}}, {"translate": [0, 0, 2]}],
                 "emitter": {"type": "area", "radiance": 5.0}}}))
    cache = tmp_path / "cache"

    def reference():
        scene = limn.load(str(scene_file))
        return limn.fd(scene, {"quad.reflectance": np.ones(3, np.float32)}, eps=1e-2, spp=4, cache=str(cache))

    reference()
    assert len(list(cache.iterdir())) == 1
    reference()
    assert len(list(cache.iterdir())) == 1  # the same scene, code and settings: served from the cache
    (tmp_path / "quad.obj").write_text(quad + "f 1 2 3\nf 2 3 4\n")  # the vertices as before, one triangle moved
    reference()
    assert len(list(cache.iterdir())) == 2
    monkeypatch.setattr(fd_module, "PRIMAL_REVISION", fd_module.PRIMAL_REVISION + 1)
    reference()
    assert len(list(cache.iterdir())) == 3


def test_translation_parameter_moves_geometry_and_differentiates_as_rigid_motion():
    d = floor_scene(DIFFUSE)
    d["ball"] = {"type": "sphere", "center": [0.5, 0.5, 0.6], "radius": 0.3}
    scene = limn.load_dict(d)
    v0 = scene.params["floor.vertex_positions"].copy()
    scene.params["floor.to_world.translation"] = [0.0, 0.0, 0.25]
    assert "floor.to_world.translation" in scene.update()
    np.testing.assert_allclose(scene.params["floor.vertex_positions"], v0 + [0, 0, 0.25], atol=1e-6)
    scene.params["ball.to_world.translation"] = [0.1, 0.0, 0.0]
    scene.update()
    np.testing.assert_allclose(scene.params["ball.center"], [0.6, 0.5, 0.6], atol=1e-6)
    assert scene.update() == []  # the move is not seen twice
    # d/d(translation) = d/d(all vertices along the same direction), forward and backward.
    rigid = np.zeros_like(v0)
    rigid[:, 2] = 1.0
    scene.set_differentiable(["floor.to_world.translation", "floor.vertex_positions"])
    a = scene.render_forward({"floor.to_world.translation": np.float32([0, 0, 1])}, seed=3, spp_boundary=4)
    b = scene.render_forward({"floor.vertex_positions": rigid}, seed=3, spp_boundary=4)
    np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-6 * np.abs(b).max())
    g = scene.render_backward(np.ones((24, 24, 3), np.float32), seed=3, spp_boundary=4)
    np.testing.assert_allclose(g["floor.to_world.translation"], g["floor.vertex_positions"].sum(0), rtol=1e-3, atol=1e-6)


@pytest.mark.term("interior")
def test_texture_slides_over_a_moving_sphere(tmp_path):
    """Camera and light inside a textured sphere that moves: the camera rays' hits slide over the
    texture, an interior derivative (no silhouette, no shadow)."""
    tex = np.random.default_rng(4).uniform(0.2, 0.9, size=(8, 16, 3)).astype(np.float32)
    limn.write_image(tmp_path / "tex.exr", tex)
    d = inside_sphere({"type": "diffuse", "reflectance": {"type": "bitmap", "filename": "tex.exr"}}, max_depth=2)
    scene = limn.load_dict(d, base_dir=tmp_path)
    t = {"dome.center": np.float32([0.3, -0.4, 0.5])}
    scene.set_differentiable(list(t))
    fwd = quiet_forward(scene, t, seed=2)
    ref = limn.fd(scene, t, eps=1e-3, spp=64, seed=2, cache=False)
    assert rel_rmse(fwd, ref) < 3e-3, rel_rmse(fwd, ref)


def quiet_forward(scene, t, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return scene.render_forward(t, spp_primary=0, spp_boundary=0, **kw)
