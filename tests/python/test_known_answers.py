"""Renders with known answers: white furnace, a point light over a plane, and agreement between
emitter sampling (incl. environment-map importance sampling) and BSDF sampling."""
from __future__ import annotations

import numpy as np
import pytest

import limn
from conftest import camera, pixel_rays


def _render_seeds(scene, spp, seeds):
    return np.stack([scene.render(spp=spp, seed=s) for s in seeds])


def test_white_furnace():
    rho, W = 0.6, 32
    origin, target = (0, -4, 0), (0, 0, 0)
    d = {"type": "scene", "integrator": {"type": "path"},
         "sensor": camera(origin, target, fov=40, width=W, height=W, spp=64),
         "ball": {"type": "sphere", "radius": 1.0, "bsdf": {"type": "diffuse", "reflectance": rho}},
         "env": {"type": "constant", "radiance": 1.0}}
    img = limn.load_dict(d).render(seed=1)
    # Classify pixels by whether all four corners of the pixel see the sphere.
    corners = pixel_rays(origin, target, (0, 0, 1), 40, W, W, offsets=((0, 0), (1, 0), (0, 1), (1, 1)))
    o = np.array(origin, float)
    hits = []
    for dirs in corners:
        b = dirs @ o
        hits.append(b * b - (o @ o - 1.0) >= 0)
    inside, outside = np.logical_and.reduce(hits), ~np.logical_or.reduce(hits)
    assert inside.sum() > 100 and outside.sum() > 100
    np.testing.assert_array_equal(img[outside], 1.0)       # the environment, exactly
    vals = img[inside].ravel()
    mean, err = vals.mean(), vals.std() / np.sqrt(vals.size)
    assert abs(mean - rho) < 4 * err + 1e-4, (mean, err)   # one bounce off a convex sphere: rho
    assert np.abs(vals - rho).max() < 0.25


def test_point_light_over_a_diffuse_plane():
    rho, I, W = 0.5, 10.0, 64
    light = np.array([0.3, -0.2, 1.0])
    origin, target, up = (0, 0, 5), (0, 0, 0), (0, 1, 0)
    d = {"type": "scene", "integrator": {"type": "direct"},
         "sensor": camera(origin, target, up=up, fov=30, width=W, height=W, spp=256),
         "floor": {"type": "rectangle", "to_world": {"scale": 10}, "bsdf": {"type": "diffuse", "reflectance": rho}},
         "lamp": {"type": "point", "position": light.tolist(), "intensity": I}}
    img = limn.load_dict(d).render(seed=0)[..., 0]
    # Expected pixel value: L = rho/pi * I cos(theta) / r^2, averaged over an 8x8 grid in the pixel.
    offsets = [((i + 0.5) / 8, (j + 0.5) / 8) for i in range(8) for j in range(8)]
    expected = np.zeros((W, W))
    for dirs in pixel_rays(origin, target, up, 30, W, W, offsets=offsets):
        t = -origin[2] / dirs[..., 2]
        p = np.array(origin) + t[..., None] * dirs
        to_light = light - p
        r2 = (to_light ** 2).sum(-1)
        expected += rho / np.pi * I * (to_light[..., 2] / np.sqrt(r2)) / r2 / len(offsets)
    rel = np.abs(img - expected) / expected
    assert np.median(rel) < 1e-3 and rel.max() < 0.01, (np.median(rel), rel.max())


def _envmap(path):
    h, w = 32, 64
    v = (np.arange(h) + 0.5) / h
    env = np.ones((h, w, 3), np.float32) * (0.2 + 0.8 * v[:, None, None])  # gradient
    env[6:9, 40:44] = [80.0, 70.0, 50.0]                                     # a small bright sun
    limn.write_image(path, env)


@pytest.mark.parametrize("lighting", ["envmap", "area"])
def test_emitter_sampling_agrees_with_bsdf_sampling(tmp_path, lighting):
    _envmap(tmp_path / "env.exr")
    base = {"type": "scene",
            "sensor": camera((0, -3.5, 1.0), (0, 0, 0.2), fov=35, width=24, height=24),
            "ball": {"type": "sphere", "radius": 0.8, "bsdf": {"type": "diffuse", "reflectance": 0.7}},
            "ground": {"type": "rectangle", "to_world": [{"scale": 3}, {"translate": [0, 0, -0.8]}],
                       "bsdf": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.3}}}
    if lighting == "envmap":
        base["env"] = {"type": "envmap", "filename": "env.exr", "to_world": {"rotate": {"axis": [1, 0, 0], "angle": 90}}}
    else:
        base["lamp"] = {"type": "rectangle", "to_world": [{"scale": 0.6}, {"rotate": {"axis": [1, 0, 0], "angle": 150}},
                                                          {"translate": [0.8, -1.0, 2.0]}],
                        "emitter": {"type": "area", "radiance": 8.0}}
    # Compare block means (6x6 pixels) over independent renders: single-pixel estimates of BSDF
    # sampling are heavy-tailed, block means over seeds are close to Gaussian.
    results = {}
    for name, (ne, nb) in {"emitter": (1, 0), "bsdf": (0, 1), "mis": (1, 1)}.items():
        d = dict(base, integrator={"type": "direct", "emitter_samples": ne, "bsdf_samples": nb})
        stack = _render_seeds(limn.load_dict(d, base_dir=tmp_path), 128, range(12))[..., 0]
        blocks = stack.reshape(len(stack), 4, 6, 4, 6).mean(axis=(2, 4))
        results[name] = (blocks.mean(0), blocks.std(0, ddof=1) / np.sqrt(len(stack)))
    for a, b in (("emitter", "bsdf"), ("mis", "bsdf"), ("mis", "emitter")):
        (ma, ea), (mb, eb) = results[a], results[b]
        z = (ma - mb) / (np.sqrt(ea ** 2 + eb ** 2) + 1e-7)
        assert np.abs(z).max() < 4.5, (a, b, z)
        assert ma.mean() > 0.01
    # Importance sampling is the better estimator for the small bright source.
    if lighting == "envmap":
        assert (results["emitter"][1] / results["emitter"][0]).mean() < 0.5 * (results["bsdf"][1] / results["bsdf"][0]).mean()
