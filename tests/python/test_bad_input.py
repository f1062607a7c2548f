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
