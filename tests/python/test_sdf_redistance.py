"""The grid helpers of limn.sdf used by every optimisation of sdfgrid values (the bench
tests/bench/sdf_optimise.py, the Blender add-on's SDF mode): the zero set of the trilinear
interpolant, the brute-force redistancing (local and world units), the Sobolev gradient smoother
and exact upsampling. Each check is also run on an input that must fail it."""
from __future__ import annotations

import numpy as np
import pytest

from limn import sdf


def sphere_grid(n, radius=0.3):
    """The signed distance to a sphere of ``radius`` around the unit cube's centre, n^3 corners,
    [z, y, x] (float32 values, as the bench's start grid, returned as float64)."""
    z, y, x = np.meshgrid(*[np.linspace(0, 1, n)] * 3, indexing="ij")
    return (np.sqrt((x - .5) ** 2 + (y - .5) ** 2 + (z - .5) ** 2) - radius).astype(np.float32).astype(np.float64)


def exact_sphere(n, radius=0.3):
    return sphere_grid(n, radius)


def interpolate(f, p):
    """The trilinear interpolant of f ([z, y, x]) at local points p (P, 3)."""
    n = np.array(f.shape[::-1]) - 1
    q = p * n
    i = np.minimum(q.astype(int), n - 1)
    u, v, w = (q - i).T
    val = 0.0
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                val = val + f[i[:, 2] + dz, i[:, 1] + dy, i[:, 0] + dx] * (u if dx else 1 - u) * (v if dy else 1 - v) * (w if dz else 1 - w)
    return val


def test_zero_set_points_lie_on_the_trilinear_surface():
    """Every root found on the axis lines is a zero of the interpolant (to rounding) and lies within
    a quarter voxel of the sphere (the trilinear surface of a scaled sphere distance is O(h^2) off)."""
    n = 12
    f = exact_sphere(n) * (1.0 + 0.3 * np.linspace(0, 1, n))[None, None, :]  # not a distance field
    p = sdf.zero_set(f, 3)
    assert len(p) > 100
    val = interpolate(f, p)
    assert np.abs(val).max() < 1e-12
    r = np.linalg.norm(p - 0.5, axis=1)
    assert np.abs(r - 0.3).max() < 0.25 / (n - 1)


@pytest.mark.parametrize("n", [12, 24])
def test_redistancing_makes_a_distance_field_and_keeps_the_surface(n):
    """A sphere's signed distance multiplied by a smooth positive factor (same corner signs, |grad f|
    between 0.4 and 2.6) becomes the sphere's signed distance again: |grad f| = 1 away from the
    surface, the values as close to the exact distance as the trilinear zero set is to the sphere
    (plus 0.05 voxel), the zero set moved by no more than trilinear interpolation's sag. The bent
    field itself fails the first two checks."""
    h = 1.0 / (n - 1)
    exact = exact_sphere(n)
    z, y, x = np.meshgrid(*[np.linspace(0, 1, n)] * 3, indexing="ij")
    bent = exact * (1.5 + np.sin(4 * x) * np.cos(3 * y) * 1.1)
    r = sdf.redistance(bent)

    def checks(f):
        g = sdf.gradient_norm(f)
        e = exact[1:-1, 1:-1, 1:-1]
        # central differences straddle neither the surface nor the centre (the distance's kink)
        away = (np.abs(e) > 1.5 * h) & (e > -0.3 + 1.5 * h)
        # How far the zero set moved (first-order distance of its points to the bent field's zero set):
        # trilinear interpolation of exact distances sags between corners by the sagitta of a voxel-long
        # chord on the sphere, h^2 / (8 r); 0.02 voxel more for the tangent-plane distances.
        p = sdf.zero_set(f, 3)
        shift = (np.abs(interpolate(bent, p)) / np.linalg.norm(sdf.trilinear_gradient(bent, p), axis=1)).max()
        # The distance is to the trilinear zero set, itself up to `surface` from the sphere; 0.05
        # voxel more for the tangent planes of a surface whose normal jumps at voxel faces.
        return (np.abs(g[away] - 1).max() < 0.1,
                np.abs(f - exact).max() < surface + 0.05 * h,
                shift < h * h / (8 * 0.3) + 0.02 * h)

    surface = np.abs(np.linalg.norm(sdf.zero_set(bent, 3) - 0.5, axis=1) - 0.3).max()
    assert surface < 0.1 * h  # the bent field's trilinear zero set is close to the sphere

    assert all(checks(r)), checks(r)
    assert not any(checks(bent)[:2]), checks(bent)  # the test can fail: the bent field is no distance field
    # the sign is the old value's everywhere
    assert ((r < 0) == (bent < 0)).all()
    # Repeated passes: each re-samples the surface trilinearly, which sags inwards on a convex surface
    # (above); the mean radius drifts by less than half that sag per pass.
    radius = lambda f: np.linalg.norm(sdf.zero_set(f, 3) - 0.5, axis=1).mean()
    again = r
    for _ in range(5):
        again = sdf.redistance(again)
    drift = (radius(r) - radius(again)) / 5
    assert 0 <= drift < 0.5 * h * h / (8 * 0.3), drift / h


def test_smoothed_gradient_solves_the_sobolev_system():
    """smooth_gradient returns s with (I + lambda L) s = g (7-point Laplacian, periodic), checked by
    applying the operator; lambda 0 returns g."""
    rng = np.random.default_rng(3)
    g = rng.standard_normal((6, 7, 8))
    lam = 4.0
    s = sdf.smooth_gradient(g, lam)
    lap = sum(2 * s - np.roll(s, 1, a) - np.roll(s, -1, a) for a in range(3))
    np.testing.assert_allclose(s + lam * lap, g, atol=1e-12)
    assert np.abs(s).max() < 0.5 * np.abs(g).max()  # it smooths
    assert sdf.smooth_gradient(g, 0.0) is g


def test_upsampling_keeps_the_interpolant():
    """n -> 2n - 1 samples: the fine grid's trilinear interpolant equals the coarse one everywhere
    (inside a coarse voxel each fine voxel's interpolant is the same trilinear function)."""
    rng = np.random.default_rng(4)
    f = rng.standard_normal((5, 6, 7))
    u = sdf.upsample(f)
    assert u.shape == (9, 11, 13)
    p = rng.random((500, 3))
    np.testing.assert_allclose(interpolate(u, p), interpolate(f, p), atol=1e-12)
    assert np.abs(interpolate(u[:, :, ::-1], p) - interpolate(f, p)).max() > 0.1  # the check can fail


def test_redistancing_a_scaled_sphere_in_world_units():
    """A sphere's signed distance times 3 (|grad f| = 3, the same zero set) on a box of 2 x 1.6 x 1.2
    world units with cubic voxels of h = 0.1 (21 x 17 x 13 samples), as the Blender add-on's grids
    are: with the box's extent, redistancing gives |grad f| = 1 per world unit away from the
    surface, values within the trilinear zero set's distance to the sphere (plus 0.05 h) of the
    exact world distance, and moves the zero set by no more than trilinear interpolation's sag
    h^2 / (8 r) plus 0.02 h (as in the test above). The scaled field itself (a no-op) and the
    result in local units (no extent) fail the value check."""
    h, r = 0.1, 0.47  # no corner exactly on the sphere (its sign would be that of rounding)
    extent = np.array([2.0, 1.6, 1.2])
    nx, ny, nz = (np.round(extent / h).astype(int) + 1)
    z, y, x = np.meshgrid(np.linspace(0, 1, nz) * extent[2], np.linspace(0, 1, ny) * extent[1],
                          np.linspace(0, 1, nx) * extent[0], indexing="ij")
    centre = (1.1, 0.8, 0.6)
    exact = np.sqrt((x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2) - r
    scaled = 3.0 * exact
    out = sdf.redistance(scaled, extent=extent)
    assert out.shape == scaled.shape and ((out < 0) == (scaled < 0)).all()

    surface_pts = sdf.zero_set(scaled) * extent
    surface = np.abs(np.linalg.norm(surface_pts - centre, axis=1) - r).max()
    assert surface < 0.1 * h

    def checks(f):
        g = sdf.gradient_norm(f, extent)
        e = exact[1:-1, 1:-1, 1:-1]
        # central differences straddle neither the surface nor the centre (2.5 h: the exact distance's
        # own central differences are 1 within 0.1 there)
        away = (np.abs(e) > 1.5 * h) & (e > -r + 2.5 * h)
        p = sdf.zero_set(f)
        grad = sdf.trilinear_gradient(scaled, p) / extent  # per world unit
        shift = (np.abs(interpolate(scaled, p)) / np.linalg.norm(grad, axis=1)).max()
        return (np.abs(g[away] - 1).max() < 0.1, np.abs(f - exact).max() < surface + 0.05 * h,
                shift < h * h / (8 * r) + 0.02 * h)

    assert all(checks(out)), checks(out)
    assert not any(checks(scaled)[:2]), checks(scaled)          # a no-op redistance fails
    assert not checks(sdf.redistance(scaled))[1]                # local units are not world distances
    assert sdf.distance_field_error(out, extent) < 0.05 < sdf.distance_field_error(scaled, extent)


def test_redistance_edge_cases():
    """No zero crossing: unchanged (a copy). Non-finite values and a bad extent: ValueError."""
    f = np.full((4, 5, 6), 0.7)
    out = sdf.redistance(f)
    assert out is not f and np.array_equal(out, f)
    bad = sphere_grid(6)
    bad[2, 2, 2] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        sdf.redistance(bad)
    with pytest.raises(ValueError, match="extent must be three finite sizes"):
        sdf.redistance(sphere_grid(6), extent=(1.0, 0.0, 1.0))
