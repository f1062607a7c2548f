"""The non-finite policy at run time (docs/scene-format.md, "Non-finite values"): a finite input
gives finite outputs or is refused with an error naming the object, the field and the value;
invalid samples and rays inside the loops are counted, never written; optimisers stop at divergence
and keep the last good state."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import limn
from conftest import sphere_over_plane


def small_scene():
    return limn.load_dict(sphere_over_plane(width=12, height=12, spp=2))


def test_thread_counts_beyond_the_limit_are_refused():
    scene = small_scene()
    with pytest.raises(ValueError, match=r"threads must be in \[0, 1024\].*got 1000000"):
        scene.render(threads=10**6)
    scene.set_differentiable(["ball.center"])
    with pytest.raises(ValueError, match=r"threads must be in \[0, 1024\].*got 1000000"):
        scene.render_forward({"ball.center": np.ones(3)}, spp=1, threads=10**6)
    with pytest.raises(ValueError, match=r"threads must be in \[0, 1024\]"):
        scene.render_backward(np.ones((12, 12, 3), np.float32), spp=1, threads=-1)


def test_an_overflowing_derivative_is_refused_naming_its_input():
    """Finite tangents and adjoints so large that the sums overflow: an error naming the input and
    its size, never inf in the result. Moderate ones stay finite."""
    scene = small_scene()
    scene.set_differentiable(["ball.center"])
    with pytest.raises(ValueError, match=r"derivative image overflowed.*'ball.center' up to 1e\+300"):
        scene.render_forward({"ball.center": np.array([1e300, 0, 0])}, spp=2)
    with pytest.raises(ValueError, match=r"gradient of 'ball.center' overflowed.*adjoint reaches 1e\+38"):
        scene.render_backward(np.full((12, 12, 3), 1e38, np.float32), spp=2)
    img = scene.render_forward({"ball.center": np.array([1e3, 0, 0])}, spp=2)
    assert np.isfinite(img).all() and np.abs(img).max() > 0
    grads = scene.render_backward(np.full((12, 12, 3), 1e3, np.float32), spp=2)
    assert np.isfinite(grads["ball.center"]).all() and np.abs(grads["ball.center"]).max() > 0


def test_a_translation_that_moves_geometry_out_of_range_is_refused_and_rolled_back():
    """update() checks the moved geometry, not only the translation: a finite 3e38 would put the
    floor's vertices where no ray can be traced (Embree's limit is 1.8e18), or at inf."""
    scene = small_scene()
    before = scene.params["floor.vertex_positions"].copy()
    for t in ([3e38, 0, 0], [0, 2e18, 0]):
        scene.params["floor.to_world.translation"] = t
        with pytest.raises(ValueError, match=r"'floor.to_world.translation'.*moves shape 'floor'.*beyond the traceable range"):
            scene.update()
        assert np.array_equal(scene.params["floor.vertex_positions"], before)
        assert np.array_equal(scene.params["floor.to_world.translation"], [0, 0, 0])
    scene.params["ball.to_world.translation"] = [0, 0, 3.4e38]
    with pytest.raises(ValueError, match=r"moves shape 'ball'"):
        scene.update()
    scene.params["floor.to_world.translation"] = [0.5, 0, 0]  # a valid one still moves it
    assert "floor.to_world.translation" in scene.update()
    assert np.allclose(scene.params["floor.vertex_positions"][:, 0], before[:, 0] + 0.5)
    assert np.isfinite(scene.render(spp=1)).all()


def test_update_refuses_degenerate_triangles_as_loading_does():
    scene = small_scene()
    v = scene.params["floor.vertex_positions"]
    faces = scene.faces("floor")
    a, b, c = faces[0]
    v[c] = v[a] + 0.5 * (v[b] - v[a])  # the third corner onto the first edge: zero area
    with pytest.raises(ValueError, match=r"'floor.vertex_positions'.*triangle 0 is degenerate"):
        scene.update()


def test_geometry_beyond_the_traceable_range_is_refused_not_called_degenerate():
    """A valid triangle at 1e37 is refused for its range (rays leaving it could not be traced), not
    called degenerate (its area overflows float; the test is done in double); at 1e17 it is fine."""
    scene = small_scene()
    v = scene.params["floor.vertex_positions"]
    before = v.copy()
    v *= 1e37
    with pytest.raises(ValueError, match=r"'floor.vertex_positions': vertex \d+ .* is beyond the traceable range") as e:
        scene.update()
    assert "degenerate" not in str(e.value)
    assert np.array_equal(scene.params["floor.vertex_positions"], before)
    scene.params["floor.vertex_positions"] = before * 1e17
    scene.update()
    scene.params["ball.radius"] = 2e18
    with pytest.raises(ValueError, match=r"'ball.radius'.*beyond the traceable range"):
        scene.update()


def test_adam_refuses_non_finite_hyper_parameters():
    x = np.zeros(3)
    for kwargs, message in (({"lr": np.inf}, "lr must be finite"), ({"lr": 0.0}, "lr must be finite and > 0"),
                            ({"betas": (1.0, 1.0)}, r"betas must be two numbers in \[0, 1\)"),
                            ({"betas": (0.9, np.nan)}, "betas"), ({"eps": 0.0}, "eps must be finite and > 0")):
        with pytest.raises(ValueError, match=message):
            limn.optim.Adam(x, **kwargs)
    with pytest.raises(ValueError, match="non-finite"):
        limn.optim.Adam(np.array([np.nan]))
    opt = limn.optim.Adam(x, lr=1.0)
    with pytest.raises(ValueError, match="step is not finite"):
        opt.step(np.array([1e200, 0, 0]))  # g * g overflows
    assert np.array_equal(x, np.zeros(3))  # unchanged
    x32 = np.zeros(3, np.float32)
    opt = limn.optim.Adam(x32, lr=1e300)  # a finite float64 step, inf in float32 (was written into x32)
    with pytest.raises(ValueError, match=r"step \(lr 1e\+300\) takes the parameters beyond the range of float32"):
        opt.step(np.ones(3))
    assert np.array_equal(x32, np.zeros(3)) and opt.t == 0


def test_fit_stops_at_divergence_and_keeps_the_last_good_state():
    """lr 1e8 would throw the ball's centre to 1e8: the first such step is refused, the loop stops
    with a warning that says why, and the scene keeps the last good centre."""
    target_scene = small_scene()
    target = target_scene.render(spp=4)
    scene = small_scene()
    scene.params["ball.center"] = [0.2, 0, 0.7]
    scene.update()
    with pytest.warns(UserWarning, match="more than 0.5 of the bounding-box diagonal"):
        result = limn.optim.fit([(scene, target)], "ball.center", iterations=5, lr=1e8, spp=2)
    assert result.diverged and len(result.losses) == 1
    assert np.allclose(scene.params["ball.center"], [0.2, 0, 0.7])
    # A sane learning rate runs to the end without a word.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = limn.optim.fit([(scene, target)], "ball.center", iterations=2, lr=1e-3, spp=2)
    assert not result.diverged and len(result.losses) == 2


def test_sample_counts_beyond_the_limit_are_refused_naming_the_option():
    """2^31 - 1 samples per pixel was accepted and ran for days (the hostile battery's hangs); a
    count beyond C++'s int was pybind11's cast error naming neither the option nor the value."""
    scene = small_scene()
    with pytest.raises(ValueError, match=r"spp must be in \[1, 1048576\] \(got 2147483647\)"):
        scene.render(spp=2**31 - 1)
    scene.set_differentiable(["ball.center"])
    for option in ("spp", "spp_interior", "spp_primary", "spp_boundary"):
        with pytest.raises(ValueError, match=rf"{option} must be in \[0, 1048576\].*got 2147483647"):
            scene.render_forward({"ball.center": np.ones(3)}, **{option: 2**31 - 1})
    with pytest.raises(ValueError, match=r"derivative option 'spp' has the wrong type or is out of range \(got 1000000000000\)"):
        scene.render_backward(np.ones((12, 12, 3), np.float32), spp=10**12)
    d = sphere_over_plane(width=12, height=12, spp=2)
    d["sensor"]["sampler"]["sample_count"] = 2**30
    with pytest.raises(ValueError, match=r"sample_count must be in \[1, 1048576\] \(got 1073741824\)"):
        limn.load_dict(d)
