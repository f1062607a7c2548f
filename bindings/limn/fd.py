"""Central finite differences of whole renders, the reference for every derivative (docs/derivatives.md, "How it is validated")."""
from __future__ import annotations

import hashlib
import os

import numpy as np

from .scene import Scene


# Part of every cached reference's key: the key holds the scene and the settings, not the code, so
# bump this whenever a change alters primal images (not only their derivatives), or the cache
# serves references of the old renderer. 2: a duplicated triangle counts once in smooth normals.
# 3: microfacet D and sampling take sin^2 from x and y (glossy images move in the last bits).
PRIMAL_REVISION = 3


def default_cache_dir() -> str:
    return os.environ.get("LIMN_FD_CACHE", os.path.join(os.path.expanduser("~"), ".cache", "limn", "fd"))


def fd(scene: Scene, tangents: dict, eps: float, spp: int, seed: int = 0, cache: bool | str = True,
       threads: int = 0, max_depth: int | None = None) -> np.ndarray:
    """(I(theta + eps t) - I(theta - eps t)) / (2 eps) from two primal renders with the same seed.
    Each pixel draws from one stream, so a path that drew a different count of numbers in the two
    renders would shift the pixel's later samples (on the projective sphere scene the two renders
    differ only in the samples the move changed: docs/reports/projective/README.md, fifteenth
    pass). Near moving edges the noise grows about as 1/eps, and eps trades it against the bias,
    O(eps^2) where the image is smooth in theta (docs/reports/projective/reference.md). ``tangents`` maps parameter names to arrays shaped like
    the parameters. The parameters are restored afterwards. Results are cached on disk (``cache``:
    True for the default folder, $LIMN_FD_CACHE or ~/.cache/limn/fd; a path; or False), keyed by
    the scene's source, every parameter value, each mesh's triangles, the tangents, the settings and
    ``PRIMAL_REVISION``. ``max_depth`` as in
    :meth:`Scene.render`."""
    if not eps > 0:
        raise ValueError(f"eps must be > 0 (got {eps})")
    base = {}
    for name, t in tangents.items():
        view = scene.params[name]
        t = np.asarray(t, dtype=np.float32)
        if t.shape != view.shape:
            raise ValueError(f"tangent of '{name}': expected shape {view.shape}, got {t.shape}")
        base[name] = (view.copy(), t)

    path = None
    if cache:
        folder = cache if isinstance(cache, str) else default_cache_dir()
        key = cache_key(scene, {name: t for name, (_, t) in base.items()}, eps, spp, seed, max_depth)
        path = os.path.join(folder, key + ".npy")
        if os.path.exists(path):
            return np.load(path)

    images = []
    try:
        for sign in (1.0, -1.0):
            for name, (value, t) in base.items():
                scene.params[name] = value + np.float32(sign * eps) * t
            images.append(scene.render(spp=spp, seed=seed, threads=threads, max_depth=max_depth))
    finally:
        for name, (value, _) in base.items():
            scene.params[name] = value
        scene.update()
    result = (images[0].astype(np.float64) - images[1]) / (2.0 * eps)
    result = result.astype(np.float32)
    if path:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        tmp = path + f".{os.getpid()}.tmp.npy"
        np.save(tmp, result)
        os.replace(tmp, path)
    return result


def cache_key(scene: Scene, tangents: dict, eps: float, spp: int, seed: int, max_depth: int | None,
              revision: int | None = None) -> str:
    """The cached reference's file name (without .npy) for float32 ``tangents``, under
    ``PRIMAL_REVISION`` unless ``revision`` is given."""
    revision = PRIMAL_REVISION if revision is None else revision
    digest = hashlib.sha256(scene._fingerprint + b"\0primal revision %d" % revision)
    for name in sorted(scene.params):
        digest.update(name.encode())
        digest.update(np.ascontiguousarray(scene.params[name]).tobytes())
        if name.endswith(".vertex_positions"):  # a mesh's triangles come from its file, not the scene's
            digest.update(np.ascontiguousarray(scene.faces(name[:-len(".vertex_positions")])).tobytes())
    for name in sorted(tangents):
        digest.update(b"tangent:" + name.encode())
        digest.update(tangents[name].tobytes())
    digest.update(repr((float(eps), int(spp), int(seed), scene.width, scene.height, max_depth)).encode())
    return digest.hexdigest()[:32]
