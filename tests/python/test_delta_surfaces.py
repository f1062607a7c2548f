"""Boundary terms through delta (specular) surfaces (issue 35 item 5, docs/derivatives.md,
"Silhouettes seen in mirrors"): a silhouette seen in a flat mirror is a silhouette seen directly
by the camera reflected across the mirror's plane, sampled by the primary term from that virtual
camera. Each case is compared with finite differences (block z-scores, and the whole image
projected onto the term, which fails with the term scaled by 0.8 or 1.25,
docs/reports/test_power.md) and must fail with the term switched off."""
from __future__ import annotations

import os
import warnings

import numpy as np
import pytest

import limn
from conftest import SCENES, load_in, scene_json
from test_derivatives import block_z, projection_z

VALIDATION = os.path.join(SCENES, "validation")


def quiet(fn, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kw)


def mirror_scene():
    """A sphere behind the camera, seen only in a small square mirror (its reflection crosses the
    mirror's right edge), against a constant sky."""
    return scene_json(VALIDATION, "sphere_in_mirror")


def unfolded_scene():
    """The positive control: the same view without the mirror, the sphere at its mirror image
    (reflected across the mirror's plane y = 1), seen directly; 0.05 further left, or the right
    end of its outline lies on a pixel boundary (4.0 px right of the centre), where FD's eps
    carries it across (FD -5.5 and -1.6 in the two pixels, the term -7 and 0: block z 40)."""
    d = mirror_scene()
    del d["mirror"]
    c = d["ball"]["center"]
    d["ball"]["center"] = [c[0] - 0.05, 2.0 - c[1], c[2]]
    return d


def check_term(d, name, t, term, spp_term, off_at_least, seeds=8, fd_spp=2048, eps=1e-2, term_seeds=4):
    """render_forward along t agrees with FD (every 4x4 block |z| < 5, and |z| < 5 for the image
    projected onto the term) and does not without the term (some block beyond `off_at_least`).
    `term`: "primary" or "boundary" (the indirect term). Returns the summary of a 1-spp call."""
    scene = load_in(VALIDATION, d)
    scene.set_differentiable([name])
    count = "spp_primary" if term == "primary" else "spp_boundary"
    other = "spp_boundary" if term == "primary" else "spp_primary"
    fd = np.stack([limn.fd(scene, {name: t}, eps=eps, spp=fd_spp, seed=k, cache=False) for k in range(seeds)])
    on = np.stack([quiet(scene.render_forward, {name: t}, spp=64, **{count: spp_term, other: 0}, seed=50 + k) for k in range(seeds)])
    off = np.stack([quiet(scene.render_forward, {name: t}, spp=64, **{count: 0, other: 0}, seed=50 + k) for k in range(seeds)])
    only = np.stack([quiet(scene.render_forward, {name: t}, spp=64, spp_interior=0, **{count: spp_term, other: 0}, seed=150 + k)
                     for k in range(term_seeds)])
    quiet(scene.render_forward, {name: t}, spp=1, **{count: 1, other: 0})
    summary = scene.last_stats["summary"]
    z_on, z_off, z_term = block_z(on, fd), block_z(off, fd), projection_z(on, fd, only)
    print(f"{name}: max |z| {np.abs(z_on).max():.2f} with the {term} term, {np.abs(z_off).max():.2f} without; "
          f"projected onto the term z {z_term:.2f}; term peak {np.abs(only.mean(0)).max():.4f}")
    assert np.abs(z_on).max() < 5.0, z_on
    assert abs(z_term) < 5.0, z_term
    assert np.abs(z_off).max() > off_at_least, z_off
    return summary


@pytest.mark.term("primary")
@pytest.mark.parametrize("name,t", [("ball.center", [1.0, 0.0, 0.0]), ("ball.radius", 1.0)], ids=["centre", "radius"])
def test_sphere_seen_in_a_plane_mirror(name, t):
    summary = check_term(mirror_scene(), name, np.float32(t), "primary", 64, 10)
    assert any("through 1 chains of planar mirror reflections" in line for line in summary), summary


@pytest.mark.term("primary")
def test_cube_seen_in_a_plane_mirror():
    """A tilted flat-shaded cube in place of the sphere: mesh silhouette edges (and creases) seen
    in the mirror, both sides probed."""
    d = mirror_scene()
    del d["ball"]
    d["box"] = {"type": "cube", "to_world": [{"scale": 0.2}, {"rotate": {"axis": [0.3, 1, 0.2], "angle": 30}},
                                             {"translate": [0.1, -0.5, 1.0]}],
                "bsdf": {"type": "diffuse", "reflectance": 0.2}}
    t = np.zeros_like(load_in(VALIDATION, d).params["box.vertex_positions"])
    t[:, 0] = 1.0
    check_term(d, "box.vertex_positions", t, "primary", 64, 10)


@pytest.mark.term("primary")
def test_sphere_seen_directly_where_the_mirror_shows_it():
    """Positive control for the test above: the same protocol on the unfolded scene."""
    check_term(unfolded_scene(), "ball.center", np.float32([1.0, 0.0, 0.0]), "primary", 64, 10)


def test_curved_mirror_is_named_in_the_summary():
    """A sphere mirror has no virtual camera: the summary says its reflections are left out."""
    d = mirror_scene()
    d["mirror"] = {"type": "sphere", "center": [0.0, 1.5, 1.0], "radius": 0.4, "bsdf": {"type": "conductor"}}
    scene = load_in(VALIDATION, d)
    scene.set_differentiable(["ball.center"])
    quiet(scene.render_forward, {"ball.center": np.float32([1, 0, 0])}, spp=1, spp_primary=1, spp_boundary=0)
    summary = scene.last_stats["summary"]
    assert any("delta surface 'mirror' is curved" in line for line in summary), summary
    assert not any("chains of planar mirror reflections" in line for line in summary), summary


def glass_scene(glass=True):
    """A box outside the view casts a shadow, under a low area light, onto a floor seen through a
    horizontal glass slab (0.2 thick, index 1.5) between the camera and the floor. Without
    `glass`, the positive control: the same shadow seen directly."""
    d = scene_json(VALIDATION, "shadow_through_glass")
    if not glass:
        del d["glass"]
    return d


def y_translation(scene_dict, name):
    scene = load_in(VALIDATION, scene_dict)
    t = np.zeros_like(scene.params[name])
    t[:, 1] = 1.0
    return t


@pytest.mark.term("boundary")
def test_shadow_seen_through_a_glass_slab():
    d = glass_scene()
    summary = check_term(d, "box.vertex_positions", y_translation(d, "box.vertex_positions"), "boundary", 256, 10)
    assert any("through 1 stacks of parallel flat glass interfaces" in line for line in summary), summary


@pytest.mark.term("boundary")
def test_shadow_seen_directly_where_the_glass_was():
    """Positive control for the test above: the same protocol without the slab."""
    d = glass_scene(glass=False)
    check_term(d, "box.vertex_positions", y_translation(d, "box.vertex_positions"), "boundary", 256, 10)


@pytest.mark.term("boundary")
def test_shadow_seen_in_a_plane_mirror():
    """The same shadow seen in a silver mirror on the ceiling from a camera looking up: the
    indirect term's camera connections go to the mirror's virtual camera (times silver's
    Fresnel reflectance). The positive control is test_shadow_seen_directly_where_the_glass_was
    (the same floor seen from above without the slab)."""
    d = scene_json(VALIDATION, "shadow_in_mirror")
    summary = check_term(d, "box.vertex_positions", y_translation(d, "box.vertex_positions"), "boundary", 256, 10)
    assert any("through 1 chains of planar mirror reflections" in line and line.startswith("indirect") for line in summary), summary


@pytest.mark.term("boundary")
@pytest.mark.parametrize("scene_name", ["shadow_through_glass", "shadow_in_mirror"], ids=["through glass", "in a mirror"])
def test_moving_receiver_seen_through_delta_surfaces(scene_name):
    """The floor moves (mostly up) under the static box: the observing point, seen through the
    slab or in the mirror, slides along the last segment of the path to the camera."""
    check_term(scene_json(VALIDATION, scene_name), "floor.to_world.translation", np.float32([0.3, 0.4, 1.0]), "boundary", 256, 10)


@pytest.mark.parametrize("scene_name,name", [("sphere_in_mirror", "ball.center"), ("shadow_through_glass", "box.vertex_positions"),
                                             ("shadow_in_mirror", "box.vertex_positions")])
def test_backward_matches_forward_through_delta_surfaces(scene_name, name):
    scene = load_in(VALIDATION, scene_json(VALIDATION, scene_name))
    scene.set_differentiable([name])
    rng = np.random.default_rng(5)
    t = rng.normal(size=scene.params[name].shape).astype(np.float32)
    adjoint = rng.normal(size=(16, 16, 3)).astype(np.float32)
    fwd = quiet(scene.render_forward, {name: t}, spp=4, spp_primary=16, spp_boundary=16, seed=3)
    grads = quiet(scene.render_backward, adjoint, spp=4, spp_primary=16, spp_boundary=16, seed=3)
    lhs = float((adjoint.astype(np.float64) * fwd).sum())
    rhs = float((grads[name].astype(np.float64) * t).sum())
    assert abs(lhs - rhs) <= 1e-3 * abs(rhs), (lhs, rhs)
