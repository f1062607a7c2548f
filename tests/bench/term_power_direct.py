#!/usr/bin/env python3
"""The statistics of the FD tests of test_indirect_boundary.py (check_term) and test_heightfield.py
(compare) at many k from one set of renders: the terms add up exactly at one seed, so the estimate
with a term scaled by k is off + k (on - off) (tests/python/term_scale.py does the same per call).
Prints, per k, the largest block |z| (test_derivatives.block_z, the tests' old and still present
check) and the z of the image projected onto an independent estimate of the term
(test_derivatives.projection_z). A test has the power issue 35 asks for when a statistic it asserts
passes |z| < 5 at k = 1 and fails at k = 0.8 and 1.25. Quicker than tests/bench/test_power.py (one
process, no pytest), but it measures the statistics, not the tests' other assertions.

    cd tests/python && python ../bench/term_power_direct.py occluder_point glossy0 hf_cone ...
    (no names: every case; --memo build/test_power_memo shares test_power.py's renders)
"""
from __future__ import annotations

import argparse
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(ROOT, "tests", "python"))
os.chdir(os.path.join(ROOT, "tests", "python"))

import numpy as np  # noqa: E402

KS = (0, 0.5, 0.8, 0.9, 1, 1.1, 1.25, 2)


def report(label, on, off, fd, term, seconds):
    from test_derivatives import block_z, projection_z
    print(f"{label} ({seconds:.0f} s)")
    for k in KS:
        s = off + k * (on - off)
        print(f"   k={k:<5g} max block |z| {np.abs(block_z(s, fd)).max():6.1f}   projected z {projection_z(s, fd, term):7.1f}",
              flush=True)


def check_term_case(label, scene, name, t, spp_boundary, eps=2e-2, fd_spp=1024, seeds=8, fd_seeds=None, term_seeds=4):
    import limn
    import test_indirect_boundary as tib
    t0 = time.time()
    if t is None:
        t = tib.x_translation(scene, name)
    elif isinstance(t, str):  # the bumps' heights scale up
        t = np.zeros_like(scene.params[name])
        t[:, 2] = scene.params[name][:, 2]
    scene.set_differentiable([name])
    fd = np.stack([limn.fd(scene, {name: t}, eps=eps, spp=fd_spp, seed=k, cache=False) for k in range(fd_seeds or seeds)])
    fwd = lambda **kw: tib.quiet(scene.render_forward, {name: t}, spp=64, **kw)
    on = np.stack([fwd(spp_boundary=spp_boundary, seed=50 + k) for k in range(seeds)])
    off = np.stack([fwd(spp_boundary=0, seed=50 + k) for k in range(seeds)])
    term = np.stack([fwd(spp_interior=0, spp_primary=0, spp_boundary=spp_boundary, seed=150 + k) for k in range(term_seeds)])
    report(label, on, off, fd, term, time.time() - t0)


def heightfield_case(label, scene, tangents, seeds=16, spp=32, fd_spp=512, eps=2e-2):
    """Both terms of the heightfield estimator: boundary = what the reparameterisation adds."""
    import limn
    import test_heightfield as th
    t0 = time.time()
    fd = np.stack([limn.fd(scene, tangents, eps=eps, spp=fd_spp, seed=k, cache=False) for k in range(seeds)])
    fwd = lambda **kw: th.quiet(scene.render_forward, tangents, spp=spp, **kw)
    on = np.stack([fwd(seed=50 + k) for k in range(seeds)])
    off = np.stack([fwd(seed=50 + k, heightfield_reparam=False) for k in range(seeds)])
    on2 = np.stack([fwd(seed=150 + k) for k in range(4)])
    off2 = np.stack([fwd(seed=150 + k, heightfield_reparam=False) for k in range(4)])
    report(label + " [boundary]", on, off, fd, on2 - off2, time.time() - t0)
    # interior scaled: (on - off) + k off, i.e. "off" and "on" of report() are on - off and on
    report(label + " [interior]", on, on - off, fd, off2, 0)


def cases():
    import test_heightfield as th
    import test_indirect_boundary as tib
    P, A = tib.POINT, tib.AREA
    c = {
        "occluder_point": lambda: check_term_case("occluder, point light", tib.load(tib.shadow_scene(P)), "box.vertex_positions", None, 16),
        "occluder_area": lambda: check_term_case("occluder, area light", tib.load(tib.shadow_scene(A)), "box.vertex_positions", None, 512),
        "receiver_point": lambda: check_term_case("receiver, point light (64 FD images)", tib.load(tib.shadow_scene(P)),
                                                  "floor.to_world.translation", np.float32([0, 0, 1]), 16, eps=5e-3, fd_spp=8192, fd_seeds=64),
        "receiver_area": lambda: check_term_case("receiver, area light", tib.load(tib.shadow_scene(A)), "floor.to_world.translation",
                                                 np.float32([0, 0, 1]), 512, eps=5e-3, fd_spp=8192),
        "self_point": lambda: check_term_case("self-shadowing, point light", tib.load(tib.validation("self_shadow_point")),
                                              "terrain.vertex_positions", "heights", 16),
        "self_area": lambda: check_term_case("self-shadowing, area light", tib.load(tib.validation("self_shadow_area")),
                                             "terrain.vertex_positions", "heights", 512),
        "glossy0": lambda: check_term_case("glossy reflection", tib.load(tib.glossy_scene(0.0)), "shape.vertex_positions", None, 512),
        "glossy5": lambda: check_term_case("glossy reflection, reflective emitter", tib.load(tib.glossy_scene(0.5)),
                                           "shape.vertex_positions", None, 512),
        "emitting": lambda: check_term_case("emitting occluder", tib.load(tib.validation("emitting_occluder_reflection")),
                                            "shape.vertex_positions", None, 512),
        "sphere_glossy": lambda: check_term_case("sphere in a glossy reflection", tib.load(tib.validation("sphere_glossy_reflection")),
                                                 "shape.center", np.float32([1, 0, 0]), 512),
    }
    for light, sb in ((P, 16), (A, 512)):
        for name, t in (("ball.center", [1.0, 0, 0]), ("ball.radius", 1.0)):
            c[f"sphere_{light}_{name.split('.')[1]}"] = (
                lambda light=light, sb=sb, name=name, t=t: check_term_case(
                    f"sphere shadow, {light} light, {name}", tib.load(tib.validation("sphere_occluder_" + light)), name, np.float32(t), sb))

    def hf(label, scene_name, name, tangent):
        d = th.scene_dict(scene_name)
        scene = th.load(d)
        scene.set_differentiable([name])
        heightfield_case(label, scene, {name: tangent(d)})
    c["hf_cone"] = lambda: hf("heightfield cone growing", "cone", "terrain.heights", th.heights_of)
    c["hf_light"] = lambda: hf("heightfield moving light", "cone", "light.to_world.translation", lambda d: np.float32([0, 0, 1]))

    def bump(d):
        n = th.heights_of(d).shape[0]
        x = np.linspace(-1, 1, n)
        X, Y = np.meshgrid(x, -x)
        return (np.maximum(0.0, 1.0 - ((X - 0.2) ** 2 + (Y - 0.1) ** 2) / 0.3) ** 2).astype(np.float32)
    c["hf_terrain"] = lambda: hf("heightfield terrain", "terrain", "terrain.heights", bump)
    return c


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("cases", nargs="*")
    p.add_argument("--memo", default="", help="a term_scale memo folder (e.g. build/test_power_memo)")
    args = p.parse_args()
    if args.memo:
        import term_scale
        term_scale.install(scales={}, memo=os.path.join(ROOT, args.memo) if not os.path.isabs(args.memo) else args.memo)
    c = cases()
    for name in args.cases or list(c):
        c[name]()


if __name__ == "__main__":
    main()
