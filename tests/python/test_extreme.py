"""Stiff and extreme cases of the primal renderer (docs/testing.md, "extreme cases"): no NaN/Inf, bounded error."""
from __future__ import annotations

import copy

import numpy as np
import pytest

import limn
from conftest import camera, sphere_over_plane


def scaled(d: dict, s: float) -> dict:
    """The same scene with every length multiplied by s (camera, shapes, lights)."""
    d = copy.deepcopy(d)
    la = d["sensor"]["to_world"]["look_at"]
    la["origin"] = [s * x for x in la["origin"]]
    la["target"] = [s * x for x in la["target"]]
    d["sensor"]["near_clip"] = 1e-2 * s
    d["sensor"]["far_clip"] = 1e4 * s
    d["ball"]["center"] = [s * x for x in d["ball"]["center"]]
    d["ball"]["radius"] *= s
    for key in ("floor", "light"):
        t = d[key]["to_world"]
        d[key]["to_world"] = (t if isinstance(t, list) else [t]) + [{"scale": s}]
    return d


@pytest.mark.parametrize("s", [1e-4, 1e4])
def test_scale_invariance(s):
    base = sphere_over_plane(spp=32)
    ref = limn.load_dict(base).render(seed=4)
    scene = limn.load_dict(scaled(base, s))
    img = scene.render(seed=4)
    assert np.isfinite(img).all() and scene.last_stats["invalid_samples"] == 0
    # Same random numbers, so only rounding differs; a few paths may diverge.
    diff = np.abs(img - ref)
    assert np.quantile(diff, 0.95) < 1e-3 * ref.max()
    assert abs(img.mean() - ref.mean()) < 0.01 * ref.mean()


def test_very_bright_emitters_scale_linearly():
    d = sphere_over_plane()
    a = limn.load_dict(d).render(seed=2)
    d["light"]["emitter"]["radiance"] = 20.0 * 1e4
    d["sky"]["radiance"] = 0.1 * 1e4
    b = limn.load_dict(d).render(seed=2)
    assert np.isfinite(b).all()
    np.testing.assert_allclose(b, 1e4 * a, rtol=1e-4, atol=1e-6 * b.max())


@pytest.mark.parametrize("bsdf", [
    {"type": "roughconductor", "distribution": "ggx", "alpha": 0.005},
    {"type": "roughconductor", "distribution": "beckmann", "alpha": 0.005},
    {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.005, "int_ior": 1.5},
    {"type": "conductor", "material": "Au"},
    {"type": "dielectric", "int_ior": 1.33},
])
def test_near_specular_and_delta_bsdfs(bsdf):
    d = sphere_over_plane(spp=16)
    d["ball"]["bsdf"] = bsdf
    d["floor"]["bsdf"] = dict(bsdf) if bsdf["type"].endswith("conductor") else d["floor"]["bsdf"]
    d["integrator"]["max_depth"] = 8
    scene = limn.load_dict(d)
    img = scene.render(seed=0)
    assert np.isfinite(img).all() and img.min() >= 0
    assert scene.last_stats["invalid_samples"] == 0
    assert img.mean() > 1e-3


def test_grazing_and_tangent_rays():
    # The camera lies in the floor's plane and looks along it; the sphere is tangent to the floor.
    d = sphere_over_plane(spp=16)
    d["sensor"] = camera((0, -4, 0), (0, 0, 0), fov=40)
    d["ball"]["center"] = [0, 0, 0.6]
    scene = limn.load_dict(d)
    img = scene.render(seed=0)
    assert np.isfinite(img).all() and scene.last_stats["invalid_samples"] == 0


def test_sliver_triangles():
    # A fan of needle-thin triangles (aspect ratio 1e6) lit from above.
    n = 200
    x = np.linspace(-1, 1, n + 1, dtype=np.float32)
    v = np.concatenate([np.stack([x, np.zeros_like(x), np.full_like(x, 0.2)], 1),
                        np.stack([x, np.full_like(x, 1e-6), np.full_like(x, 0.2)], 1)])
    faces = np.array([[i, i + 1, n + 1 + i] for i in range(n)] + [[i + 1, n + 2 + i, n + 1 + i] for i in range(n)])
    d = sphere_over_plane(spp=16)
    d["needles"] = {"type": "mesh", "vertex_positions": v, "faces": faces}
    scene = limn.load_dict(d)
    img = scene.render(seed=0)
    assert np.isfinite(img).all() and scene.last_stats["invalid_samples"] == 0
