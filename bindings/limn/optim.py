"""Optimisation: Adam, the Large-Steps preconditioner for meshes, image losses, a multi-view loop.

    views = [(scene_a, target_a), (scene_b, target_b)]     # scenes that share the parameter name
    result = limn.optim.fit(views, "shape.vertex_positions", iterations=100, lr=0.02, lambda_=20)

Large Steps (Nicolet et al. 2021) optimises u = (I + lambda L) x instead of the vertices x; the
gradient with respect to u is (I + lambda L)^-1 times the gradient with respect to x, computed with
a sparse Cholesky factorisation in the C++ core (Eigen)."""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from . import _core


class Adam:
    """Adam (Kingma and Ba 2015) on one array, updated in place. ``lr`` is a number or an array
    that broadcasts to x (e.g. one rate per column: a fibre's radii move slower than its points)."""

    def __init__(self, x: np.ndarray, lr=1e-2, betas=(0.9, 0.999), eps: float = 1e-8):
        lr_array = np.asarray(lr, dtype=np.float64)
        if not (np.isfinite(lr_array).all() and (lr_array > 0).all()):
            raise ValueError(f"Adam: lr must be finite and > 0 (got {lr})")
        try:
            np.broadcast_to(lr_array, np.shape(x))
        except ValueError:
            raise ValueError(f"Adam: lr of shape {lr_array.shape} does not broadcast to the parameters' shape {np.shape(x)}") from None
        lr = float(lr_array) if lr_array.ndim == 0 else lr_array
        betas = tuple(betas)
        if len(betas) != 2 or not all(math.isfinite(b) and 0.0 <= b < 1.0 for b in betas):
            raise ValueError(f"Adam: betas must be two numbers in [0, 1) (got {betas})")
        if not (math.isfinite(eps) and eps > 0):
            raise ValueError(f"Adam: eps must be finite and > 0 (got {eps})")
        if not np.isfinite(x).all():
            raise ValueError("Adam: the parameters have non-finite values")
        self.x, self.lr, self.b1, self.b2, self.eps = x, lr, betas[0], betas[1], eps
        self.m = np.zeros_like(x, dtype=np.float64)
        self.v = np.zeros_like(x, dtype=np.float64)
        self.t = 0

    def step(self, grad: np.ndarray) -> None:
        g = np.asarray(grad, dtype=np.float64)
        if g.shape != self.x.shape:
            raise ValueError(f"Adam: gradient shape {g.shape} != parameter shape {self.x.shape}")
        if not np.isfinite(g).all():
            raise ValueError("Adam: the gradient has non-finite values")
        with np.errstate(over="ignore", invalid="ignore"):
            m = self.b1 * self.m + (1 - self.b1) * g
            v = self.b2 * self.v + (1 - self.b2) * g * g
            m_hat = m / (1 - self.b1 ** (self.t + 1))
            v_hat = v / (1 - self.b2 ** (self.t + 1))
            step = self.lr * m_hat / (np.sqrt(v_hat) + self.eps)
        if not (np.isfinite(v).all() and np.isfinite(step).all()):  # the state and the parameters stay as they were
            raise ValueError("Adam: the step is not finite (the gradient's square overflows)")
        with np.errstate(over="ignore", invalid="ignore"):
            x = self.x - step.astype(self.x.dtype)
        if not np.isfinite(x).all():  # a finite float64 step beyond the parameters' type (lr 1e300, float32)
            raise ValueError(f"Adam: the step (lr {np.max(self.lr):g}) takes the parameters beyond the range of {self.x.dtype}; lower lr")
        self.t, self.m, self.v = self.t + 1, m, v
        self.x[...] = x


def grid_faces(rows: int, columns: int) -> np.ndarray:
    """Triangles (F x 3) of a rows x columns grid of points indexed row-major: the connectivity a
    heightfield's Laplacian is taken over (Large Steps on heights). With row 0 at the far edge (+y)
    and column 0 at -x, as limn's heightfields, they wind counter-clockwise seen from +z (face up)."""
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(columns - 1), indexing="ij")
    a = (r * columns + c).ravel()
    b, d, e = a + 1, a + columns, a + columns + 1  # right, below (towards -y), diagonal
    return np.concatenate([np.stack([a, e, b], 1), np.stack([a, d, e], 1)]).astype(np.int64)


class LargeSteps:
    """u = (I + lambda L) x and back, for N points x (N x k: vertex positions k = 3, heights k = 1)
    connected by faces (F x 3)."""

    def __init__(self, faces, vertex_count: int, lambda_: float):
        self._native = _core.LargeSteps(np.asarray(faces, dtype=np.int64), int(vertex_count), float(lambda_))

    def to_u(self, x) -> np.ndarray:
        return self._native.to_u(np.asarray(x, dtype=np.float64))

    def from_u(self, u) -> np.ndarray:
        return self._native.from_u(np.asarray(u, dtype=np.float64))

    def gradient_u(self, grad_x) -> np.ndarray:
        """dLoss/du from dLoss/dx (M is symmetric: M^-T = M^-1)."""
        return self.from_u(grad_x)


def curve_faces(offsets, point_count: int) -> np.ndarray:
    """Degenerate triangles (i, i + 1, i + 1) for consecutive control points of each fibre curve
    (``offsets``: the first point of each curve, as the scene's ``curve_offsets``): LargeSteps keeps
    their unique edges, so its L is the path Laplacian along each curve and no edge joins two
    curves (Large Steps on ``"<id>.control_points"``, the radius column smoothed as the positions)."""
    starts = np.asarray(offsets, dtype=np.int64).ravel()
    n = int(point_count)
    if starts.size == 0 or starts[0] != 0 or (np.diff(starts) < 2).any() or starts[-1] > n - 2:
        raise ValueError(f"curve_faces: offsets {starts.tolist()} must start at 0 and leave >= 2 points per curve "
                         f"of the {n} points")
    ends = np.append(starts[1:], n)
    i = np.concatenate([np.arange(a, b - 1) for a, b in zip(starts, ends)])
    return np.stack([i, i + 1, i + 1], 1).astype(np.int64)


def l2(image: np.ndarray, target: np.ndarray):
    """Mean squared error and its derivative with respect to the image."""
    d = image.astype(np.float64) - target
    return float((d * d).mean()), (2.0 * d / d.size).astype(np.float32)


def l1(image: np.ndarray, target: np.ndarray):
    """Mean absolute error and its derivative with respect to the image."""
    d = image.astype(np.float64) - target
    return float(np.abs(d).mean()), (np.sign(d) / d.size).astype(np.float32)


@dataclass
class FitResult:
    losses: list = field(default_factory=list)
    seconds: list = field(default_factory=list)   # elapsed time at each iteration
    cancelled: bool = False
    diverged: str = ""   # why the loop stopped early, keeping the last good parameters ("" if it did not)


# Divergence: one Adam step that moves any point by more than this share of the parameters'
# bounding-box diagonal (the optimiser's steps are a small share of it when it converges).
MAX_STEP = 0.5


def fit(views, name: str, iterations: int = 100, lr: float = 0.01, lambda_: float = 20.0, loss=l2, spp: int = 8,
        spp_primary: int | None = None, spp_boundary: int | None = None, mask=None, faces=None, callback=None,
        seed: int = 0, options: dict | None = None, project=None, gradient=None) -> FitResult:
    """Optimise the vertex positions ``name`` (shared by every scene in ``views``, a list of
    (scene, target image) pairs) to match the targets. ``faces`` (F x 3) enables Large Steps with
    ``lambda_`` (0 disables it); ``mask`` (N,) of 0/1 holds vertices with 0 fixed.
    ``callback(iteration, loss, vertices)`` may return False to stop (the last good state stays).
    ``options`` go to every ``render_backward`` call (e.g. ``guiding``, ``grid_resolution``).
    The loop stops early and keeps the last good parameters, with a warning and
    ``FitResult.diverged`` saying why, when the loss or the gradient is not finite, a step is not
    finite or moves a point by more than ``MAX_STEP`` of the bounding-box diagonal, or the scene
    refuses the new parameters (e.g. a triangle collapsed).
    A heightfield's ``"<id>.heights"`` (rows x columns) works the same way: ``faces`` from
    :func:`grid_faces`, ``mask`` of shape (rows * columns,) or (rows, columns).
    Fibre curves' ``"<id>.control_points"`` (N x 4: x, y, z, radius) are optimised as N rows
    (``mask`` (N,) holds whole control points; ``faces`` from :func:`curve_faces` smooth along each
    curve; ``lr`` may be per column, e.g. ``[lr, lr, lr, lr_radius]``). ``project(x)`` (the parameter's shape in and out)
    is applied after every step, before the scenes see it: a projection onto what the parameter
    may be (e.g. radii clamped above a floor); the optimiser continues from the projected point.
    ``gradient(g)`` (same shape) maps each iteration's gradient before the step: with a ``project``
    that derives some entries from others, the chain rule onto the free entries (theirs zeroed)."""
    if not views:
        raise ValueError("fit: no views")
    scenes = [s for s, _ in views]
    for s, target in views:
        if target.shape != (s.height, s.width, 3):
            raise ValueError(f"fit: target shape {target.shape} != film {(s.height, s.width, 3)}")
        s.set_differentiable([name])
    shape = scenes[0].params[name].shape
    # Points as rows: vertex positions (N, 3) and curve control points (N, 4) as they are, heights
    # (rows, columns) as (N, 1).
    rows = shape if len(shape) == 2 and shape[1] in (3, 4) else (-1, 1)
    x = scenes[0].params[name].astype(np.float64).reshape(rows)
    keep = None if mask is None else np.asarray(mask, dtype=np.float64).reshape(-1, 1)
    precond = LargeSteps(faces, len(x), lambda_) if faces is not None and lambda_ > 0 else None
    u = precond.to_u(x) if precond else x.copy()
    opt = Adam(u, lr=lr)
    result = FitResult()
    diagonal = float(np.linalg.norm(x.max(axis=0) - x.min(axis=0))) or 1.0

    def stop(reason: str) -> FitResult:
        result.diverged = reason
        warnings.warn(f"fit: stopped at iteration {len(result.losses)}: {reason}; the parameters keep their last good values",
                      stacklevel=3)
        for s in scenes:  # the last good state, also where a refused update left it
            s.params[name] = x.reshape(shape).astype(np.float32)
            s.update()
        return result

    t0 = time.perf_counter()
    for it in range(iterations):
        grad = np.zeros_like(x)
        total = 0.0
        for k, (s, target) in enumerate(views):
            img = s.render(spp=spp, seed=seed + 7919 * it + k)
            value, adjoint = loss(img, target)
            total += value
            try:
                g = s.render_backward(adjoint, spp=spp, spp_primary=spp_primary, spp_boundary=spp_boundary,
                                      seed=seed + 104729 * it + k, **(options or {}))
            except ValueError as e:
                if "overflowed" not in str(e):
                    raise
                return stop(str(e))
            grad += g[name].reshape(x.shape)
        if gradient is not None:
            grad = np.asarray(gradient(grad.reshape(shape).copy()), dtype=np.float64).reshape(x.shape)
        if keep is not None:
            grad *= keep
        if not math.isfinite(total) or not np.isfinite(grad).all():
            return stop(f"the loss ({total}) or the gradient is not finite")
        result.losses.append(total / len(views))
        result.seconds.append(time.perf_counter() - t0)
        if callback is not None and callback(it, result.losses[-1], x.reshape(shape)) is False:
            result.cancelled = True
            break
        u_before = u.copy()
        try:
            opt.step(precond.gradient_u(grad) if precond else grad)
        except ValueError as e:
            return stop(str(e))
        x_new = precond.from_u(u) if precond else u.copy()  # not u itself: Adam steps u in place, x must stay the last good state
        if keep is not None:
            x_new = np.where(keep > 0, x_new, x)
        if project is not None and np.isfinite(x_new).all():
            x_new = np.asarray(project(x_new.reshape(shape).copy()), dtype=np.float64).reshape(x.shape)
            u[...] = precond.to_u(x_new) if precond else x_new
        moved = float(np.abs(x_new - x).max()) if np.isfinite(x_new).all() else math.inf
        if moved > MAX_STEP * diagonal:
            u[...] = u_before
            return stop(f"a step moved a point by {moved:.3g}, more than {MAX_STEP} of the bounding-box diagonal "
                        f"{diagonal:.3g} (lower lr)")
        try:
            for s in scenes:
                s.params[name] = x_new.reshape(shape).astype(np.float32)
                s.update()
        except ValueError as e:
            return stop(f"the scene refused the new parameters: {e}")
        x = x_new
    return result
