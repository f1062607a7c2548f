"""The Scene object: loading, rendering and editable parameters."""
from __future__ import annotations

import collections.abc
import hashlib
import json
import math
import os
import warnings
from typing import Callable, Iterator

import numpy as np

from . import _core


class Parameters(collections.abc.MutableMapping):
    """Editable scene parameters by name, e.g. ``"bunny.vertex_positions"`` (N x 3),
    ``"ball.center"`` (3,), ``"ball.radius"`` (a 0-d array), ``"floor.reflectance"`` (3,) or
    (H, W, 3) for a bitmap, ``"lamp.radiance"`` (3,).

    ``params[name]`` is a writable float32 view into the scene's memory; assigning copies values in
    (the shape must match). Call ``Scene.update()`` after edits (``render()`` does it for you)."""

    def __init__(self, native: _core.Scene):
        self._native = native

    def __getitem__(self, name: str) -> np.ndarray:
        return self._native.parameter(name)

    def __setitem__(self, name: str, value) -> None:
        view = self._native.parameter(name)
        array = np.asarray(value, dtype=np.float32)
        if array.shape != view.shape:
            raise ValueError(f"parameter '{name}': expected shape {view.shape}, got {array.shape}")
        view[...] = array

    def __delitem__(self, name: str) -> None:
        raise TypeError("scene parameters cannot be removed")

    def __iter__(self) -> Iterator[str]:
        return iter(self._native.parameter_names())

    def __len__(self) -> int:
        return len(self._native.parameter_names())

    def __repr__(self) -> str:
        rows = [f"  {name}: {tuple(self[name].shape)}" for name in self]
        return "Parameters(\n" + "\n".join(rows) + "\n)"


class Scene:
    """A loaded scene. Create with :func:`load` or :func:`load_dict`."""

    def __init__(self, native: _core.Scene, fingerprint: bytes = b""):
        self._native = native
        self._fingerprint = fingerprint  # what the scene was made from (for finite-difference caches)
        self._differentiable: list[str] = []
        self.params = Parameters(native)
        self.last_stats: dict = {}
        self.guide_cache = _core.GuideCache()  # guides kept between calls (option guide_refresh)
        for message in native.warnings:
            warnings.warn(message, stacklevel=3)

    @property
    def width(self) -> int:
        return self._native.width

    @property
    def height(self) -> int:
        return self._native.height

    @property
    def spp(self) -> int:
        """Samples per pixel from the scene's sampler (used when render() gets none)."""
        return self._native.spp

    @property
    def warnings(self) -> list[str]:
        return list(self._native.warnings)

    def update(self) -> list[str]:
        """Apply edits made through ``params``: validates them (ValueError names the parameter and
        the bad value; the old values are restored), refits moved geometry. Returns the changed names."""
        return self._native.update()

    def render(self, spp: int | None = None, seed: int = 0, threads: int = 0,
               progress: Callable[[float], bool | None] | None = None, max_depth: int | None = None) -> np.ndarray:
        """Render the scene; returns a (H, W, 3) float32 array of linear RGB radiance.

        The same ``seed`` gives the same image for any number of ``threads`` (0 = all cores).
        ``max_depth`` overrides the path integrator's longest path (-1: unbounded).
        ``progress(fraction)`` is called from time to time; returning False cancels with
        :class:`limn.RenderCancelled`. Statistics of the call are kept in ``last_stats``."""
        if spp is not None and spp <= 0:
            raise ValueError(f"spp must be > 0 (got {spp})")
        if seed < 0:
            raise ValueError(f"seed must be >= 0 (got {seed})")
        self.update()
        image, self.last_stats = self._native.render(spp or 0, seed, threads, progress, max_depth)
        if self.last_stats["invalid_samples"]:
            warnings.warn(f"{self._native.source}: {self.last_stats['invalid_samples']} invalid (NaN/Inf) samples were dropped",
                          stacklevel=2)
        if self.last_stats["invalid_rays"]:
            warnings.warn(f"{self._native.source}: {self.last_stats['invalid_rays']} rays could not be traced (non-finite, or "
                          "coordinates beyond 1.8e18) and missed", stacklevel=2)
        return image

    # ---- derivatives --------------------------------------------------------------------------------
    def set_differentiable(self, names) -> None:
        """Mark parameters (names as in ``params``) as differentiable for render_forward/backward."""
        names = [names] if isinstance(names, str) else list(names)
        known = set(self.params)
        for n in names:
            if n not in known:
                raise ValueError(f"{self._native.source}: unknown parameter '{n}' (parameters: {', '.join(sorted(known))})")
        self._differentiable = list(dict.fromkeys(names))

    @property
    def differentiable(self) -> list[str]:
        return list(self._differentiable)

    # Derivative options and their defaults (render_forward / render_backward keyword arguments),
    # from the C++ DiffOptions, the one place that states them; the core validates every value
    # (core/diff/diff_options.h). The sample counts and the seed are arguments of their own.
    DIFF_OPTIONS = {k: (float(f"{v:.6g}") if isinstance(v, float) else v)
                    for k, v in _core.diff_option_defaults().items()
                    if k not in ("spp", "spp_interior", "spp_primary", "spp_boundary", "seed")}

    def _diff_options(self, spp, seed, spp_interior, spp_primary, spp_boundary, options: dict) -> dict:
        unknown = set(options) - set(self.DIFF_OPTIONS)
        if unknown:
            raise TypeError(f"unknown derivative option(s) {sorted(unknown)}; known: {sorted(self.DIFF_OPTIONS)}")
        self.update()
        return dict(options, spp=spp, seed=seed, spp_interior=spp_interior, spp_primary=spp_primary, spp_boundary=spp_boundary)

    def _report(self, stats: dict) -> None:
        self.last_stats = stats
        if stats["invalid_paths"]:
            warnings.warn(f"{self._native.source}: {stats['invalid_paths']} paths with non-finite values or derivatives were dropped",
                          stacklevel=3)
        for line in stats["summary"]:
            if "NOT COMPUTED" in line or line.startswith("warning:"):
                warnings.warn(f"{self._native.source}: {line}", stacklevel=3)

    def render_forward(self, tangents: dict, spp: int | None = None, seed: int = 0, *, spp_interior: int | None = None,
                       spp_primary: int | None = None, spp_boundary: int | None = None, progress=None,
                       **options) -> np.ndarray:
        """Derivative image d(image)/d(theta) along ``tangents`` ({name: array shaped like the
        parameter}; differentiable parameters that are not listed get a zero tangent).

        Terms: the interior term (``spp_interior`` paths per pixel), the primary-visibility boundary
        term for silhouettes seen directly (``spp_primary`` samples per pixel on average), and the
        indirect boundary term for the boundaries of the shapes (mesh edges, sphere surfaces): shadows
        and silhouettes seen in reflections (``spp_boundary``). Each count is ``spp`` when None, which
        is the scene's sample count when None; 0 switches a term off.

        Options (keyword arguments; their defaults are listed at the end):

        - ``guiding``: ``"auto"`` (the default) takes the projective grid below 256 boundary samples
          per pixel and the octree from there, with one leaf per 16 of the call's boundary samples
          (docs/reports/default_estimator/README.md: at low budgets the octree's set-up outweighs its
          lower error); no guide when every boundary segment ends at a point or directional light (no
          bounce after the first hit, only delta emitters), which fixes its direction; the summary
          says which; ``"none"``
          samples the boundary sample space uniformly; ``"grid"`` uses a
          uniform grid of ``grid_resolution`` cells along the first axis (and R/4 x R/2 over the
          others); ``"octree"`` an adaptive octree (``octree_slices`` slabs along the first axis,
          depth <= ``octree_max_depth``, ``octree_leaf_samples`` uniform samples per leaf, one per octant
          when a multiple of 8, at most ``octree_max_leaves`` leaves: beyond that it coarsens and the
          summary says so), sampled
          in a mixture with the projective grid built from the same projections
          (``octree_grid_mix``, its share; 0: the octree alone). The grid covers the parts of
          a narrow feature next to the points that were found, which the octree's leaves there estimate as
          empty; without it the octree's errors are heavy-tailed (see docs/reports/projective/README.md).
          ``octree_training`` samples per pixel are first drawn from that grid and its
          direction histogram (below); those whose weight f / g is at least twice the mean (where that
          mixture under-samples the integrand) join the projections as points the octree splits at, each
          adding its value over one finest cell to its leaf's mass (a training round in the manner of
          practical path guiding, not in the paper; 0: projections only, as in the paper).
          ``octree_refine_rounds`` (0: off, as in the paper) rounds then split every leaf of more than
          ``octree_refine_factor`` times the mean leaf mass into 8 and estimate the new
          leaves' masses from ``octree_leaf_samples`` uniform points each (resolution where the mass
          is), together with those leaves' face neighbours that are two or more levels coarser (a
          peak crossing into a large leaf is otherwise missed by its few points); not in the paper;
          docs/reports/projective/octree_refinement.md has the rounds' cost and gain.
        - ``direction_mix`` (projective grid and octree): the share of the projections'
          direction histogram in the mixture (the octree's and the grid's shares above are of the rest),
          ``direction_resolution`` squared cells (at most 4096) over the sample space's second
          and third coordinates (the direction for mesh edges), uniform along the first, and
          ``direction_octaves`` coarser histograms of a half, a quarter ... of that
          resolution, with equal shares. In a near-specular chain every silhouette edge's integrand
          peaks at nearly the same directions, so it covers the peaks of edges the projections missed,
          which the grid and the octree hold at the defensive density only; the coarser histograms
          cover the GGX lobe's long tails next to the cells the projections filled (0: off;
          docs/reports/projective/README.md).
        - ``boundary_parts``: which parts of the indirect term's Eq. 4 to sample, ``"both"``,
          ``"perimeter"`` (mesh edges, SDF creases) or ``"interior"`` (spheres, SDF patches): one part
          alone validates it against finite differences (tests/python/test_sdfgrid.py).
        - ``boundary_sampler``: the indirect term's points of the boundary sample space,
          ``"stratified"`` (the first coordinate in one stratum per sample, the other two
          from Owen-scrambled Sobol points, which the guides map axis by axis, so every region gets
          close to its expected share of the samples; core/math/sequence.h) or
          ``"independent"`` (independent uniform numbers). Both are unbiased.
        - ``projective`` (grid): fill the grid from projected seeds (True) or from
          ``guiding_spp`` random points per cell (False, the path-space baseline).
        - ``grid_octaves`` (projective grid and the octree's grid): the projections fill
          a pyramid of grids, R 2^k cells along the first axis (R/4 2^k, R/2 2^k along the others)
          for k = -grid_octaves .. grid_octaves, sampled with equal shares (not in the paper: the
          fine levels resolve narrow lobes at no extra integrand evaluations, the coarse ones cover
          the gaps between seed paths; docs/reports/projective/README.md); 0: one grid, as in the
          paper. Levels over 4M cells are left out and the summary says so.
        - ``guiding_seeds``: projective guides trace ``guiding_seeds`` seed paths per pixel, whose
          segments (``project_seed``: ``"bsdf"``, ``"emitter"`` or ``"both"``) are projected onto
          silhouettes; None: for the grid an eighth of ``spp_boundary``, between 32 and 128 (its
          set-up stays a small share of the call), 256 for the octree (the octree splits only at
          projections where the integrand is non-zero, a few per cent of them).
        - ``guide_refresh`` k > 0 keeps the guide in ``Scene.guide_cache`` and reuses it for up to k
          calls while the settings are the same and no moving geometry moved by more than
          ``guide_refresh_threshold`` of its bounding-box diagonal (optimisation loops and repeated
          calls; a kept guide is still a valid density, so the estimate stays unbiased); 0 builds
          it every call.
        - ``shading_horizon``: at smooth-shaded (interpolated-normal) reflective surfaces the interior
          term adds the boundary term of the geometric horizon, where the leak test cuts the shading
          hemisphere (docs/derivatives.md, "Smooth shading"); False leaves it out (a diagnostic).
        - ``max_depth`` overrides the path integrator's longest path for every term;
          ``threads`` (0: all cores).

        Scenes with a ``heightfield`` shape and differentiable geometry use the heightfield estimator
        (Tong et al. 2023) instead of all three terms (``spp_interior`` >= 1 paths per pixel; the boundary
        sample counts and guiding options do not apply): ``heightfield_mipmap=False`` searches
        discontinuities without the maximum mipmap (brute force, for comparison),
        ``heightfield_curvature_test=False`` skips mipmap nodes by their maximum height only (not
        also by the second-derivative bound, core/geometry/shapes/heightfield/peak_search.h; for comparison), and
        ``theta_subrange`` > 0 searches only a sub-range of that many degrees per sample (App. C);
        ``heightfield_interval_mix`` is the share of the choice of a theta interval
        made uniformly over the intervals, the rest proportional to their widths (0: widths only,
        whose per-sample derivatives have a heavy tail at slivers next to silhouettes);
        ``heightfield_camera_every_interval`` traces a camera path through every
        interval of a pixel's theta range (Eq. 5) instead of choosing one (Eq. 6);
        ``heightfield_reparam=False`` holds the split points fixed, which drops the visibility part
        of the derivative (a diagnostic, like ``spp_boundary=0``); ``heightfield_delta_edges=False``
        drops only the boundary term of point and directional lights' shadow edges cast by heightfields.

        ``last_stats["summary"]`` lists what was computed and what was skipped."""
        options = self._diff_options(spp, seed, spp_interior, spp_primary, spp_boundary, options)
        for n in tangents:
            if n not in self._differentiable:
                raise ValueError(f"tangent given for '{n}', which is not differentiable (differentiable: {self._differentiable})")
        arrays = []
        for n in self._differentiable:
            shape = self.params[n].shape
            t = np.asarray(tangents.get(n, np.zeros(shape)), dtype=np.float64)
            if t.shape != shape:
                raise ValueError(f"tangent of '{n}': expected shape {shape}, got {t.shape}")
            if not np.isfinite(t).all():
                raise ValueError(f"tangent of '{n}' has non-finite values")
            arrays.append(np.ascontiguousarray(t))
        image, stats = self._native.render_forward(self._differentiable, arrays, options, progress, self.guide_cache)
        self._report(stats)
        return image

    def faces(self, shape_id: str) -> np.ndarray:
        """Triangles (F, 3) int32 of mesh shape ``shape_id``, indexing ``params["<id>.vertex_positions"]``
        (vertices are welded by position when loaded, so this can differ from the file's)."""
        return self._native.faces(shape_id)

    def render_backward(self, adjoint, spp: int | None = None, seed: int = 0, *, spp_interior: int | None = None,
                        spp_primary: int | None = None, spp_boundary: int | None = None, progress=None,
                        **options) -> dict:
        """Gradient of sum(adjoint * image) for every differentiable parameter, as {name: array
        shaped like the parameter}. ``adjoint`` is a (H, W, 3) array, e.g. dLoss/dImage.
        Same terms and caveats as :meth:`render_forward`."""
        options = self._diff_options(spp, seed, spp_interior, spp_primary, spp_boundary, options)
        a = np.asarray(adjoint, dtype=np.float32)
        if a.shape != (self.height, self.width, 3):
            raise ValueError(f"adjoint must have shape {(self.height, self.width, 3)}, got {a.shape}")
        grads, stats = self._native.render_backward(self._differentiable, np.ascontiguousarray(a), options, progress,
                                                    self.guide_cache)
        self._report(stats)
        return dict(zip(self._differentiable, grads))

    def __repr__(self) -> str:
        return (f"Scene('{self._native.source}', {self.width}x{self.height}, spp={self.spp}, "
                f"shapes={self._native.shape_ids}, integrator={self._native.integrator})")


def _defaults_text() -> str:
    """The derivative options' defaults, from the C++ DiffOptions, as a docstring paragraph."""
    rows = [f"{k}={v!r}" for k, v in Scene.DIFF_OPTIONS.items()]
    lines, line = [], "       "
    for r in rows:
        if len(line) + len(r) + 2 > 100:
            lines.append(line.rstrip())
            line = "       "
        line += " " + r + ","
    lines.append(line.rstrip(","))
    return "\n\n        Defaults (core/diff/diff_options.h):\n\n" + "\n".join(lines) + "\n"


Scene.render_forward.__doc__ += _defaults_text()
Scene.render_backward.__doc__ += _defaults_text()


def load(path: str | os.PathLike) -> Scene:
    """Load a scene description (JSON, Mitsuba-3 dictionary conventions) from a file."""
    import stat
    if not isinstance(path, (str, bytes, os.PathLike)):
        raise TypeError(f"limn.load: the scene file must be a path (str or os.PathLike), not {type(path).__name__}")
    path = os.fsdecode(os.fspath(path))
    # What is not a regular file is refused before it is opened: opening a FIFO would block.
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise ValueError(f"scene file '{path}' not found") from None
    except (OSError, ValueError) as e:
        raise ValueError(f"scene file {path!r}: cannot read it ({e})") from None
    if stat.S_ISDIR(st.st_mode):
        raise ValueError(f"scene file '{path}' is a directory, not a file")
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"scene file '{path}' is not a regular file (a FIFO, socket or device)")
    try:
        with open(path, "rb") as f:
            fingerprint = os.path.abspath(path).encode(errors="surrogateescape") + b"\0" + f.read()
    except OSError as e:
        raise ValueError(f"scene file '{path}': cannot read it ({e.strerror})") from None
    return Scene(_core.load_file(path), fingerprint)


def load_dict(description: dict, base_dir: str | os.PathLike | None = None, source: str = "<dict>") -> Scene:
    """Load a scene from a dictionary in the same format as the JSON files. Values may be numpy
    arrays (e.g. ``vertex_positions`` and ``faces`` of a ``mesh`` shape, a 4x4 ``to_world``; 0-d
    arrays are scalars). Relative file names are resolved against ``base_dir`` (default: the
    working directory)."""
    if not isinstance(description, dict):
        raise ValueError(f"load_dict expects a dict, got {type(description).__name__}")
    arrays: list[np.ndarray] = []
    MAX_NESTING = 256  # deeper descriptions are refused, as the C++ loader refuses deeper JSON

    def name(where: str) -> str:
        return where if len(where) <= 120 else where[:60] + "..." + where[-57:]

    def convert(value, where: str, depth: int):
        if depth > MAX_NESTING:
            raise ValueError(f"{source}: '{name(where)}' nests deeper than {MAX_NESTING} levels")
        if isinstance(value, np.ndarray):
            if value.ndim == 0:
                return convert(value.item(), where, depth)
            if value.dtype.kind not in "biuf":
                raise ValueError(f"{source}: '{name(where)}' is an array of {value.dtype}; arrays must hold numbers")
            arrays.append(np.ascontiguousarray(value))
            return {"__limn_array__": len(arrays) - 1}
        if isinstance(value, dict):
            out = {}
            for k, v in value.items():
                if not isinstance(k, str):
                    raise TypeError(f"{source}: '{name(where)}' has the key {k!r} of type {type(k).__name__}; keys must be strings")
                out[text(k, where)] = convert(v, f"{where}.{k}", depth + 1)
            return out
        if isinstance(value, (list, tuple)):
            return [convert(v, where, depth + 1) for v in value]
        if isinstance(value, np.generic):
            return convert(value.item(), where, depth)
        if isinstance(value, bool) or value is None:
            return value
        if isinstance(value, int):
            if abs(value) >= 2 ** 64:  # beyond what JSON numbers hold exactly; beyond double it is an error
                try:
                    float(value)
                except OverflowError:
                    raise ValueError(f"{source}: '{name(where)}' is out of range (an integer of {len(str(abs(value)))} digits)") from None
            return value
        if isinstance(value, float):
            if not math.isfinite(value):
                raise ValueError(f"{source}: '{name(where)}' is not finite ({value})")
            return value
        if isinstance(value, str):
            return text(value, where)
        raise ValueError(f"{source}: '{name(where)}' has a value of unsupported type {type(value).__name__}")

    def text(value: str, where: str) -> str:
        try:
            value.encode("utf-8")
        except UnicodeEncodeError:
            raise ValueError(f"{source}: '{name(where)}' has text that is not valid Unicode ({value!r})") from None
        return value

    text_ = json.dumps(convert(description, "scene", 0), allow_nan=False)
    base = os.fspath(base_dir) if base_dir is not None else os.getcwd()
    digest = hashlib.sha256(text_.encode())
    for a in arrays:
        digest.update(str((a.dtype.str, a.shape)).encode())
        digest.update(a.tobytes())
    return Scene(_core.load_json(text_, source, base, arrays), digest.digest())
