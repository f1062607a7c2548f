"""Regenerates scenes/projective: `python3 scenes/projective/make.py`.

The projective-sampling paper's test scene (section 6): a shape in front of a large uniform area
emitter, seen only in its reflection in a rough conductor plane (GGX alpha = 0.005); the
derivative is for a horizontal translation of the shape. One JSON per shape: an analytic sphere,
a torus, a cube with a square hole, and the Stanford bunny.

The bunny is the Stanford 3D Scanning Repository's `bun_zipper_res3` (1889 vertices, 3851
triangles, open at the base), taken from Debian's `opencv-doc` package, which ships it as an
example data file. The issue asked for the npm package `bunny`; this workplace reaches PyPI and
Debian only (`npm view bunny` fails with ENOTFOUND), and the npm package holds the same scan at a
similar resolution. bunny.ply is committed; make.py fetches the Debian package again only when
bunny.ply is missing (`apt-get download`, no install)."""
import json
import os
import subprocess
import tempfile

import numpy as np

import limn

here = os.path.dirname(os.path.abspath(__file__))


def base(shape: dict) -> dict:
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": {"look_at": {"origin": [0, -2.2, 1.6], "target": [0, 0.6, -0.2], "up": [0, 0, 1]}},
                   "film": {"type": "hdrfilm", "width": 48, "height": 48},
                   "sampler": {"type": "independent", "sample_count": 16}},
        "plane": {"type": "rectangle", "to_world": {"scale": 3},
                  "bsdf": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.005}},
        "emitter": {"type": "rectangle",
                    "to_world": [{"scale": [3, 1.5, 1]}, {"rotate": {"axis": [1, 0, 0], "angle": 90}}, {"translate": [0, 2.5, 1.5]}],
                    "bsdf": {"type": "diffuse", "reflectance": 0.0}, "emitter": {"type": "area", "radiance": 2.0}},
        "shape": shape,
    }


def torus(R=0.22, r=0.09, nu=32, nv=16):
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, nu, endpoint=False), np.linspace(0, 2 * np.pi, nv, endpoint=False), indexing="ij")
    p = np.stack([(R + r * np.cos(v)) * np.cos(u), r * np.sin(v), (R + r * np.cos(v)) * np.sin(u)], -1).reshape(-1, 3)
    f = []
    for i in range(nu):
        for j in range(nv):
            a, b, c, d = i * nv + j, ((i + 1) % nu) * nv + j, ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
            f += [[a, c, b], [a, d, c]]
    return p.astype(np.float32), np.int32(f)


def cube_with_hole(outer=0.25, inner=0.12, depth=0.08):
    """A square annulus extruded along y: a closed genus-1 mesh with sharp edges."""
    sq = lambda s: [(-s, -s), (s, -s), (s, s), (-s, s)]
    v = [(x, y, z) for y in (-depth, depth) for s in (outer, inner) for x, z in sq(s)]
    O = lambda side, k: side * 8 + k          # outer ring corner k on side 0 (front) / 1 (back)
    I = lambda side, k: side * 8 + 4 + k
    f = []
    for k in range(4):
        n = (k + 1) % 4
        f += [[O(0, k), O(0, n), I(0, n)], [O(0, k), I(0, n), I(0, k)]]      # front annulus
        f += [[O(1, k), I(1, n), O(1, n)], [O(1, k), I(1, k), I(1, n)]]      # back annulus
        f += [[O(0, k), O(1, k), O(1, n)], [O(0, k), O(1, n), O(0, n)]]      # outer walls
        f += [[I(0, k), I(0, n), I(1, n)], [I(0, k), I(1, n), I(1, k)]]      # inner walls
    return np.float32(v), np.int32(f)


BUNNY_PACKAGE = "opencv-doc"
BUNNY_MEMBER = "./usr/share/doc/opencv-doc/examples/viz/data/bunny.ply"


def read_ascii_ply(text: str, source: str):
    """Positions and triangles of an ASCII PLY whose vertices start with x y z (extra columns ignored)."""
    lines = text.splitlines()
    header_end = lines.index("end_header")
    counts = {l.split()[1]: int(l.split()[2]) for l in lines[:header_end] if l.startswith("element")}
    nv, nf = counts["vertex"], counts["face"]
    body = lines[header_end + 1:]
    p = np.float32([l.split()[:3] for l in body[:nv]])
    rows = [l.split() for l in body[nv:nv + nf]]
    if len(p) != nv or len(rows) != nf or any(r[0] != "3" for r in rows):
        raise ValueError(f"{source}: expected {nv} vertices and {nf} triangles")
    return p, np.int32([r[1:4] for r in rows])


def bunny():
    """The Stanford bunny from Debian's opencv-doc, centred, scaled to radius 0.3, z up."""
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run(["apt-get", "download", "-q", BUNNY_PACKAGE], cwd=tmp, check=True)
        deb = next(os.path.join(tmp, f) for f in os.listdir(tmp) if f.endswith(".deb"))
        tar = subprocess.run(["dpkg-deb", "--fsys-tarfile", deb], check=True, capture_output=True).stdout
        text = subprocess.run(["tar", "-xO", BUNNY_MEMBER], input=tar, check=True, capture_output=True).stdout
    p, f = read_ascii_ply(text.decode(), f"{BUNNY_PACKAGE}:{BUNNY_MEMBER}")
    p = (p - p.mean(0)) / np.abs(p - p.mean(0)).max() * 0.3
    return p[:, [0, 2, 1]], f[:, [0, 2, 1]]   # y up -> z up; swapping two axes flips winding, so swap back


PLACE = [{"rotate": {"axis": [0, 0, 1], "angle": 20}}, {"translate": [0.05, 1.0, 1.2]}]

if __name__ == "__main__":
    scenes = {"sphere": {"type": "sphere", "center": [0.05, 1.0, 1.2], "radius": 0.25,
                         "bsdf": {"type": "diffuse", "reflectance": 0.1}}}
    meshes = {"torus": torus, "cube_hole": cube_with_hole, "bunny": bunny}
    for name, make in meshes.items():
        path = os.path.join(here, name + ".ply")
        if name != "bunny" or not os.path.exists(path):   # the bunny needs a download: keep the committed one
            limn.write_ply(path, *make())
        scenes[name] = {"type": "ply", "filename": name + ".ply", "face_normals": True, "to_world": PLACE,
                        "bsdf": {"type": "diffuse", "reflectance": 0.1}}
    for name, shape in scenes.items():
        with open(os.path.join(here, name + ".json"), "w") as f:
            json.dump(base(shape), f, indent=1)
        print("wrote", name + ".json")
