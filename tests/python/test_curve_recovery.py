"""The hair-tuft recovery of issue 36 (tests/bench/curve_recovery.py, docs/reports/curves/recovery.md)
reduced: 2 curves of 5 control points, 2 views at 32x32. The fit must bring the centre lines and the
control points much closer to the target's; it must fail with the gradient zeroed
(LIMN_CURVE_RECOVERY_ZERO_GRADIENT=1 runs the same test on zeros, and it fails: the error does not
move). Also limn.optim.curve_faces: LargeSteps over it is the path Laplacian of each curve."""
from __future__ import annotations

import os
import sys

import numpy as np
import pytest

from conftest import ROOT
from limn import optim

sys.path.insert(0, os.path.join(ROOT, "tests", "bench"))
import curve_recovery as cr  # noqa: E402


def test_curve_faces_give_the_path_laplacian_of_each_curve():
    offsets, n, lam = [0, 4, 9], 12, 3.0
    ls = optim.LargeSteps(optim.curve_faces(offsets, n), n, lam)
    L = np.zeros((n, n))
    for a, b in zip(offsets, offsets[1:] + [n]):
        for i in range(a, b - 1):
            L[i, i] += 1
            L[i + 1, i + 1] += 1
            L[i, i + 1] = L[i + 1, i] = -1
    x = np.random.default_rng(3).normal(size=(n, 4))
    np.testing.assert_allclose(ls.to_u(x), (np.eye(n) + lam * L) @ x, rtol=1e-12, atol=1e-12)
    for bad in ([1, 4], [0, 1], [0, 11]):
        with pytest.raises(ValueError, match="offsets"):
            optim.curve_faces(bad, n)


def test_adam_takes_a_learning_rate_per_column():
    x = np.ones((3, 4))
    opt = optim.Adam(x, lr=np.array([0.1, 0.1, 0.1, 0.01]))
    opt.step(np.ones((3, 4)))
    np.testing.assert_allclose(x, [[0.9, 0.9, 0.9, 0.99]] * 3, atol=1e-7)
    with pytest.raises(ValueError, match="broadcast"):
        optim.Adam(x, lr=np.array([0.1, 0.1]))
    with pytest.raises(ValueError, match="lr"):
        optim.Adam(x, lr=np.array([0.1, 0.1, 0.1, -1.0]))


def test_centre_line_distance_is_zero_on_itself_and_a_shift_otherwise():
    target, start, offsets = cr.tuft(2, 5)
    assert cr.geometric_error(target, target, offsets)[:2] == (0.0, 0.0)
    shifted = target.copy()
    shifted[:, 0] += 0.1
    cp, line, rad = cr.geometric_error(shifted, target, offsets)
    assert cp == pytest.approx(0.1, rel=1e-6) and 0.05 < line <= 0.1 + 1e-6 and rad == 0.0


def test_a_tuft_is_recovered_from_two_views():
    zero = os.environ.get("LIMN_CURVE_RECOVERY_ZERO_GRADIENT") == "1"
    out = cr.run(iterations=50, size=32, views=2, curves=2, points=5, lr=0.03, lr_radius=0.003, lambda_=4.0, spp=4,
                 spp_boundary=16, levels=3, target_spp=128, zero_gradient=zero)
    rows = out["rows"]
    first, last = rows[0], rows[-1]
    print(f"tuft recovery: loss {first[2]:.3e} -> {last[2]:.3e}, control-point RMS {first[3]:.4f} -> {last[3]:.4f}, "
          f"centre line {first[4]:.4f} -> {last[4]:.4f}, {last[1]:.1f} s{' (gradient zeroed)' if zero else ''}")
    assert not out["diverged"]
    assert last[4] < first[4] / 3.0
    assert last[3] < first[3] / 2.0
    assert (out["final"][:, 3] >= cr.RADIUS_FLOOR - 1e-7).all()
