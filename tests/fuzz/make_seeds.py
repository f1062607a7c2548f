"""Writes the seed corpora of the fuzz targets (tests/fuzz/corpus/<target>/seed-*): small valid
inputs of every kind each reader knows, and a few broken ones. Regenerate with

    .venv/bin/python tests/fuzz/make_seeds.py

Inputs that once crashed or hung a target are kept next to the seeds as crash-* files (written by
hand from libFuzzer's artifacts, never by this script); tests/python/test_hostile_input.py loads
each of them and expects a clean error."""
from __future__ import annotations

import glob
import json
import os
import struct
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
CORPUS = os.path.join(HERE, "corpus")


def put(target: str, name: str, data: bytes | str) -> None:
    folder = os.path.join(CORPUS, target)
    os.makedirs(folder, exist_ok=True)
    with open(os.path.join(folder, "seed-" + name), "wb") as f:
        f.write(data.encode() if isinstance(data, str) else data)


def camera(w=4, h=4, **extra):
    return {"type": "perspective", "fov": 40,
            "to_world": {"look_at": {"origin": [0, -4, 2], "target": [0, 0, 0.5], "up": [0, 0, 1]}},
            "film": {"type": "hdrfilm", "width": w, "height": h},
            "sampler": {"type": "independent", "sample_count": 4}, **extra}


def scenes() -> dict[str, dict]:
    base = {"type": "scene", "integrator": {"type": "path", "max_depth": 4}, "sensor": camera(),
            "floor": {"type": "rectangle", "to_world": {"scale": 3}, "bsdf": {"type": "diffuse", "reflectance": 0.5}},
            "ball": {"type": "sphere", "center": [0, 0, 0.7], "radius": 0.6, "bsdf": {"type": "ref", "id": "metal"}},
            "metal": {"type": "roughconductor", "material": "Au", "distribution": "ggx", "alpha": 0.2},
            "light": {"type": "rectangle", "to_world": [{"scale": 0.5}, {"rotate": {"axis": [1, 0, 0], "angle": 180}},
                                                        {"translate": [0.5, -0.5, 3]}],
                      "emitter": {"type": "area", "radiance": [20, 18, 15]}},
            "sky": {"type": "constant", "radiance": 0.1}}
    files = {"type": "scene", "sensor": camera(),
             "p": {"type": "ply", "filename": "mesh.ply", "to_world": {"translate": [0, 0, 1]}, "face_normals": True},
             "o": {"type": "obj", "filename": "mesh.obj", "flip_normals": True,
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "bitmap", "filename": "tex.png", "raw": False}}},
             "h": {"type": "heightfield", "filename": "height.png", "size": [2, 3], "height_scale": 0.3},
             "env": {"type": "envmap", "filename": "env.exr", "scale": 2, "to_world": {"rotate": {"axis": [1, 0, 0], "angle": 90}}}}
    arrays = {"type": "scene", "sensor": camera(),
              "m": {"type": "mesh", "vertex_positions": {"__limn_array__": 0}, "faces": {"__limn_array__": 1},
                    "corner_uvs": {"__limn_array__": 4}, "to_world": {"__limn_array__": 2}, "allow_degenerate": True},
              "h": {"type": "heightfield", "data": {"__limn_array__": 3}},
              "pt": {"type": "point", "position": {"__limn_array__": 5}, "intensity": 3}}
    inline = {"type": "scene", "sensor": camera(fov_axis="y", near_clip=0.1, far_clip=100),
              "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
              "tri": {"type": "mesh", "vertex_positions": [[0, 0, 1], [1, 0, 1], [0, 1, 1]], "faces": [[0, 1, 2]],
                      "corner_uvs": [[[0, 0], [1, 0], [0, 1]]],
                      "bsdf": {"type": "twosided", "inner": {"type": "roughdielectric", "int_ior": "water", "alpha": 0.3}}},
              "hf": {"type": "heightfield", "data": [[0, 0.1, 0], [0.2, 0.4, 0.1], [0, 0, 0]],
                     "to_world": {"matrix": [[2, 0, 0, 0], [0, 2, 0, 0], [0, 0, 2, 1], [0, 0, 0, 1]]}},
              "glass": {"type": "dielectric", "int_ior": 1.5, "ext_ior": "air"},
              "box": {"type": "cube", "to_world": [[0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 0.5, 0.5], [0, 0, 0, 1]],
                      "bsdf": {"type": "ref", "id": "glass"}},
              "sun": {"type": "directional", "direction": [0, 0.3, -1], "irradiance": [3, 3, 3]},
              "mirror": {"type": "conductor", "eta": [0.2, 0.9, 1.1], "k": [3.9, 2.4, 2.1]}}
    return {"base": base, "files": files, "arrays": arrays, "inline": inline}


def scene_seeds() -> None:
    for name, d in scenes().items():
        put("scene_json", name + ".json", json.dumps(d, indent=1))
    put("scene_json", "deep.json", '{"type": "scene", "x": ' + "[" * 300 + "]" * 300 + "}")
    put("scene_json", "overflow.json", '{"type": "scene", "ball": {"type": "sphere", "radius": 1e400}}')
    put("scene_json", "utf8.json", b'{"type": "scene", "b\xffall": {"type": "sphere"}}')
    put("scene_json", "duplicate.json", '{"type": "scene", "ball": {"type": "sphere", "radius": 1, "radius": 2}}')


def obj_seeds() -> None:
    put("obj", "quad.obj", "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n")
    put("obj", "normals.obj", "# comment\no thing\ng group\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvn 0 0 1\ns off\nusemtl m\n"
                              "f 1//1 2//1 3//1\nf -4//1 -2//1 -1//1\nl 1 2\n")
    put("obj", "hexagon.obj", "".join(f"v {np.cos(a):.6f} {np.sin(a):.6f} 0\n" for a in np.linspace(0, 2 * np.pi, 7)[:6])
        + "vt 0 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.5 0.5\nvt 0.2 0.8\nf 1/1/1 2/2/1 3/3/1 4/4/1 5/5/1 6/6/1\n")
    put("obj", "crlf.obj", "v 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nf 1 2 3\r\n")
    put("obj", "bad_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 100000000\n")
    put("obj", "nan.obj", "v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")


def ply_header(fmt: str, nv: int, nf: int, vprops: list[str], extra: str = "", flist: str = "uchar int") -> str:
    return ("ply\nformat " + fmt + " 1.0\ncomment seed\nelement vertex %d\n" % nv
            + "".join(f"property {p}\n" for p in vprops) + extra
            + f"element face {nf}\nproperty list {flist} vertex_indices\nend_header\n")


def ply_seeds(tmp: str) -> None:
    import limn
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    limn.write_ply(os.path.join(tmp, "quad.ply"), v, f)
    with open(os.path.join(tmp, "quad.ply"), "rb") as fh:
        binary = fh.read()
    put("ply", "binary_le.ply", binary)
    end = binary.index(b"end_header\n") + len(b"end_header\n")
    put("ply", "truncated.ply", binary[:end + 7])  # the issue's case: cut 7 bytes after end_header
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    ascii_uv = ply_header("ascii", 4, 1, ["float x", "float y", "float z", "float s", "float t"]) + "".join(
        f"{a[0]} {a[1]} {a[2]} {b[0]} {b[1]}\n" for a, b in zip(v, uv)) + "4 0 1 2 3\n"
    put("ply", "ascii_uv.ply", ascii_uv)
    put("ply", "ascii_bad_uv_index.ply", ply_header("ascii", 3, 1, ["float x", "float y", "float z", "float s", "float t"])
        + "0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n3 0 1 100000000\n")
    # Big endian, double coordinates, texture_u/v, an extra per-vertex list and an extra element.
    vprops = ["double x", "double y", "double z", "float texture_u", "float texture_v", "list uchar ushort extra", "uchar red"]
    hdr = ply_header("binary_big_endian", 4, 2, vprops, flist="uint uint")
    hdr = hdr.replace("end_header\n", "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n")
    body = b"".join(struct.pack(">dddffB", *p, *t, 1) + struct.pack(">H", 7) + b"\x80" for p, t in zip(v.astype(float), uv))
    body += b"".join(struct.pack(">I", 3) + struct.pack(">3I", *tri) for tri in f)
    body += struct.pack(">ii", 0, 1)
    put("ply", "binary_be.ply", hdr.encode() + body)
    put("ply", "ascii_skip.ply", ply_header("ascii", 3, 1, ["float x", "float y", "float z", "list int float w"],
                                            extra="element material 1\nproperty float k\n")
        + "0 0 0 2 1 2\n1 0 0 0\n0 1 0 1 5\n0.5\n3 0 1 2\n")


def image_seeds(tmp: str) -> dict[str, bytes]:
    import limn
    rgb = np.random.default_rng(0).random((3, 4, 3)).astype(np.float32)
    out = {}
    for ext in ("png", "jpg", "exr", "hdr", "tif", "bmp", "tga"):
        p = os.path.join(tmp, "img." + ext)
        limn.write_image(p, rgb)
        out[ext] = open(p, "rb").read()
    oiio = [("grey16.png", ["--pattern", "fill:color=0.25", "3x2", "1", "-d", "uint16"]),
            ("rgba.png", ["--pattern", "checker:width=1:height=1", "3x3", "4", "-d", "uint8"]),
            ("half.exr", ["--pattern", "fill:color=0.5,0.25,1", "2x2", "3", "-d", "half"]),
            ("grey.pfm", ["--pattern", "fill:color=0.5", "2x3", "1", "-d", "float"]),
            ("rgb.ppm", ["--pattern", "checker:width=1:height=1", "3x2", "3", "-d", "uint8"]),
            ("tiled.exr", ["--pattern", "fill:color=1,2,3", "5x5", "3", "-d", "float", "--tile", "2", "2"])]
    for name, args in oiio:
        p = os.path.join(tmp, name)
        if subprocess.run(["oiiotool", *args, "-o", p], capture_output=True).returncode == 0:
            out[name] = open(p, "rb").read()
    return out


def main() -> None:
    for f in glob.glob(os.path.join(CORPUS, "*", "seed-*")):
        os.remove(f)
    with tempfile.TemporaryDirectory() as tmp:
        scene_seeds()
        obj_seeds()
        ply_seeds(tmp)
        images = image_seeds(tmp)
        for name, data in images.items():
            put("image", name if "." in name else "img." + name, data)
            put("image", "truncated-" + (name if "." in name else "img." + name), data[: max(1, len(data) * 2 // 3)])
        for name in ("png", "exr", "grey16.png", "grey.pfm", "tif"):
            if name in images:
                put("heightfield", name if "." in name else "h." + name, images[name])
    sizes = sum(os.path.getsize(f) for f in glob.glob(os.path.join(CORPUS, "*", "*")))
    print(f"seed corpora in {CORPUS}: {sizes} bytes")


if __name__ == "__main__":
    sys.exit(main())
