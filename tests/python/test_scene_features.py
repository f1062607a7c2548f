"""Scene features that scenes from other renderers use (issue 35, item 7): the film's crop window
and gaussian reconstruction filter, writable per-vertex shading normals, bitmap area emitters,
spot lights and analytic disks. Primal features against known answers; every derivative against
central finite differences, each failing with its term switched off."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import limn
from conftest import camera
from test_derivatives import DIFFUSE, GLOSSY, block_z, floor_scene, rel_rmse
from test_indirect_boundary import load, quiet, validation, x_translation


def check_term_power(scene, name, t, spp_boundary, seeds=8, fd_spp=1024, eps=2e-2):
    """test_indirect_boundary.check_term, also with the indirect term scaled by 0.8 and 1.25
    (off + k (on - off), the same seeds): agrees with FD (block |z| < 5) at k = 1 only."""
    scene.set_differentiable([name])
    fd = np.stack([limn.fd(scene, {name: t}, eps=eps, spp=fd_spp, seed=k, cache=False) for k in range(seeds)])
    on = np.stack([quiet(scene.render_forward, {name: t}, spp=64, spp_boundary=spp_boundary, seed=50 + k) for k in range(seeds)])
    off = np.stack([quiet(scene.render_forward, {name: t}, spp=64, spp_boundary=0, seed=50 + k) for k in range(seeds)])
    z = {k: np.abs(block_z(off + k * (on - off), fd)).max() for k in (0.0, 0.8, 1.0, 1.25)}
    print(f"{name}: max |z| with the indirect term scaled by k: " + ", ".join(f"k={k}: {v:.2f}" for k, v in z.items()))
    assert z[1.0] < 5.0, z
    assert z[0.0] > 10 and z[0.8] > 5.0 and z[1.25] > 5.0, z


# ---- film: crop window and gaussian filter --------------------------------------------------------
# A bright half-plane (world x < edge) seen head-on from distance D fills the film left of column
# x0: with max_depth 1 each pixel is L times the probability that its film sample lands left of x0,
# L F(x0 - c) for the pixel centre c and the normalised filter's CDF F (a known answer).
EW, EH, D, FOV, X0 = 16, 4, 5.0, 30.0, 7.3


def gaussian_cdf(d, stddev=0.5):
    """CDF of Mitsuba's gaussian, exp(-x^2 / 2 s^2) - exp(-r^2 / 2 s^2) on [-r, r], r = 4 s, normalised."""
    r, s2 = 4 * stddev, stddev * math.sqrt(2)
    b = math.exp(-r * r / (2 * stddev * stddev))
    G = lambda x: 0.5 * math.sqrt(math.pi) * s2 * math.erf(x / s2)  # noqa: E731
    d = min(max(d, -r), r)
    return (G(d) - G(-r) - b * (d + r)) / (2 * G(r) - 2 * b * r)


def gaussian_pdf(d, stddev=0.5):
    r = 4 * stddev
    b = math.exp(-r * r / (2 * stddev * stddev))
    z = 2 * (0.5 * math.sqrt(math.pi) * stddev * math.sqrt(2) * math.erf(r / (stddev * math.sqrt(2)))) - 2 * b * r
    return max(0.0, math.exp(-d * d / (2 * stddev * stddev)) - b) / z if abs(d) < r else 0.0


def edge_scene(film, L=1.0):
    tx = math.tan(math.radians(FOV) / 2)
    edge = (X0 / (EW / 2) - 1) * D * tx  # world x seen at film column X0 (camera +x is the image's left)
    sensor = camera((0, -D, 0), (0, 0, 0), fov=FOV, width=EW, height=EH, spp=64)
    sensor["film"].update(film)
    return {"type": "scene", "integrator": {"type": "path", "max_depth": 1}, "sensor": sensor,
            # 4 wide, 2 high: its other three edges lie beyond the film and the filter's reach (the
            # film sees |x| < 1.34 and |z| < 0.34, the filter 2 pixels = 0.33 more), and a fifth of
            # the primary term's samples land on the edge in view.
            "lamp": {"type": "rectangle", "to_world": [{"scale": [2, 1, 1]}, {"rotate": {"axis": [1, 0, 0], "angle": 90}},
                                                       {"translate": [edge - 2, 0, 0]}],
                     "emitter": {"type": "area", "radiance": L}}}


GAUSSIAN = {"rfilter": {"type": "gaussian"}}


@pytest.mark.parametrize("film,cdf,offset", [
    ({}, lambda d: min(max(d + 0.5, 0.0), 1.0), 0),
    (GAUSSIAN, gaussian_cdf, 0),
    ({**GAUSSIAN, "crop_offset_x": 5, "crop_offset_y": 1, "crop_width": 8, "crop_height": 2}, gaussian_cdf, 5),
], ids=["box", "gaussian", "gaussian, cropped"])
def test_film_filter_and_crop_window_known_answer(film, cdf, offset):
    scene = limn.load_dict(edge_scene(film))
    spp = 4096
    img = scene.render(spp=spp, seed=3)[..., 0]
    expected = np.array([cdf(X0 - offset - (i + 0.5)) for i in range(img.shape[1])])
    sigma = np.sqrt(np.maximum(expected * (1 - expected), 1e-6) / spp)
    err = np.abs(img - expected[None, :]) / sigma[None, :]
    assert img.shape == ((2, 8) if offset else (EH, EW))
    assert err.max() < 5.0, (img, expected)


def test_film_options_are_checked():
    with pytest.raises(ValueError, match=r"crop window .* must lie inside the 16 x 4 film"):
        limn.load_dict(edge_scene({"crop_offset_x": 10, "crop_width": 8}))
    with pytest.raises(ValueError, match=r"rfilter.*stddev must be in \[0.25, 4\] pixels \(got 0.1"):
        limn.load_dict(edge_scene({"rfilter": {"type": "gaussian", "stddev": 0.1}}))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        limn.load_dict(edge_scene({"rfilter": {"type": "tent"}}))
    assert any("'tent' is not supported (known: box, gaussian)" in str(w.message) for w in caught)


def edge_derivative(film, offset=0):
    """The analytic derivative of the edge image when the lamp moves along +x: the edge's film
    column moves by K = (W / 2) / (D tan(fov / 2)) pixels per unit, and pixel c changes by
    L f(x0 - c) K, f the normalised filter's density."""
    K = (EW / 2) / (D * math.tan(math.radians(FOV) / 2))
    pdf = (lambda d: 1.0 if -0.5 <= d < 0.5 else 0.0) if not film else gaussian_pdf
    return np.array([pdf(X0 - offset - (i + 0.5)) * K for i in range(EW - offset if not offset else 8)])


@pytest.mark.parametrize("film,offset", [(GAUSSIAN, 0), ({**GAUSSIAN, "crop_offset_x": 5, "crop_width": 8}, 5)],
                         ids=["gaussian", "gaussian, cropped"])
def test_primary_term_splats_through_the_filter(film, offset):
    """The primary term's film samples are spread over the pixels by the film's filter, as the
    camera samples of the primal image are: known answer and FD. Splatted into one pixel each (the
    box film's term, what it did before filters) the derivative misses the analytic one."""
    scene = limn.load_dict(edge_scene(film))
    name = "lamp.to_world.translation"
    t = {name: np.float32([1, 0, 0])}
    scene.set_differentiable([name])
    expected = edge_derivative(film, offset)
    # Known answer: z-scores of the column profile (rows averaged) over independent seeds.
    on = np.stack([quiet(scene.render_forward, t, spp=4, spp_primary=256, seed=k)[..., 0].mean(axis=0) for k in range(8)])
    mean, se = on.mean(0), on.std(0, ddof=1) / np.sqrt(len(on))
    z = (mean - expected) / (se + 1e-12)  # columns beyond the filter's reach: exactly 0 on both sides
    assert np.abs(z).max() < 5.0, (mean, expected, z)
    z_k = {k: np.abs((k * mean - expected) / (k * se + 1e-12)).max() for k in (0.8, 1.25)}
    print(f"primary term through the filter: known answer max |z| {np.abs(z).max():.2f}; scaled by k: {z_k}")
    assert min(z_k.values()) > 5.0, z_k  # the term scaled (it is the whole derivative here) fails the known answer
    sums = on.sum(axis=1)
    assert abs(sums.mean() - expected.sum()) < 5.0 * sums.std(ddof=1) / np.sqrt(len(sums)), (sums, expected.sum())
    # FD: block z-scores (rows averaged) against central differences of the filtered image.
    fd = np.stack([limn.fd(scene, t, eps=2e-2, spp=4096, seed=20 + k, cache=False) for k in range(4)])
    fwd = np.stack([quiet(scene.render_forward, t, spp=4, spp_primary=64, seed=40 + k) for k in range(4)])
    z = block_z(fwd, fd, block=2)
    assert np.abs(z).max() < 5.0, z
    off = np.stack([quiet(scene.render_forward, t, spp=4, spp_primary=0, seed=40 + k) for k in range(4)])
    assert np.abs(block_z(off, fd, block=2)).max() > 10
    # The same term splatted box-wise (the box film's scene) against the gaussian answer.
    box = limn.load_dict(edge_scene({k: v for k, v in film.items() if k != "rfilter"}))
    box.set_differentiable([name])
    box_cols = np.stack([quiet(box.render_forward, t, spp=4, spp_primary=256, seed=k)[..., 0].mean(axis=0) for k in range(8)])
    z_box = (box_cols.mean(0) - expected) / (box_cols.std(0, ddof=1) / np.sqrt(len(box_cols)) + se + 1e-12)
    assert np.abs(z_box).max() > 10, z_box


def test_indirect_term_splats_through_the_filter():
    """A box's point-light shadow seen through the gaussian film: the indirect term's camera
    connections are spread by the filter too."""
    d = validation("occluder_point")
    d["sensor"]["film"]["rfilter"] = {"type": "gaussian"}
    scene = load(d)
    name = "box.vertex_positions"
    check_term_power(scene, name, x_translation(scene, name), 16)


def crop_agrees_with_the_full_film(d, tangents, window, seeds=6, **options):
    """The cropped film's image and derivative image against the same window of the whole film's:
    block z-scores over independent seeds (the pixels' random streams differ between the two)."""
    x0, y0, w, h = window
    full = limn.load_dict(d)
    cropped_d = {**d, "sensor": {**d["sensor"], "film": {**d["sensor"]["film"], "crop_offset_x": x0, "crop_offset_y": y0,
                                                          "crop_width": w, "crop_height": h}}}
    cropped = limn.load_dict(cropped_d)
    for scene in (full, cropped):
        scene.set_differentiable(list(tangents))
    run = lambda scene, k: (scene.render(seed=k), quiet(scene.render_forward, tangents, seed=k, **options))  # noqa: E731
    a = [run(full, k) for k in range(seeds)]
    b = [run(cropped, 100 + k) for k in range(seeds)]
    assert b[0][0].shape == (h, w, 3)
    for i, what in enumerate(["image", "derivative"]):
        z = block_z(np.stack([r[i][y0:y0 + h, x0:x0 + w] for r in a]), np.stack([r[i] for r in b]), block=2)
        assert np.abs(z).max() < 5.0, (what, z)
    assert np.abs(np.stack([r[1] for r in b]).mean(0)).max() > 0  # not a window of zeros


def test_crop_window_images_and_derivatives_are_windows_of_the_full_film():
    """Every term (interior, primary, indirect) and the heightfield estimator see the crop window
    as the same part of the film."""
    d = validation("occluder_point")
    crop_agrees_with_the_full_film(d, {"box.to_world.translation": np.float32([1, 0.5, 0])}, (4, 6, 8, 8), spp=16,
                                   spp_primary=16, spp_boundary=16)
    heights = np.outer(np.hanning(6), np.hanning(6)).astype(np.float32)
    hf = {"type": "scene", "sensor": camera((0, -3, 2), (0, 0, 0), width=12, height=12, spp=16),
          "terrain": {"type": "heightfield", "data": heights}, "sun": {"type": "directional", "direction": [0.2, 0.1, -1]}}
    crop_agrees_with_the_full_film(hf, {"terrain.heights": np.ones_like(heights)}, (2, 4, 8, 6), spp=16)


def test_heightfield_estimator_refuses_a_non_box_filter():
    heights = np.outer(np.hanning(6), np.hanning(6)).astype(np.float32)
    d = {"type": "scene", "sensor": camera((0, -3, 2), (0, 0, 0), width=8, height=8, spp=4),
         "terrain": {"type": "heightfield", "data": heights}, "sun": {"type": "directional", "direction": [0.2, 0.1, -1]}}
    d["sensor"]["film"]["rfilter"] = {"type": "gaussian"}
    scene = limn.load_dict(d)
    scene.set_differentiable(["terrain.heights"])
    with pytest.raises(ValueError, match="heightfield 'terrain': its estimator integrates each pixel's box footprint"):
        scene.render_forward({"terrain.heights": np.ones_like(heights)}, spp=1)


# ---- vertex normals -------------------------------------------------------------------------------
@pytest.mark.parametrize("bsdf", [DIFFUSE, GLOSSY], ids=["diffuse", "glossy"])
def test_vertex_normals_derivatives_match_fd(bsdf):
    """"<id>.vertex_normals" (Mitsuba's name): the shading normals are interpolated, normalised and
    enter the BSDF in the interior term. No visibility changes: the interior term alone."""
    scene = limn.load_dict(floor_scene(bsdf))
    name = "floor.vertex_normals"
    assert scene.params[name].shape == scene.params["floor.vertex_positions"].shape
    t = {name: (0.3 * np.random.default_rng(4).normal(size=scene.params[name].shape)).astype(np.float32)}
    scene.set_differentiable([name])
    fwd = scene.render_forward(t, seed=1, spp=32)
    ref = limn.fd(scene, t, eps=1e-3, spp=32, seed=1, cache=False)
    assert np.abs(ref).mean() > 0.02
    assert rel_rmse(fwd, ref) < 2e-3, rel_rmse(fwd, ref)
    off = scene.render_forward(t, seed=1, spp_interior=0)
    assert rel_rmse(off, ref) > 0.99


def test_vertex_normals_are_kept_once_written():
    """Derived normals follow the positions; written ones are kept as given, also when written
    together with new positions. Bad normals are refused and rolled back."""
    scene = limn.load_dict(floor_scene(DIFFUSE))
    n0 = scene.params["floor.vertex_normals"].copy()
    assert np.allclose(np.linalg.norm(n0, axis=1), 1.0, atol=1e-5)
    scene.params["floor.vertex_positions"][:, 2] *= 2.0  # steeper bumps: derived normals tilt further
    scene.update()
    tilted = scene.params["floor.vertex_normals"].copy()
    assert np.abs(tilted - n0).max() > 0.01
    written = np.tile(np.float32([0.0, 0.3, 1.0]), (len(n0), 1))
    scene.params["floor.vertex_normals"][:] = written
    scene.params["floor.vertex_positions"][:, 2] *= 0.5
    scene.update()
    assert np.array_equal(scene.params["floor.vertex_normals"], written)
    a = scene.render(spp=8, seed=1)
    scene.params["floor.vertex_normals"][3] = 0.0
    with pytest.raises(ValueError, match=r"parameter 'floor.vertex_normals': normal 3 must be finite and non-zero \(got \[0, 0, 0\]\)"):
        scene.update()
    assert np.array_equal(scene.params["floor.vertex_normals"], written)
    assert np.array_equal(scene.render(spp=8, seed=1), a)
    flat = limn.load_dict(floor_scene(DIFFUSE, smooth=False))
    assert "floor.vertex_normals" not in flat.params


# ---- bitmap area emitters -------------------------------------------------------------------------
TEXELS = np.array([[[4.0, 0.5, 0.5], [0.5, 4.0, 0.5]], [[0.5, 0.5, 4.0], [2.0, 2.0, 0.5]]], np.float32)


def test_bitmap_emitter_known_answer(tmp_path):
    """A bitmap emitter seen directly shows its texture at the hit's uv: the same texture as the
    diffuse reflectance of an equal, non-emitting rectangle under a white environment (whose
    radiance is exactly the reflectance) renders the same image."""
    limn.write_image(tmp_path / "tex.exr", TEXELS)
    tex = {"type": "bitmap", "filename": "tex.exr"}
    quad = {"type": "rectangle", "to_world": [{"rotate": {"axis": [1, 0, 0], "angle": 90}}]}
    sensor = camera((0, -3.5, 0), (0, 0, 0), fov=30, width=16, height=16, spp=256)
    emitting = limn.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 1}, "sensor": sensor,
                               "quad": {**quad, "emitter": {"type": "area", "radiance": tex}}}, base_dir=tmp_path)
    reflecting = limn.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 2}, "sensor": sensor,
                                 "quad": {**quad, "bsdf": {"type": "diffuse", "reflectance": {**tex, "raw": True}}},
                                 "sky": {"type": "constant", "radiance": 1.0}}, base_dir=tmp_path)
    assert emitting.params["quad.radiance"].shape == (2, 2, 3)
    a, b = emitting.render(seed=1), reflecting.render(seed=2, spp=2048)
    covered = a.max(axis=2) > 0.4
    assert covered.sum() > 60
    assert np.abs(a - b)[covered].max() < 0.05 * TEXELS.max(), np.abs(a - b)[covered].max()
    assert a[covered].std() > 0.5  # the texture varies over the image


def test_bitmap_emitter_derivatives_match_fd(tmp_path):
    """Texels of the lamp lighting the floor (next-event estimation at the lamp's attached point's
    uv), and the lamp moving with its texture."""
    limn.write_image(tmp_path / "tex.exr", TEXELS)
    d = floor_scene(DIFFUSE)
    d["lamp"]["emitter"]["radiance"] = {"type": "bitmap", "filename": "tex.exr"}
    d["lamp"]["to_world"][0] = {"scale": 1.0}
    scene = limn.load_dict(d, base_dir=tmp_path)
    rng = np.random.default_rng(5)
    t = {"lamp.radiance": rng.normal(size=(2, 2, 3)).astype(np.float32),
         "lamp.to_world.translation": np.float32([0.3, -0.2, 0.4])}
    scene.set_differentiable(list(t))
    fwd = quiet(scene.render_forward, t, seed=6, spp=32, spp_primary=0, spp_boundary=0)
    ref = limn.fd(scene, t, eps=1e-3, spp=32, seed=6, cache=False)
    assert np.abs(ref).mean() > 0.01
    assert rel_rmse(fwd, ref) < 3e-3, rel_rmse(fwd, ref)
    off = quiet(scene.render_forward, t, seed=6, spp_interior=0, spp_primary=0, spp_boundary=0)
    assert rel_rmse(off, ref) > 0.99


def test_bitmap_emitter_errors(tmp_path):
    """Negative or non-finite texels are refused at load (the file and texel named) and when written."""
    limn.write_image(tmp_path / "neg.exr", np.where(np.arange(12).reshape(2, 2, 3) == 7, -1.0, TEXELS).astype(np.float32))
    d = floor_scene(DIFFUSE)
    d["lamp"]["emitter"]["radiance"] = {"type": "bitmap", "filename": "neg.exr"}
    with pytest.raises(ValueError, match=r"emitter 'lamp'.*radiance bitmap '.*neg.exr': texel \(row 1, column 0\) channel 1 "
                                         r"must be finite and >= 0 \(got -1"):
        limn.load_dict(d, base_dir=tmp_path)
    limn.write_image(tmp_path / "tex.exr", TEXELS)
    d["lamp"]["emitter"]["radiance"] = {"type": "bitmap", "filename": "tex.exr"}
    scene = limn.load_dict(d, base_dir=tmp_path)
    scene.params["lamp.radiance"][1, 1, 2] = np.nan
    with pytest.raises(ValueError, match=r"parameter 'lamp.radiance': entry 11 must be finite and >= 0"):
        scene.update()


# ---- spot lights ----------------------------------------------------------------------------------
CUTOFF, BEAM, H_SPOT = 40.0, 25.0, 2.0


def spot_scene(**spot):
    return {"type": "scene", "integrator": {"type": "direct", "bsdf_samples": 0},
            "sensor": camera((0, 0, 6), (0, 0, 0), up=(0, 1, 0), fov=60, width=24, height=24, spp=64),
            "floor": {"type": "rectangle", "to_world": {"scale": 6}, "bsdf": {"type": "diffuse", "reflectance": 0.5}},
            "spot": {"type": "spot", "intensity": 10.0, "cutoff_angle": CUTOFF, "beam_width": BEAM,
                     "to_world": {"look_at": {"origin": [0, 0, H_SPOT], "target": [0, 0, 0], "up": [0, 1, 0]}}, **spot}}


def test_spot_light_known_answer():
    """Mitsuba's spot: I f(theta) with f = 1 inside beam_width, falling linearly in angle to 0 at
    cutoff_angle; a diffuse floor shows rho / pi I f cos / r^2."""
    scene = limn.load_dict(spot_scene())
    img = scene.render(seed=1, spp=256)[..., 0]
    n, sub = 24, 8
    tx = math.tan(math.radians(30))
    s = (np.arange(n * sub) + 0.5) / sub  # sub-pixel film positions
    x = -6 * (1 - 2 * s / n) * tx         # the camera's +x is the world's -x; it sees z = 0 at distance 6
    y = 6 * (1 - 2 * s / n) * tx
    X, Y = np.meshgrid(x, y)
    r2 = X * X + Y * Y + H_SPOT ** 2
    theta = np.degrees(np.arccos(H_SPOT / np.sqrt(r2)))
    f = np.clip((CUTOFF - theta) / (CUTOFF - BEAM), 0, 1)
    L = 0.5 / np.pi * 10.0 * f * (H_SPOT / np.sqrt(r2)) / r2
    expected = L.reshape(n, sub, n, sub).mean(axis=(1, 3))
    assert np.abs(img - expected).max() < 0.03 * expected.max(), np.abs(img - expected).max() / expected.max()
    f_pix = f.reshape(n, sub, n, sub).mean(axis=(1, 3))  # the image covers outside, ramp and inside of the cone
    assert (f_pix == 0).sum() > 100 and ((f_pix > 0) & (f_pix < 1)).sum() > 50 and (f_pix == 1).sum() > 16, f_pix


def test_spot_receiver_motion_matches_fd():
    """The floor rises under the spot: the falloff at each floor point changes (the spot's profile on
    the tape, through the attached point). No visibility changes: the interior term alone."""
    scene = limn.load_dict(spot_scene())
    name = "floor.to_world.translation"
    t = {name: np.float32([0.2, 0.1, 0.5])}
    scene.set_differentiable([name])
    fwd = quiet(scene.render_forward, t, seed=2, spp=64, spp_primary=0, spp_boundary=0)
    ref = limn.fd(scene, t, eps=1e-3, spp=64, seed=2, cache=False)
    assert rel_rmse(fwd, ref) < 3e-3, rel_rmse(fwd, ref)
    assert rel_rmse(quiet(scene.render_forward, t, seed=2, spp_interior=0, spp_primary=0, spp_boundary=0), ref) > 0.99


def spot_shadow_scene():
    d = validation("occluder_point")
    # The shadow's edges lie 0 to 12 degrees off the axis: on the ramp (2 to 25 degrees), where
    # the falloff varies along them (0.6 to 1).
    d["lamp"] = {"type": "spot", "intensity": 30.0, "cutoff_angle": 25.0, "beam_width": 2.0,
                 "to_world": {"look_at": {"origin": [0.6, 0.6, 4.0], "target": [0.4, 0.2, 0.0], "up": [0, 1, 0]}}}
    return load(d)


def test_spot_shadow_of_a_moving_occluder():
    """A spot's shadow edges go through the delta-light boundary term, as a point light's."""
    scene = spot_shadow_scene()
    name = "box.vertex_positions"
    check_term_power(scene, name, x_translation(scene, name), 16)


def test_spot_errors():
    with pytest.raises(ValueError, match=r"beam_width must be in \[0, cutoff_angle = 40.0+\] degrees \(got 50"):
        limn.load_dict(spot_scene(beam_width=50.0))
    with pytest.raises(ValueError, match=r"cutoff_angle must be in \(0, 180\) degrees \(got -1"):
        limn.load_dict(spot_scene(cutoff_angle=-1.0, beam_width=0.0))
    hard = limn.load_dict(spot_scene(beam_width=CUTOFF))
    hard.render(spp=1)  # renders; derivatives of geometry would miss the cone's edge
    hard.set_differentiable(["floor.to_world.translation"])
    with pytest.raises(ValueError, match=r"spot 'spot' has a hard edge \(beam_width = cutoff_angle = 40"):
        hard.render_forward({"floor.to_world.translation": np.float32([0, 0, 1])}, spp=1)


# ---- disks ------------------------------------------------------------------------------------------
def test_disk_emitter_known_answers():
    """An emitting disk (Mitsuba's: the unit disk in local xy, facing +z, placed by to_world) of
    radiance L and radius R at height h over a diffuse floor gives irradiance pi L R^2 / (h^2 + R^2)
    on its axis; seen head-on its image is L times its projected area."""
    R, h, L = 0.5, 1.5, 4.0
    scene = limn.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": camera((0, -0.3, 1), (0, 0, 0), fov=10, width=8, height=8, spp=512),  # below the lamp
        "floor": {"type": "rectangle", "to_world": {"scale": 4}, "bsdf": {"type": "diffuse", "reflectance": 0.5}},
        "lamp": {"type": "disk", "to_world": [{"scale": R}, {"rotate": {"axis": [1, 0, 0], "angle": 180}}, {"translate": [0, 0, h]}],
                 "emitter": {"type": "area", "radiance": L}}})
    img = scene.render(seed=1)
    expected = 0.5 / math.pi * math.pi * L * R * R / (h * h + R * R)
    assert img[3:5, 3:5].mean() == pytest.approx(expected, rel=0.01)
    head_on, ppu = disk_head_on()
    assert head_on.render(seed=2)[..., 0].sum() == pytest.approx(2.0 * math.pi * (0.7 * ppu) ** 2, rel=2e-3)


def disk_head_on():
    """An emitting disk of radius 0.7 and radiance 2 seen head-on, and the film's pixels per unit
    length at its distance."""
    W, fov, Dd = 32, 30.0, 4.0
    head_on = limn.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 1},
                              "sensor": camera((0, -Dd, 0), (0, 0, 0), fov=fov, width=W, height=W, spp=256),
                              "obj": {"type": "disk", "to_world": [{"scale": 0.7}, {"rotate": {"axis": [1, 0, 0], "angle": 90}}],
                                      "emitter": {"type": "area", "radiance": 2.0}}})
    return head_on, W / (2 * math.tan(math.radians(fov) / 2)) / Dd


def test_disk_lamp_derivatives_match_fd():
    """A disk lamp over a floor grows, tilts nowhere and moves: its attached points' area Jacobian
    (r^2 / r0^2) and positions in next-event estimation, against FD and the analytic irradiance
    derivative on the axis, d/dR [pi L R^2 / (h^2 + R^2)] = 2 pi L R h^2 / (h^2 + R^2)^2."""
    R, h, L = 0.5, 1.5, 4.0
    scene = limn.load_dict({
        # Emitter sampling only: the sampled points ride on the lamp, so the image is smooth in its
        # parameters (same-seed FD) and the interior term is the whole derivative.
        "type": "scene", "integrator": {"type": "direct", "bsdf_samples": 0},
        "sensor": camera((0, -0.6, 1), (0, 0, 0), fov=50, width=16, height=16, spp=64),  # below the lamp: the floor only
        "floor": {"type": "rectangle", "to_world": {"scale": 4}, "bsdf": {"type": "diffuse", "reflectance": 0.5}},
        "lamp": {"type": "disk", "to_world": [{"scale": R}, {"rotate": {"axis": [1, 0, 0], "angle": 180}}, {"translate": [0, 0, h]}],
                 "emitter": {"type": "area", "radiance": L}}})
    t = {"lamp.radius": np.float32(1.0), "lamp.to_world.translation": np.float32([0.3, 0.2, -0.4])}
    scene.set_differentiable(list(t))
    fwd = quiet(scene.render_forward, t, seed=3, spp=64, spp_primary=0, spp_boundary=0)
    ref = limn.fd(scene, t, eps=1e-3, spp=64, seed=3, cache=False)
    assert np.abs(ref).mean() > 0.05
    assert rel_rmse(fwd, ref) < 3e-3, rel_rmse(fwd, ref)
    assert rel_rmse(quiet(scene.render_forward, t, seed=3, spp_interior=0, spp_primary=0, spp_boundary=0), ref) > 0.99
    # The radius alone, at the pixel that sees the axis (the camera looks at the origin).
    only_r = {"lamp.radius": np.float32(1.0), "lamp.to_world.translation": np.float32([0, 0, 0])}
    d = quiet(scene.render_forward, only_r, seed=4, spp=1024, spp_primary=0, spp_boundary=0)[7:9, 7:9, 0].mean()
    assert d == pytest.approx(0.5 / math.pi * 2 * math.pi * L * R * h * h / (h * h + R * R) ** 2, rel=0.01)


def test_disk_rim_matches_the_analytic_derivative():
    """The rim is the primary term's silhouette: d(image sum)/dR = L 2 pi R (pixels per unit)^2."""
    head_on, ppu = disk_head_on()
    head_on.set_differentiable(["obj.radius"])
    f = quiet(head_on.render_forward, {"obj.radius": np.float32(1.0)}, spp_interior=4, spp_primary=16, seed=0)
    assert f[..., 0].sum() == pytest.approx(2.0 * 2 * math.pi * 0.7 * ppu ** 2, rel=1e-4)
    off = quiet(head_on.render_forward, {"obj.radius": np.float32(1.0)}, spp_interior=4, spp_primary=0, seed=0)
    assert abs(off.sum()) < 1e-3 * abs(f.sum())


def test_disk_silhouette_against_finite_differences(tmp_path):
    """A tilted disk in an environment moves and grows: interior + primary against FD."""
    env = np.ones((16, 32, 3), np.float32) * np.linspace(0.2, 1.0, 16)[:, None, None]
    limn.write_image(tmp_path / "sky.exr", env)
    scene = limn.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 3},
                            "sensor": camera((0, -4, 0), (0, 0, 0), fov=35, width=16, height=16, spp=64),
                            "obj": {"type": "disk", "to_world": [{"scale": 0.9}, {"rotate": {"axis": [1, 0.3, 0], "angle": 60}}],
                                    "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": 0.3}}},
                            "sky": {"type": "envmap", "filename": "sky.exr", "to_world": {"rotate": {"axis": [1, 0, 0], "angle": 90}}}},
                           base_dir=tmp_path)
    t = {"obj.to_world.translation": np.float32([1.0, 0.0, 0.3]), "obj.radius": np.float32(0.5)}
    scene.set_differentiable(list(t))
    fd = np.stack([limn.fd(scene, t, eps=2e-2, spp=1024, seed=30 + k, cache=False) for k in range(6)])
    on = np.stack([quiet(scene.render_forward, t, spp=128, spp_primary=128, seed=40 + k) for k in range(6)])
    off = np.stack([quiet(scene.render_forward, t, spp=128, spp_primary=0, seed=40 + k) for k in range(6)])
    z_on, z_off = block_z(on, fd), block_z(off, fd)
    print(f"disk silhouette: max |z| {np.abs(z_on).max():.2f} with the primary term, {np.abs(z_off).max():.2f} without")
    assert np.abs(z_on).max() < 4.5, z_on
    assert np.abs(z_off).max() > 10, z_off
    for k in (0.8, 1.25):  # the primary term scaled (the same seeds)
        z_k = np.abs(block_z(off + k * (on - off), fd)).max()
        print(f"disk silhouette: primary term x{k}: max |z| {z_k:.2f}")
        assert z_k > 5.0, (k, z_k)


def disk_occluder(light):
    d = validation("occluder_" + light)
    del d["box"]
    d["plate"] = {"type": "disk", "to_world": [{"scale": 0.4}, {"rotate": {"axis": [1, 0, 0], "angle": 25}}, {"translate": [0.4, 0.2, 1.2]}],
                  "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": 0.4}}}
    return load(d)


@pytest.mark.parametrize("light,spp_boundary", [("point", 16), ("area", 512)], ids=["point light", "area light"])
@pytest.mark.parametrize("name,t", [("plate.to_world.translation", [1.0, 0.0, 0.0]), ("plate.radius", 1.0)], ids=["translation", "radius"])
def test_disk_shadow(light, spp_boundary, name, t):
    """The rim as the perimeter part of Eq. 4 (sin phi dl dw), and a point light's direction through
    any rim point."""
    scene = disk_occluder(light)
    t = np.float32(t)
    check_term_power(scene, name, t, spp_boundary)
    quiet(scene.render_forward, {name: t}, spp=1, spp_boundary=spp_boundary)
    assert any("1 disk rims" in line for line in scene.last_stats["summary"]), scene.last_stats["summary"]


def test_disk_backward_matches_forward():
    scene = disk_occluder("area")
    names = ["plate.to_world.translation", "plate.radius"]
    scene.set_differentiable(names)
    rng = np.random.default_rng(8)
    t = {n: rng.normal(size=scene.params[n].shape).astype(np.float32) for n in names}
    adjoint = rng.normal(size=(16, 16, 3)).astype(np.float32)
    fwd = quiet(scene.render_forward, t, spp=16, spp_boundary=64, seed=9)
    grads = quiet(scene.render_backward, adjoint, spp=16, spp_boundary=64, seed=9)
    lhs = float((adjoint.astype(np.float64) * fwd).sum())
    rhs = sum(float((grads[n].astype(np.float64) * t[n]).sum()) for n in names)
    assert abs(lhs - rhs) <= 1e-3 * abs(rhs), (lhs, rhs)


def test_disk_errors():
    base = {"type": "scene", "sensor": camera((0, -3, 0), (0, 0, 0), width=8, height=8, spp=4)}
    with pytest.raises(ValueError, match="'to_world' must be a rotation, uniform scale and translation"):
        limn.load_dict({**base, "d": {"type": "disk", "to_world": {"scale": [1, 2, 1]}}})
    scene = limn.load_dict({**base, "d": {"type": "disk"}})
    scene.params["d.radius"][...] = -1.0
    with pytest.raises(ValueError, match=r"parameter 'd.radius': must be finite and > 0 \(got -1"):
        scene.update()
