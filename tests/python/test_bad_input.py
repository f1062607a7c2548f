"""Bad input: every problem is a ValueError that names the file, the object and the bad value."""
from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import limn
from conftest import sphere_over_plane


def write(tmp_path, d, name="scene.json"):
    p = tmp_path / name
    p.write_text(json.dumps(d) if not isinstance(d, str) else d)
    return p


def expect(fn, *fragments):
    with pytest.raises(ValueError) as info:
        fn()
    message = str(info.value)
    for f in fragments:
        assert f in message, f"{f!r} not in {message!r}"
    return message


def test_malformed_json(tmp_path):
    p = write(tmp_path, '{"type": "scene", "sensor": {"type": "perspective",,}}')
    expect(lambda: limn.load(p), str(p), "malformed JSON", "line 1")


def test_missing_scene_file(tmp_path):
    expect(lambda: limn.load(tmp_path / "nope.json"), "nope.json", "not found")


def test_unknown_types(tmp_path):
    d = sphere_over_plane()
    d["thing"] = {"type": "teapot"}
    p = write(tmp_path, d)
    expect(lambda: limn.load(p), str(p), "'thing'", "unknown type 'teapot'", "sphere")
    d = sphere_over_plane()
    d["ball"]["bsdf"] = {"type": "plastic"}
    expect(lambda: limn.load_dict(d), "shape 'ball' (sphere)", "unknown type 'plastic' under 'bsdf'", "roughconductor")
    d = sphere_over_plane()
    d["integrator"] = {"type": "volpath"}
    expect(lambda: limn.load_dict(d), "'integrator'", "volpath")


def test_missing_files(tmp_path):
    d = sphere_over_plane()
    d["bunny"] = {"type": "obj", "filename": "meshes/bunny.obj"}
    p = write(tmp_path, d)
    expect(lambda: limn.load(p), str(p), "shape 'bunny' (obj)", "meshes/bunny.obj", "not found")
    d = sphere_over_plane()
    d["sky"] = {"type": "envmap", "filename": "sky.exr"}
    expect(lambda: limn.load_dict(d, base_dir=tmp_path), "emitter 'sky' (envmap)", "sky.exr")
    d = sphere_over_plane()
    d["floor"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "bitmap", "filename": "wood.png"}}
    expect(lambda: limn.load_dict(d, base_dir=tmp_path), "bsdf 'floor' (diffuse)", "wood.png")


def test_unreadable_mesh_file(tmp_path):
    (tmp_path / "junk.ply").write_text("this is not a ply file\n")
    d = sphere_over_plane()
    d["junk"] = {"type": "ply", "filename": "junk.ply"}
    expect(lambda: limn.load_dict(d, base_dir=tmp_path), "shape 'junk' (ply)", "junk.ply")


def test_wrong_array_shapes():
    d = sphere_over_plane()
    d["tri"] = {"type": "mesh", "vertex_positions": np.zeros((3, 2), np.float32), "faces": np.array([[0, 1, 2]])}
    expect(lambda: limn.load_dict(d), "shape 'tri' (mesh)", "'vertex_positions' must have shape (N, 3)")
    d["tri"] = {"type": "mesh", "vertex_positions": np.eye(3, dtype=np.float32), "faces": np.array([[0, 1, 5]])}
    expect(lambda: limn.load_dict(d), "shape 'tri' (mesh)", "refers to vertex 5")
    d["tri"] = {"type": "mesh", "vertex_positions": np.eye(3, dtype=np.float32), "faces": np.array([[0.0, 1.0, 2.0]])}
    expect(lambda: limn.load_dict(d), "'faces' must hold integers")
    d = sphere_over_plane()
    d["ball"]["center"] = [0, 1]
    expect(lambda: limn.load_dict(d), "shape 'ball' (sphere)", "'center' must be a list of 3 numbers", "[0,1]")
    scene = limn.load_dict(sphere_over_plane())
    expect(lambda: scene.params.__setitem__("floor.vertex_positions", np.zeros((5, 3))),
           "floor.vertex_positions", "(4, 3)", "(5, 3)")
    with pytest.raises(KeyError, match="no.such"):
        scene.params["no.such"]


def test_non_finite_vertices():
    d = sphere_over_plane()
    v = np.array([[0, 0, 1], [1, 0, 1], [0, np.nan, 1]], np.float32)
    d["tri"] = {"type": "mesh", "vertex_positions": v, "faces": np.array([[0, 1, 2]])}
    expect(lambda: limn.load_dict(d), "shape 'tri' (mesh)", "vertex 2 is not finite", "nan")
    d = sphere_over_plane()
    d["ball"]["center"] = [0, float("inf"), 0]
    expect(lambda: limn.load_dict(d), "'scene.ball.center' is not finite", "inf")
    # Through params: rejected by update(), and the previous values come back.
    scene = limn.load_dict(sphere_over_plane())
    before = scene.params["floor.vertex_positions"].copy()
    scene.params["floor.vertex_positions"][1, 0] = np.inf
    expect(scene.update, "<dict>", "parameter 'floor.vertex_positions'", "vertex 1 is not finite", "inf")
    np.testing.assert_array_equal(scene.params["floor.vertex_positions"], before)
    scene.params["ball.center"][0] = np.nan
    expect(lambda: scene.render(), "parameter 'ball.center'", "not finite")
    assert np.isfinite(scene.render(spp=1)).all()


def test_degenerate_triangles():
    v = np.array([[0, 0, 1], [1, 0, 1], [2, 0, 1], [0, 1, 1]], np.float32)  # 0, 1, 2 are collinear
    faces = np.array([[0, 1, 3], [0, 1, 2]])
    d = sphere_over_plane()
    d["tri"] = {"type": "mesh", "vertex_positions": v, "faces": faces}
    expect(lambda: limn.load_dict(d), "shape 'tri' (mesh)", "triangle 1 is degenerate", "allow_degenerate")
    d["tri"]["allow_degenerate"] = True
    with pytest.warns(UserWarning, match="dropped 1 degenerate triangle"):
        limn.load_dict(d)


def test_negative_radius_and_bad_alpha():
    d = sphere_over_plane()
    d["ball"]["radius"] = -1
    expect(lambda: limn.load_dict(d), "shape 'ball' (sphere)", "radius must be > 0", "-1")
    d = sphere_over_plane()
    d["ball"]["bsdf"] = {"type": "roughconductor", "alpha": 0.0}
    expect(lambda: limn.load_dict(d), "bsdf 'ball' (roughconductor)", "alpha must be > 0", "0.0")
    d["ball"]["bsdf"] = {"type": "roughdielectric", "alpha": -0.2}
    expect(lambda: limn.load_dict(d), "bsdf 'ball' (roughdielectric)", "alpha must be > 0", "-0.2")
    d["ball"]["bsdf"] = {"type": "roughconductor", "alpha": 0.2}
    scene = limn.load_dict(d)
    scene.params["ball.alpha"] = 0.0
    expect(scene.update, "parameter 'ball.alpha'", "> 0")
    scene.params["ball.radius"] = -2.0
    expect(scene.update, "parameter 'ball.radius'", "-2")


def test_structural_mistakes():
    d = sphere_over_plane()
    del d["sensor"]
    expect(lambda: limn.load_dict(d), "no sensor")
    d = sphere_over_plane()
    d["floor"]["bsdf"] = {"type": "ref", "id": "marble"}
    expect(lambda: limn.load_dict(d), "shape 'floor' (rectangle)", "unknown bsdf 'marble'")
    d = sphere_over_plane()
    d["ball"]["emitter"] = {"type": "point"}
    expect(lambda: limn.load_dict(d), "only 'area' emitters")
    d = sphere_over_plane()
    d["sensor"]["to_world"] = {"look_at": {"origin": [0, 0, 1], "target": [0, 0, 0], "up": [0, 0, 1]}}
    expect(lambda: limn.load_dict(d), "sensor 'sensor' (perspective)", "up is parallel")
    d = sphere_over_plane()
    d["sensor"]["film"]["width"] = 0
    expect(lambda: limn.load_dict(d), "film", "width and height")
    d = sphere_over_plane()
    d["sensor"]["fov"] = 190
    expect(lambda: limn.load_dict(d), "fov must be in (0, 180)", "190")
    d = sphere_over_plane()
    d["ball"]["to_world"] = {"scale": [1, 2, 1]}
    expect(lambda: limn.load_dict(d), "shape 'ball' (sphere)", "uniform scale")
    d = sphere_over_plane()
    d["floor"]["to_world"] = {"spin": 3}
    expect(lambda: limn.load_dict(d), "shape 'floor' (rectangle)", "unknown transform 'spin'")
    expect(lambda: limn.load_dict([1, 2]), "expects a dict")
    scene = limn.load_dict(sphere_over_plane())
    expect(lambda: scene.render(spp=0), "spp must be > 0")


def test_unused_parameters_warn():
    d = sphere_over_plane()
    d["ball"]["colour"] = [1, 0, 0]
    with pytest.warns(UserWarning, match=r"shape 'ball' \(sphere\): unused parameter 'colour'"):
        limn.load_dict(d)


GARBAGE = [None, "x", -5, 1e300, [], {}, [1, 2, 3, 4], {"type": 3}, [[1, 2], [3]], True]


def load_and_render_garbage(obj, key, value):
    """sphere_over_plane with d[obj][key] = value, loaded and rendered at 1 spp. Returns the
    warnings' messages, or None when loading raised a ValueError naming the object or the key."""
    d = sphere_over_plane()
    d[obj][key] = value
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            limn.load_dict(d).render(spp=1)
        except ValueError as e:
            assert obj in str(e) or key in str(e), str(e)
            return None
    return [str(w.message) for w in caught]


def test_nothing_crashes_on_random_garbage():
    """Garbage values are refused naming the object or the key, or accepted as what they can mean
    (an empty transform list is the identity); a garbage value is never dropped with an "unused
    parameter" warning, which would render a different scene than the one described."""
    rng = np.random.default_rng(1)
    keys = [("ball", "radius"), ("ball", "center"), ("floor", "to_world"), ("sensor", "fov")]
    for _ in range(60):
        obj, key = keys[rng.integers(len(keys))]
        value = GARBAGE[rng.integers(len(GARBAGE))]
        messages = load_and_render_garbage(obj, key, value)
        if messages is not None:
            assert not any(f"unused parameter '{key}'" in m for m in messages), (obj, key, value, messages)
            assert all(obj in m for m in messages), (obj, key, value, messages)


@pytest.mark.xfail(strict=True, reason="needs a core change (scene loader): a shape's 'emitter' that is not an emitter "
                                       "object (null, a number, a string, a list, {} or {'type': 3}) is only warned "
                                       "about as an unused parameter and the shape loads without its emitter, here "
                                       "the scene's only area light")
@pytest.mark.parametrize("value", GARBAGE, ids=[repr(v) for v in GARBAGE])
def test_a_garbage_emitter_is_refused_not_dropped(value):
    assert load_and_render_garbage("light", "emitter", value) is None, f"emitter {value!r} loaded without its light"


def test_ragged_and_mistyped_values():
    d = sphere_over_plane()
    d["tri"] = {"type": "mesh", "vertex_positions": [[0, 0, 1], [1, 0, 1], [0, 1, 1]], "faces": [0, [1, 2, 3]]}
    expect(lambda: limn.load_dict(d), "shape 'tri' (mesh)", "ragged")
    d = sphere_over_plane()
    d["floor"]["id"] = 5
    expect(lambda: limn.load_dict(d), "'floor'", "\"id\" must be a string")
    d = sphere_over_plane()
    d["light"]["emitter"]["radiance"] = {"type": 3}
    expect(lambda: limn.load_dict(d), "emitter 'light' (area)", "radiance")
    d = sphere_over_plane()
    d["ball"]["radius"] = 1e300
    expect(lambda: limn.load_dict(d), "shape 'ball' (sphere)", "finite float")
    d = sphere_over_plane()
    d["sensor"]["film"]["width"] = 4294967552
    expect(lambda: limn.load_dict(d), "'width' is out of range")
    d = sphere_over_plane()
    d["ball"]["bsdf"] = {"type": "diffuse", "id": "shared"}
    d["floor"]["bsdf"] = {"type": "diffuse", "id": "shared"}
    expect(lambda: limn.load_dict(d), "duplicate id 'shared'")


def test_envmap_transform_must_be_a_rotation(tmp_path):
    limn.write_image(tmp_path / "env.exr", np.ones((4, 8, 3), np.float32))
    d = sphere_over_plane()
    d["sky"] = {"type": "envmap", "filename": "env.exr", "to_world": {"scale": [1, 2, 1]}}
    expect(lambda: limn.load_dict(d, base_dir=tmp_path), "emitter 'sky' (envmap)", "rotation")


def test_update_during_a_render_is_refused():
    import threading
    scene = limn.load_dict(sphere_over_plane())
    entered, release, errors = threading.Event(), threading.Event(), []

    def progress(_):
        entered.set()
        release.wait(10)

    worker = threading.Thread(target=lambda: scene.render(progress=progress))
    worker.start()
    assert entered.wait(10)
    scene.params["ball.radius"] = 0.3
    try:
        scene.update()
    except RuntimeError as e:
        errors.append(str(e))
    finally:
        release.set()
        worker.join()
    assert errors and "while a render of this scene is running" in errors[0]
    assert scene.update() == ["ball.radius"]  # applied once the render is over


# ---- the hostile-input report: each reproduction as a regression test --------------------------------

PLY_UV_HEADER = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                 "property float s\nproperty float t\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n")


def load_mesh(tmp_path, name, data, **extra):
    (tmp_path / name).write_bytes(data if isinstance(data, bytes) else data.encode())
    d = sphere_over_plane()
    d["m"] = {"type": name.rsplit(".", 1)[1], "filename": name, **extra}
    return limn.load_dict(d, base_dir=tmp_path)


def test_ply_index_out_of_range_with_texture_coordinates(tmp_path):
    # Was a segfault in read_mesh_file: texture coordinates looked up by an unchecked index.
    text = PLY_UV_HEADER + "0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n3 0 1 100000000\n"
    expect(lambda: load_mesh(tmp_path, "bad.ply", text), "shape 'm' (ply)", "bad.ply", "line 15", "face 0 refers to vertex 1e+08",
           "3 vertices")


def test_truncated_binary_ply_and_endless_headers(tmp_path):
    # Was 7 segfaults, 3 aborts and 3 endless loops in assimp.
    limn.write_ply(tmp_path / "quad.ply", np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32),
                   np.array([[0, 1, 2], [0, 2, 3]]))
    data = (tmp_path / "quad.ply").read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    for cut in (0, 7, 30, len(data) - end - 1):
        expect(lambda: load_mesh(tmp_path, "cut.ply", data[:end + cut]), "shape 'm' (ply)", "cut.ply", "truncated")
    expect(lambda: load_mesh(tmp_path, "head.ply", "ply\nformat ascii 1.0\n" + "comment x\n" * 1000), "head.ply", "end_header")
    expect(lambda: load_mesh(tmp_path, "huge.ply", data[:end].replace(b"element vertex 4", b"element vertex 4294967295")),
           "huge.ply", "4294967295", "cannot hold them")


def test_ply_formats_and_texture_coordinates(tmp_path):
    import struct
    v = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)]
    uv = [(0, 0), (1, 0), (1, 1), (0, 1)]
    text = PLY_UV_HEADER.replace("vertex 3", "vertex 4") + "".join(f"{a} {b} {c} {s} {t}\n" for (a, b, c), (s, t) in zip(v, uv)) + "4 0 1 2 3\n"
    header = text[:text.index("end_header\n") + 11].replace("ascii", "binary_big_endian").replace("uchar int", "ushort uint")
    body = b"".join(struct.pack(">5f", *p, *t) for p, t in zip(v, uv)) + struct.pack(">H4I", 4, 0, 1, 2, 3)
    for name, data in (("a.ply", text), ("be.ply", header.encode() + body)):
        scene = load_mesh(tmp_path, name, data, to_world={"scale": 3})
        assert scene.params["m.vertex_positions"].shape == (4, 3)
        np.testing.assert_array_equal(scene.faces("m"), [[0, 1, 2], [0, 2, 3]])


def test_obj_reader(tmp_path):
    quad = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 9 9 9\n"  # the last vertex is never used: left out
    scene = load_mesh(tmp_path, "q.obj", quad + "f -5 -4 -3 -2\n")
    assert scene.params["m.vertex_positions"].shape == (4, 3)
    expect(lambda: load_mesh(tmp_path, "b.obj", quad + "f 1 2 6\n"), "shape 'm' (obj)", "b.obj", "line 6", "vertex 6", "5 vertices")
    expect(lambda: load_mesh(tmp_path, "z.obj", quad + "f 0 1 2\n"), "z.obj", "line 6")
    expect(lambda: load_mesh(tmp_path, "n.obj", "v 0 0 nan\n" + quad + "f 1 2 3\n"), "n.obj", "line 1", "nan")
    expect(lambda: load_mesh(tmp_path, "e.obj", quad), "e.obj", "no triangles")


def test_scene_files_that_are_not_regular_files(tmp_path):
    import os
    expect(lambda: limn.load(tmp_path), str(tmp_path), "is a directory")  # was "malformed JSON"
    os.mkfifo(tmp_path / "fifo.json")  # was a hang
    expect(lambda: limn.load(tmp_path / "fifo.json"), "fifo.json", "not a regular file")
    os.mkfifo(tmp_path / "mesh.ply")
    d = sphere_over_plane()
    d["m"] = {"type": "ply", "filename": "mesh.ply"}
    expect(lambda: limn.load_dict(d, base_dir=tmp_path), "shape 'm' (ply)", "'filename'", "mesh.ply", "not a regular file")


def test_json_text_errors_name_the_file_and_the_place(tmp_path):
    good = json.dumps(sphere_over_plane(), indent=1)
    text = good.replace('"radius": 0.6', '"radius": 1e400')
    p = write(tmp_path, text)  # was a RuntimeError without the file name
    expect(lambda: limn.load(p), str(p), f"line {text[:text.index('1e400')].count(chr(10)) + 1}", "'ball.radius'", "1e400")
    p.write_bytes(good.encode().replace(b'"ball"', b'"b\xffall"'))  # was a ValueError with an empty message
    message = expect(lambda: limn.load(p), str(p), "line", "UTF-8", "\\xFF")
    assert message.isprintable()
    p.write_text('{"type": "scene", "x": ' + "[" * 100000 + "]" * 100000 + "}")  # was a stack overflow in dump()
    expect(lambda: limn.load(p), str(p), "line 1", "deeper than 256 levels")
    p.write_text(good.replace('"radius": 0.6', '"radius": 0.6, "radius": 2'))
    expect(lambda: limn.load(p), str(p), "'radius' appears twice", "'ball'")


def test_deep_and_zero_d_values_in_dictionaries():
    d = sphere_over_plane()
    d["ball"]["center"] = np.array([0, 0, 0.7])
    d["ball"]["radius"] = np.array(0.5)  # a 0-d array is a number (was {"__limn_array__": 0})
    assert limn.load_dict(d).params["ball.radius"] == 0.5
    d["ball"]["radius"] = np.array(np.nan)
    expect(lambda: limn.load_dict(d), "'scene.ball.radius' is not finite")
    d["ball"]["radius"] = np.array([[0.5]])  # was "(got {"__limn_array__":0})"
    expect(lambda: limn.load_dict(d), "shape 'ball' (sphere)", "'radius' must be a number (got an array of shape (1, 1))")
    d["ball"]["radius"] = 0.5
    d["ball"]["center"] = np.zeros(2)
    expect(lambda: limn.load_dict(d), "shape 'ball' (sphere)", "'center' must have 3 values (got 2)")
    d = sphere_over_plane()
    deep = 0
    for _ in range(100000):
        deep = [deep]
    d["ball"]["center"] = deep
    expect(lambda: limn.load_dict(d), "'scene.ball.center' nests deeper than 256 levels")
    d = sphere_over_plane()
    d["ball"]["radius"] = 10 ** 400
    expect(lambda: limn.load_dict(d), "'scene.ball.radius' is out of range")


def test_load_time_scales_that_overflow_or_underflow():
    for scale, fragments in ((1e300, ("'radius' 0.6 scaled by 'to_world' is 6", "outside [1e-18, 1e+18]")),
                             (1e-300, ("'radius' 0.6 scaled by 'to_world'", "e-301")),
                             ([1, 1, 0], ("'to_world'", "scale must be finite and non-zero"))):
        d = sphere_over_plane()
        d["ball"]["to_world"] = {"scale": scale}
        expect(lambda: limn.load_dict(d), "shape 'ball' (sphere)", *fragments)
    d = sphere_over_plane()
    d["ball"]["to_world"] = [[1, 0, 0, 0], [0, 1, 0, 0], [1, 1, 0, 0], [0, 0, 0, 1]]
    expect(lambda: limn.load_dict(d), "shape 'ball' (sphere)", "'to_world'", "singular")
    d = sphere_over_plane()
    d["hf"] = {"type": "heightfield", "data": [[0, 1], [1, 0]], "to_world": {"scale": 1e300}}
    expect(lambda: limn.load_dict(d), "shape 'hf' (heightfield)", "'to_world'", "1e+300")
    d = sphere_over_plane()
    d["floor"]["to_world"] = {"scale": 1e-300}
    expect(lambda: limn.load_dict(d), "shape 'floor' (rectangle)", "becomes degenerate after 'to_world'")


def test_meshes_at_huge_scales_are_not_called_degenerate():
    tri = np.array([[0, 0, 1], [1, 0, 1], [0, 1, 1]], np.float32)
    d = sphere_over_plane()
    d["tri"] = {"type": "mesh", "vertex_positions": tri * np.float32(1e8), "faces": np.array([[0, 1, 2]])}
    assert limn.load_dict(d).params["tri.vertex_positions"].max() == np.float32(1e8)
    d["tri"]["vertex_positions"] = tri * np.float32(1e38)  # was "triangle 0 is degenerate"
    message = expect(lambda: limn.load_dict(d), "shape 'tri' (mesh)", "1e+38", "beyond 1e+18")
    assert "degenerate" not in message
    d["tri"]["vertex_positions"] = tri * np.float32(1e12)  # its area is 5e23: float's cross product overflows
    message = expect(lambda: limn.load_dict(d), "shape 'tri' (mesh)", "triangle 0", "too large for float arithmetic")
    assert "degenerate" not in message


def test_nested_objects_come_in_file_order(tmp_path):
    d = sphere_over_plane()
    d["ball"]["zz"] = {"type": "diffuse"}  # the second bsdf in the file; in key order "bsdf" would be
    d["ball"]["aa"] = {"type": "diffuse"}
    p = write(tmp_path, d)
    expect(lambda: limn.load(p), "shape 'ball' (sphere)", "more than one bsdf (another under 'zz')")


def test_sensor_children_and_sampler_default():
    d = sphere_over_plane()
    del d["sensor"]["sampler"]["sample_count"]
    with_sampler = limn.load_dict(d).spp
    del d["sensor"]["sampler"]
    assert with_sampler == limn.load_dict(d).spp == 16  # was 4 with a sampler, 16 without
    d = sphere_over_plane()
    d["sensor"]["film2"] = {"type": "hdrfilm"}  # was silently ignored
    expect(lambda: limn.load_dict(d), "sensor 'sensor' (perspective)", "two films ('film' and 'film2')")
    d = sphere_over_plane()
    d["sensor"]["sampler2"] = {"type": "independent"}
    expect(lambda: limn.load_dict(d), "sensor 'sensor' (perspective)", "two samplers")


def test_array_shapes_and_nested_bsdf_details():
    d = sphere_over_plane()
    d["tri"] = {"type": "mesh", "vertex_positions": [[0, 0], [[0], [0]]], "faces": [[0, 1, 2]]}  # was shape (2, 2, 1)
    expect(lambda: limn.load_dict(d), "shape 'tri' (mesh)", "'vertex_positions' is a ragged array")
    d["tri"] = {"type": "mesh", "vertex_positions": np.eye(3, dtype=np.float32), "faces": np.array([[0, 1, 2]]),
                "corner_uvs": np.zeros((1, 6), np.float32)}  # was accepted (only the count was checked)
    expect(lambda: limn.load_dict(d), "shape 'tri' (mesh)", "'corner_uvs' must have shape (F, 3, 2)", "(1, 6)")
    d = sphere_over_plane()
    d["ball"]["bsdf"] = {"type": "twosided", "inner": {"type": "diffuse", "id": "lost"}}  # was ignored
    expect(lambda: limn.load_dict(d), "bsdf 'ball' (twosided)", "remove its \"id\" \"lost\"")
    d = sphere_over_plane()
    d["metal"] = {"type": "conductor"}
    d["ball"]["bsdf"] = {"type": "ref", "id": "metal", "colour": 1}  # extra keys were not reported
    with pytest.warns(UserWarning, match=r"shape 'ball' \(sphere\): 'bsdf' \(ref\): unused parameter 'colour'"):
        limn.load_dict(d)
    d["ball"]["bsdf"] = {"type": "ref", "id": "floor"}
    expect(lambda: limn.load_dict(d), "'bsdf' refers to unknown bsdf 'floor'", "not a top-level bsdf")


def test_images_truncated_empty_or_claiming_huge_sizes(tmp_path):
    import struct
    import zlib
    limn.write_image(tmp_path / "a.png", np.full((8, 8, 3), 0.5, np.float32))
    data = (tmp_path / "a.png").read_bytes()
    (tmp_path / "cut.png").write_bytes(data[:len(data) // 2])
    expect(lambda: limn.read_image(tmp_path / "cut.png"), "cut.png", "png")
    (tmp_path / "empty.png").write_bytes(b"")
    expect(lambda: limn.read_image(tmp_path / "empty.png"), "empty.png", "empty")

    def chunk(kind, payload):
        return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", zlib.crc32(kind + payload))
    huge = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 100000, 100000, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b""))
    (tmp_path / "huge.png").write_bytes(huge)
    expect(lambda: limn.read_image(tmp_path / "huge.png"), "huge.png", "100000 x 100000", "limit")
    (tmp_path / "notes.png").write_text("not an image")
    expect(lambda: limn.read_image(tmp_path / "notes.png"), "notes.png", "not a PNG, JPEG")
    limn.write_image(tmp_path / "b.exr", np.full((2, 3, 3), 0.25, np.float32))
    (tmp_path / "b.png").write_bytes((tmp_path / "b.exr").read_bytes())  # read by its content, not its name
    np.testing.assert_array_equal(limn.read_image(tmp_path / "b.png"), np.full((2, 3, 3), 0.25, np.float32))
    # A TIFF whose strip sizes are broken (found by fuzz_heightfield; reading stops at the first bad block).
    import pathlib
    broken = pathlib.Path(__file__).parents[1] / "fuzz/corpus/heightfield/slow-tiff-broken-strip-sizes-a"
    expect(lambda: limn.read_image(broken), "slow-tiff-broken-strip-sizes-a", "(tiff)", "StripByteCounts")
