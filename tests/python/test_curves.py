"""Fibre curves (`bsplinecurve`, projective-sampling paper section 5.3): loading and its errors,
silhouettes seen by the camera and the indirect boundary term (shadows) against finite differences,
each failing with its boundary term switched off, and no NaN/Inf in the stiff cases."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import limn
from conftest import camera
from test_derivatives import block_z


def quiet(fn, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kw)


# A gently bent fibre with a radius that varies along it (0.12 .. 0.22).
BENT = np.float32([[-1.1, 0.0, -0.2, 0.12], [-0.6, 0.1, 0.25, 0.16], [-0.1, -0.1, -0.1, 0.22],
                   [0.4, 0.1, 0.2, 0.18], [0.9, 0.0, -0.15, 0.14], [1.3, -0.1, 0.1, 0.12]])
# A sausage: nearly straight, strongly varying radius (0.08 .. 0.35).
SAUSAGE = np.float32([[-1.0, 0.0, 0.0, 0.08], [-0.5, 0.0, 0.05, 0.3], [0.0, 0.0, -0.05, 0.35],
                      [0.5, 0.0, 0.05, 0.3], [1.0, 0.0, 0.0, 0.08]])


def curve(points, offsets=None, **extra):
    d = {"type": "bsplinecurve", "control_points": np.asarray(points, np.float32),
         "bsdf": {"type": "diffuse", "reflectance": [0.7, 0.5, 0.3]}}
    if offsets is not None:
        d["curve_offsets"] = np.asarray(offsets, np.int32)
    d.update(extra)
    return d


def envmap_scene(tmp_path, shape, origin=(0, -4, 0)):
    """The shape alone in a graded environment (as test_primary_visibility): moving it changes only
    what the camera sees directly."""
    env = np.ones((16, 32, 3), np.float32) * np.linspace(0.2, 1.0, 16)[:, None, None]
    limn.write_image(tmp_path / "sky.exr", env)
    return {"type": "scene", "integrator": {"type": "path", "max_depth": 3},
            "sensor": camera(origin, (0, 0, 0), fov=40, width=16, height=16, spp=64),
            "obj": shape, "sky": {"type": "envmap", "filename": "sky.exr", "to_world": {"rotate": {"axis": [1, 0, 0], "angle": 90}}}}


def shadow_scene(light, points):
    """The curve at z ~ 1.2 over a diffuse floor, lit by a point light or a small area light."""
    pts = np.array(points, np.float32)
    pts[:, 2] += 1.2
    lamp = ({"type": "point", "position": [0.3, 0.4, 4.0], "intensity": 30.0} if light == "point" else
            {"type": "rectangle", "to_world": [{"scale": 0.3}, {"rotate": {"axis": [1, 0, 0], "angle": 180}}, {"translate": [0.3, 0.4, 4.0]}],
             "emitter": {"type": "area", "radiance": 80.0}})
    return {"type": "scene", "integrator": {"type": "direct"},
            "sensor": camera((0, -4, 3), (0.2, 0.3, 0.3), fov=50, width=16, height=16, spp=64),
            "floor": {"type": "rectangle", "to_world": {"scale": 4}, "bsdf": {"type": "diffuse", "reflectance": 0.6}},
            "lamp": lamp, "fibre": curve(pts)}


def tangent(points, dx=1.0, dz=0.3, dr=0.0):
    t = np.zeros_like(np.asarray(points, np.float32))
    t[:, 0], t[:, 2], t[:, 3] = dx, dz, dr * np.asarray(points)[:, 3]
    return t


# ---- loading --------------------------------------------------------------------------------------

def test_loads_from_file_and_from_arrays_alike(tmp_path):
    """Mitsuba's text format (x y z r per line, blank lines between curves) and the arrays give the
    same curve and the same image."""
    two = np.concatenate([BENT, SAUSAGE + np.float32([0, 0, 0.8, 0])])
    text = "# two curves\n" + "\n".join(" ".join(f"{x:.9g}" for x in p) for p in BENT) + "\n\n" + \
        "\n".join(" ".join(f"{x:.9g}" for x in p) for p in SAUSAGE + np.float32([0, 0, 0.8, 0])) + "\n"
    (tmp_path / "c.txt").write_text(text)
    a = limn.load_dict(envmap_scene(tmp_path, curve(two, [0, len(BENT)])), base_dir=tmp_path)
    b = limn.load_dict(envmap_scene(tmp_path, {"type": "bsplinecurve", "filename": "c.txt",
                                               "bsdf": {"type": "diffuse", "reflectance": [0.7, 0.5, 0.3]}}), base_dir=tmp_path)
    np.testing.assert_array_equal(a.params["obj.control_points"], b.params["obj.control_points"])
    assert a.params["obj.control_points"].shape == (len(two), 4)
    ia, ib = a.render(spp=4, seed=1), b.render(spp=4, seed=1)
    np.testing.assert_array_equal(ia, ib)
    assert np.isfinite(ia).all() and (ia != ia[0, 0]).any()  # the curves are seen


BAD = [
    ({"control_points": BENT[:3]}, "at least 4"),
    ({"control_points": np.concatenate([BENT[:2], [[-0.1, -0.1, -0.1, -0.2]], BENT[3:]])}, "radius must be > 0"),
    ({"control_points": np.concatenate([BENT[:2], [[np.nan, 0, 0, 0.1]], BENT[3:]])}, "not finite"),
    ({"control_points": np.float32([[0, 0, 0, 0.1]] * 5)}, "zero length"),
    ({"control_points": np.float32([[0, 0, 0, 0.5], [1, 0, 0, 0.5], [1, 1, 0, 0.5], [0, 1, 0, 0.5]])}, "curvature radius"),
    ({"control_points": BENT[:, :3]}, "shape (N, 4)"),
    ({"control_points": BENT, "curve_offsets": np.int32([0, 9])}, "curve_offsets"),
]


@pytest.mark.parametrize("props,message", BAD, ids=[m for _, m in BAD])
def test_bad_curves_are_refused_with_the_object_and_the_value(tmp_path, props, message):
    d = envmap_scene(tmp_path, {"type": "bsplinecurve", **props})
    with pytest.raises(ValueError) as e:
        limn.load_dict(d, base_dir=tmp_path)
    assert message in str(e.value) and "obj" in str(e.value), str(e.value)


def test_bad_curve_files_name_the_file_and_line(tmp_path):
    (tmp_path / "c.txt").write_text("0 0 0 0.1\n1 0 0 0.1\n2 x 0 0.1\n3 0 0 0.1\n")
    with pytest.raises(ValueError, match=r"c\.txt', line 3: 'x' is not a number"):
        limn.load_dict(envmap_scene(tmp_path, {"type": "bsplinecurve", "filename": "c.txt"}), base_dir=tmp_path)
    (tmp_path / "c.txt").write_text("0 0 0 0.1\n1 0 0\n")
    with pytest.raises(ValueError, match="line 2: expected 4 numbers"):
        limn.load_dict(envmap_scene(tmp_path, {"type": "bsplinecurve", "filename": "c.txt"}), base_dir=tmp_path)


def test_updates_are_validated_and_rolled_back(tmp_path):
    scene = limn.load_dict(envmap_scene(tmp_path, curve(BENT)), base_dir=tmp_path)
    before = scene.params["obj.control_points"].copy()
    scene.params["obj.control_points"][2, 3] = 5.0  # far beyond the curvature radius
    with pytest.raises(ValueError, match="obj.control_points.*curvature radius"):
        scene.update()
    np.testing.assert_array_equal(scene.params["obj.control_points"], before)


# ---- derivatives against finite differences -------------------------------------------------------

def fd_stack(scene, name, t, seeds=6, eps=2e-2, spp=1024, seed0=30):
    return np.stack([limn.fd(scene, {name: t}, eps=eps, spp=spp, seed=seed0 + k, cache=False) for k in range(seeds)])


# The level view (0, -4, 0) sees the first end's rim nearly edge-on: before the primary term
# dropped back-facing rim points it counted that end twice there (block z 21.8).
SILHOUETTE_CASES = [(BENT, 0.0, (0, -4, 0)), (BENT, 0.0, (0, -4, 1)), (BENT, 0.0, (0.5, -4, 0)), (SAUSAGE, 0.4, (0, -4, 0))]


@pytest.mark.parametrize("points,dr,origin", SILHOUETTE_CASES, ids=["bent seen level", "bent from above", "bent from the side", "sausage"])
def test_silhouettes_against_finite_differences(tmp_path, points, dr, origin):
    """Curves alone in an environment: interior + primary (the tube's silhouettes and rim circles)
    agree with FD; without the primary term they do not."""
    check_silhouettes(tmp_path, points, dr, origin)


def check_silhouettes(tmp_path, points, dr, origin):
    scene = limn.load_dict(envmap_scene(tmp_path, curve(points), origin), base_dir=tmp_path)
    name = "obj.control_points"
    t = tangent(points, dx=1.0, dz=0.3, dr=dr)
    scene.set_differentiable([name])
    fd = fd_stack(scene, name, t)
    on = np.stack([quiet(scene.render_forward, {name: t}, spp=128, spp_primary=128, seed=40 + k) for k in range(6)])
    off = np.stack([quiet(scene.render_forward, {name: t}, spp=128, spp_primary=0, seed=40 + k) for k in range(6)])
    z_on, z_off = block_z(on, fd), block_z(off, fd)
    print(f"max |z| {np.abs(z_on).max():.2f} with the primary term, {np.abs(z_off).max():.2f} without")
    assert np.isfinite(on).all()
    assert np.abs(z_on).max() < 4.5, z_on
    assert np.abs(z_off).max() > 10, z_off


@pytest.mark.parametrize("light,spp_boundary", [("point", 16), ("area", 512)], ids=["point light", "area light"])
def test_curve_shadow_against_finite_differences(light, spp_boundary):
    """The indirect boundary term (Eq. 4, the tube's curvature part and its rims): the curve's shadow
    on the floor moves with it; without the term the shadow's blocks are far off."""
    scene = limn.load_dict(shadow_scene(light, BENT))
    name = "fibre.control_points"
    t = tangent(BENT, dx=1.0, dz=0.0, dr=0.3)
    scene.set_differentiable([name])
    fd = fd_stack(scene, name, t, seeds=8)
    on = np.stack([quiet(scene.render_forward, {name: t}, spp=64, spp_boundary=spp_boundary, guiding="none", seed=50 + k) for k in range(8)])
    off = np.stack([quiet(scene.render_forward, {name: t}, spp=64, spp_boundary=0, seed=50 + k) for k in range(8)])
    z_on, z_off = block_z(on, fd), block_z(off, fd)
    print(f"{light}: max |z| {np.abs(z_on).max():.2f} with the indirect term, {np.abs(z_off).max():.2f} without")
    assert np.isfinite(on).all()
    assert np.abs(z_on).max() < 5.0, z_on
    assert np.abs(z_off).max() > 10, z_off


# Two strands crossing like yarn: the upper one shadows the lower one and hides part of it.
YARN = np.float32([[-1.0, 0.0, 0.0, 0.1], [-0.5, 0.05, 0.1, 0.12], [0.0, 0.0, 0.0, 0.12], [0.5, -0.05, 0.1, 0.12], [1.0, 0.0, 0.0, 0.1],
                   [0.0, -1.0, 0.3, 0.1], [0.05, -0.5, 0.35, 0.12], [0.0, 0.0, 0.45, 0.12], [-0.05, 0.5, 0.35, 0.12], [0.0, 1.0, 0.3, 0.1]])


def yarn_with_fd(light):
    """The yarn under `light`, framed so that it and its shadow fill the view; the upper strand's
    tangent and 8 seeds of finite differences."""
    scene_dict = shadow_scene(light, YARN)
    scene_dict["fibre"]["curve_offsets"] = np.int32([0, 5])
    scene_dict["sensor"] = camera((1.5, -3.0, 3.6), (0, 0, 0.9), fov=45, width=16, height=16, spp=64)
    scene = limn.load_dict(scene_dict)
    name = "fibre.control_points"
    t = np.zeros_like(YARN)
    t[5:, 0], t[5:, 2] = 1.0, -0.3  # the upper strand only
    scene.set_differentiable([name])
    return scene, name, t, fd_stack(scene, name, t, seeds=8)


@pytest.mark.parametrize("light,spp_boundary", [("point", 16), ("area", 512)], ids=["point light", "area light"])
def test_yarn_shadowing_itself_against_finite_differences(light, spp_boundary):
    """Two crossing strands of one curve shape: the upper strand moves, its shadow falls on the
    lower strand and on the floor (the indirect term with a curve as the receiver). Uniform
    boundary samples: the fine guides leave part of this self-shadow at their defensive share,
    which makes 8 guided seeds heavy-tailed (test_yarn_with_fine_guides_is_heavy_tailed below)."""
    scene, name, t, fd = yarn_with_fd(light)
    on = np.stack([quiet(scene.render_forward, {name: t}, spp=64, spp_boundary=spp_boundary, guiding="none", seed=50 + k) for k in range(8)])
    off = np.stack([quiet(scene.render_forward, {name: t}, spp=64, spp_boundary=0, seed=50 + k) for k in range(8)])
    z_on, z_off = block_z(on, fd), block_z(off, fd)
    print(f"{light}: max |z| {np.abs(z_on).max():.2f} with the indirect term, {np.abs(z_off).max():.2f} without")
    assert np.isfinite(on).all()
    assert np.abs(z_on).max() < 5.0, z_on
    assert np.abs(z_off).max() > 10, z_off


# ---- stiff cases (design.md section 7) -------------------------------------------------------------

STIFF = {
    "thin": np.float32([[-1, 0, 0, 1e-4], [-0.3, 0, 0.2, 1e-4], [0.3, 0, -0.2, 1e-4], [1, 0, 0, 1e-4]]),
    "straight": np.float32([[-1, 0, 0, 0.1], [-0.3, 0, 0, 0.15], [0.3, 0, 0, 0.12], [1, 0, 0, 0.1]]),
    "along the view axis": np.float32([[0, -1, 0, 0.1], [0, -0.3, 0, 0.15], [0, 0.3, 0, 0.12], [0, 1, 0, 0.1]]),
    "along z": np.float32([[0, 0, -1, 0.1], [0, 0, -0.3, 0.15], [0, 0, 0.3, 0.12], [0, 0, 1, 0.1]]),
    "tight bend": np.float32([[-0.5, 0, 0, 0.05], [0, 0, 0.5, 0.05], [0.5, 0, 0, 0.05], [0, 0, -0.5, 0.05], [-0.5, 0, 0, 0.05]]),
}


@pytest.mark.parametrize("case", list(STIFF))
def test_stiff_curves_give_finite_images_and_derivatives(case):
    pts = STIFF[case]
    scene = limn.load_dict(shadow_scene("point", pts))
    name = "fibre.control_points"
    scene.set_differentiable([name])
    t = tangent(pts, dx=1.0, dz=0.5, dr=0.5)
    img = scene.render(spp=8)
    fwd = quiet(scene.render_forward, {name: t}, spp=8, spp_boundary=64)
    grad = quiet(scene.render_backward, np.ones_like(img), spp=8, spp_boundary=64)
    assert np.isfinite(img).all() and np.isfinite(fwd).all() and np.isfinite(grad[name]).all()


@pytest.mark.xfail(strict=True, reason="open: the projective grid misses part of the yarn's self-shadow, which it then samples "
                                       "at its defensive share only (10 %): unbiased but heavy-tailed, so 8 seeds fail the z-test "
                                       "(docs/derivatives.md; tests/bench/yarn_guides.py)")
def test_yarn_with_fine_guides_is_heavy_tailed():
    """Not a bias: over 48 seeds the default grid's pixels agree with uniform samples at 16x the
    budget and with a coarse grid (R = 4) that has no holes (tests/bench/yarn_guides.py), but a few
    seeds carry most of some pixels' value. This records the coverage gap until the projections
    reach that part of the silhouette."""
    scene, name, t, fd = yarn_with_fd("area")
    on = np.stack([quiet(scene.render_forward, {name: t}, spp=64, spp_boundary=512, guiding="grid", seed=50 + k) for k in range(8)])
    assert np.abs(block_z(on, fd)).max() < 5.0
