"""Scale one derivative term by k, to measure a test's power (tests/bench/test_power.py,
docs/reports/test_power.md).

The three terms add up exactly with the same seed: render_forward(t, spp, seed) equals the sum
of the calls with only one of spp_interior / spp_primary / spp_boundary non-zero, bit for bit,
and so do render_backward's gradients (test_each_term_switches_off_and_the_terms_add_up). So a
term scaled by k is

    on + (k - 1) * part

with `part` the term's own contribution at the call's seed: for the interior and primary terms
the call with only that term's count non-zero, for the indirect boundary term on - (the call with
spp_boundary=0). None of these extra calls samples the indirect term, so none of them builds or
reuses a guide: Scene.guide_cache is left as the test's own calls leave it, and `on` is exactly
what the test computes without the hook.

Heightfield scenes with differentiable geometry use the heightfield estimator, which replaces
the three terms (docs/heightfields.md; the boundary sample counts do not apply there and
spp_interior=0 is refused). Its visibility part, silhouettes and shadow edges alike, is what the
reparameterisation adds: heightfield_reparam=False holds the split points fixed and drops it
(with the same random numbers). There `boundary` scales on - (the call with
heightfield_reparam=False), `interior` scales the rest, and `primary` has no part of its own
(left unscaled; the report says so).

Environment:
- LIMN_TERM_SCALE="boundary=0.8" (terms interior, primary, boundary; several comma-separated):
  scale Scene.render_forward and Scene.render_backward, and so limn.optim.fit, which calls
  render_backward. conftest.py installs it; sitecustomize.py in term_scale_site/ installs it in
  subprocesses (the CLI demos), conftest puts that folder on their PYTHONPATH.
- LIMN_TERM_MEMO=<folder> (with LIMN_TERM_SCALE): keep every render, render_forward,
  render_backward and limn.fd result on disk, keyed by the scene's fingerprint, all its
  parameter values, the differentiable names, the tangents or adjoint and every argument, so
  that runs of one test at several k trace each path once. A memoised call leaves the guide
  cache untouched, so a later call that would have reused a guide builds its own (a different,
  equally valid density): runs with the memo agree with runs without it in distribution, not bit
  for bit, wherever a test's guided calls depend on an earlier call's guide.
- LIMN_SEED_OFFSET=n: add n * 1000003 to the seed of every render, render_forward,
  render_backward and limn.fd call (the re-seeding job that estimates false-failure rates:
  forward and FD seeds stay as far apart as the test put them).
"""
from __future__ import annotations

import hashlib
import os
import pickle
import warnings

import numpy as np

TERMS = ("interior", "primary", "boundary")
SEED_STRIDE = 1000003
_installed = False


def parse(text: str | None) -> dict:
    """"boundary=0.8,primary=1.25" -> {"boundary": 0.8, "primary": 1.25}."""
    out = {}
    for item in (text or "").split(","):
        item = item.strip()
        if not item:
            continue
        term, _, k = item.partition("=")
        term = term.strip()
        if term not in TERMS:
            raise ValueError(f"LIMN_TERM_SCALE: unknown term '{term}' (terms: {', '.join(TERMS)})")
        out[term] = float(k)
    return out


def _count(scene, spp, value):
    if value is not None:
        return value
    return spp if spp is not None else scene.spp


def _uses_heightfield_estimator(stats) -> bool:
    return any(line.startswith("heightfield estimator") for line in stats.get("summary", []))


class _Memo:
    def __init__(self, folder: str):
        self.folder = folder
        os.makedirs(folder, exist_ok=True)

    @staticmethod
    def key(scene, kind: str, *values) -> str:
        h = hashlib.sha256(kind.encode() + b"\0" + getattr(scene, "_fingerprint", b""))
        for name in sorted(scene.params):
            h.update(name.encode())
            h.update(np.ascontiguousarray(scene.params[name]).tobytes())
        h.update(repr(list(getattr(scene, "_differentiable", []))).encode())

        def add(v):
            if isinstance(v, dict):
                for k in sorted(v):
                    h.update(repr(k).encode())
                    add(v[k])
            elif isinstance(v, (np.ndarray, np.generic)):
                a = np.ascontiguousarray(v)
                h.update(repr((a.dtype.str, a.shape)).encode())
                h.update(a.tobytes())
            elif isinstance(v, (list, tuple)):
                h.update(b"[")
                for x in v:
                    add(x)
                h.update(b"]")
            else:
                h.update(repr(v).encode())
        for v in values:
            add(v)
        return h.hexdigest()[:40]

    def get(self, key):
        path = os.path.join(self.folder, key + ".pkl")
        if os.path.exists(path):
            with open(path, "rb") as f:
                return pickle.load(f)
        return None

    def put(self, key, value):
        path = os.path.join(self.folder, key + ".pkl")
        tmp = f"{path}.{os.getpid()}.tmp"
        with open(tmp, "wb") as f:
            pickle.dump(value, f)
        os.replace(tmp, path)


def install(scales: dict | None = None, memo: str | None = None, seed_offset: int | None = None) -> None:
    """Wrap limn's Scene.render / render_forward / render_backward and limn.fd (see the module
    docstring). Arguments default to the environment variables."""
    global _installed
    if _installed:
        return
    import limn
    from limn import scene as scene_module

    scales = parse(os.environ.get("LIMN_TERM_SCALE")) if scales is None else scales
    memo = os.environ.get("LIMN_TERM_MEMO") if memo is None else memo
    seed_offset = int(os.environ.get("LIMN_SEED_OFFSET", "0")) if seed_offset is None else seed_offset
    scales = {t: k for t, k in scales.items() if k != 1.0}
    if not scales and not memo and not seed_offset:
        return
    _installed = True
    store = _Memo(memo) if memo else None
    Scene = scene_module.Scene
    orig_render, orig_forward, orig_backward = Scene.render, Scene.render_forward, Scene.render_backward
    import importlib
    fd_module = importlib.import_module("limn.fd")  # the attribute limn.fd is the function
    orig_fd = fd_module.fd
    shift = seed_offset * SEED_STRIDE
    inside_fd = [0]  # fd's own renders: their seed is shifted once, by fd

    def memoised(kind, fn, scene, *key_values, stats=True):
        """fn() through the memo (the result and last_stats; on a hit the stats' warnings again)."""
        if store is None:
            return fn()
        key = _Memo.key(scene, kind, *key_values)
        hit = store.get(key)
        if hit is not None:
            value, last = hit
            if stats:
                scene._report(last) if kind != "render" else setattr(scene, "last_stats", last)
            return value
        value = fn()
        store.put(key, (value, scene.last_stats if stats else None))
        return value

    def render(self, spp=None, seed=0, threads=0, progress=None, max_depth=None):
        seed = seed + (0 if inside_fd[0] else shift)
        return memoised("render", lambda: orig_render(self, spp=spp, seed=seed, threads=threads, progress=progress,
                                                      max_depth=max_depth),
                        self, spp, seed, max_depth)

    def scaled(orig, kind, combine):
        def call(self, first, spp=None, seed=0, *, spp_interior=None, spp_primary=None, spp_boundary=None, progress=None,
                 **options):
            seed = seed + shift
            counts = dict(spp_interior=spp_interior, spp_primary=spp_primary, spp_boundary=spp_boundary)

            def run(quietly=False, **changes):
                kw = dict(counts, **{k: v for k, v in changes.items() if k in counts})
                opts = dict(options, **{k: v for k, v in changes.items() if k not in counts})

                def go():
                    if quietly:
                        with warnings.catch_warnings():
                            warnings.simplefilter("ignore")
                            return orig(self, first, spp, seed, progress=None if quietly else progress, **kw, **opts)
                    return orig(self, first, spp, seed, progress=progress, **kw, **opts)
                return memoised(kind, go, self, first, spp, seed, kw, opts)

            on = run()
            if not scales:
                return on
            stats = self.last_stats
            parts = {}
            try:
                if _uses_heightfield_estimator(stats):
                    reparam_off = (options.get("heightfield_reparam", True) is False)
                    off = on if reparam_off else run(quietly=True, heightfield_reparam=False)
                    if "boundary" in scales:
                        parts["boundary"] = combine(on, off, 1.0, -1.0)
                    if "interior" in scales:
                        parts["interior"] = off
                else:
                    n = {t: _count(self, spp, counts["spp_" + t]) for t in TERMS}
                    for term in scales:
                        if not n[term]:
                            continue  # switched off by the test itself: nothing to scale
                        if term == "boundary":
                            parts[term] = combine(on, run(quietly=True, spp_boundary=0), 1.0, -1.0)
                        else:
                            only = {"spp_" + t: (n[t] if t == term else 0) for t in TERMS}
                            parts[term] = run(quietly=True, **only)
            finally:
                self.last_stats = stats
            result = on
            for term, part in parts.items():
                result = combine(result, part, 1.0, scales[term] - 1.0)
            return result
        call.__doc__ = orig.__doc__
        call.__name__ = orig.__name__
        call.__wrapped__ = orig
        return call

    def combine_images(a, b, wa, wb):
        return (wa * a.astype(np.float64) + wb * b.astype(np.float64)).astype(a.dtype)

    def combine_grads(a, b, wa, wb):
        return {n: (wa * np.asarray(a[n], np.float64) + wb * np.asarray(b[n], np.float64)).astype(np.asarray(a[n]).dtype)
                for n in a}

    def fd(scene, tangents, eps, spp, seed=0, cache=True, threads=0, max_depth=None):
        seed = seed + shift
        if store is not None:
            cache = os.path.join(store.folder, "fd")
        inside_fd[0] += 1
        try:
            return orig_fd(scene, tangents, eps, spp, seed=seed, cache=cache, threads=threads, max_depth=max_depth)
        finally:
            inside_fd[0] -= 1

    Scene.render = render
    Scene.render_forward = scaled(orig_forward, "forward", combine_images)
    Scene.render_backward = scaled(orig_backward, "backward", combine_grads)
    fd.__doc__ = orig_fd.__doc__
    fd_module.fd = fd
    limn.fd = fd
    install.scales, install.memo, install.seed_offset = scales, memo, seed_offset


def active() -> bool:
    return _installed
