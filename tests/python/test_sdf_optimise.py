"""The signed-distance grid optimisation of issue 37 (tests/bench/sdf_optimise.py,
docs/reports/sdf/optimisation.md) on a tiny grid: the image loss and the Chamfer error to the bunny
fall, and the loop's redistancing keeps a distance field. The grid helpers themselves (limn.sdf:
zero_set, redistance, smooth_gradient, upsample) are tested in test_sdf_redistance.py."""
from __future__ import annotations

import os
import sys

import numpy as np
import pytest

import limn
from limn import sdf
from conftest import ROOT

sys.path.insert(0, os.path.join(ROOT, "tests", "bench"))
import sdf_optimise as so  # noqa: E402


@pytest.mark.parametrize("k", [4, 0])
def test_optimisation_lowers_loss_and_chamfer_and_stays_a_distance_field(k):
    """A 12^3 sphere grid, two 24 x 24 px views of the bunny, 16 iterations, redistancing every 4:
    the image loss (measured at 64 spp with fixed seeds, not the noisy training estimate) and the
    Chamfer error fall, and the final grid is a distance field away from its surface. The start is
    the sphere's distance times 2 (the same surface, |grad f| = 2), so the last check fails unless
    the loop's redistancing works: k = 0 (never) is expected to fail it."""
    n, its = 12, 16
    bunny = so.read_bunny()
    start = 2.0 * so.sphere_grid(n)
    r = so.optimise(n=n, size=24, views=2, iterations=its, lr=6e-3, k=k, spp=8, verbose=False, bunny=bunny,
                    chamfer_every=its, start=start)
    first = [limn.load_dict(so.view({"type": "sdfgrid", "data": start, "to_world": so.TO_WORLD}, o, 24))
             for o in so.ORIGINS[:2]]

    def loss(scenes):
        return sum(limn.optim.l2(s.render(spp=64, seed=99 + i), t)[0] for i, (s, t) in enumerate(zip(scenes, r["targets"])))

    loss0, loss1 = loss(first), loss(r["scenes"])
    c0, c1 = r["history"][0]["chamfer"], r["history"][-1]["chamfer"]
    assert loss1 < 0.8 * loss0, (loss0, loss1)
    assert c1 < 0.9 * c0, (c0, c1)
    grid = r["grid"].astype(np.float64)
    h = 1.0 / (n - 1)
    g = sdf.gradient_norm(grid)
    away = np.abs(grid[1:-1, 1:-1, 1:-1]) > 1.5 * h
    assert away.sum() > 100
    distance_field = (np.median(np.abs(g[away] - 1)) < 0.05 and np.percentile(np.abs(g[away] - 1), 90) < 0.15)
    assert distance_field == (k > 0), np.percentile(g[away], [5, 50, 95])
