"""The Python API: loading, rendering, parameters, update(), images, the CLI."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import limn
from conftest import ROOT, SCENES, sphere_over_plane


def test_load_file_and_dict_render_the_same(tmp_path, scene_dict):
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(scene_dict))
    a = limn.load(path).render(seed=3)
    b = limn.load_dict(scene_dict).render(seed=3)
    assert a.shape == (32, 32, 3) and a.dtype == np.float32
    np.testing.assert_array_equal(a, b)
    assert a.mean() > 0.01


def test_default_scene_loads_and_renders():
    scene = limn.load(os.path.join(SCENES, "default.json"))
    img = scene.render(spp=2)
    assert img.shape == (256, 256, 3)
    assert np.isfinite(img).all()
    assert scene.last_stats["rays"] > scene.last_stats["samples"]
    assert scene.last_stats["invalid_samples"] == 0


def test_same_seed_same_image_for_any_thread_count(scene_dict):
    scene = limn.load_dict(scene_dict)
    a = scene.render(seed=5, threads=1)
    b = scene.render(seed=5, threads=2)
    c = scene.render(seed=6, threads=2)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_spp_argument_overrides_the_sampler(scene_dict):
    scene = limn.load_dict(scene_dict)
    assert scene.spp == 16
    scene.render(spp=3)
    assert scene.last_stats["spp"] == 3
    assert scene.last_stats["samples"] == 32 * 32 * 3


def test_progress_callback_and_cancel(scene_dict):
    scene = limn.load_dict(scene_dict)
    seen = []
    scene.render(progress=lambda f: seen.append(f))
    assert seen and seen[-1] == 1.0 and all(0 < f <= 1 for f in seen)
    with pytest.raises(limn.RenderCancelled):
        scene.render(progress=lambda f: False)

    def boom(_):
        raise RuntimeError("from the callback")

    with pytest.raises(RuntimeError, match="from the callback"):
        scene.render(progress=boom)


def test_params_are_writable_views(scene_dict):
    scene = limn.load_dict(scene_dict)
    names = set(scene.params)
    assert {"floor.vertex_positions", "ball.center", "ball.radius", "ball.reflectance", "light.radiance",
            "sky.radiance", "floor.reflectance"} <= names
    v = scene.params["floor.vertex_positions"]
    assert v.shape == (4, 3) and v.dtype == np.float32
    np.testing.assert_allclose(np.abs(v[:, :2]), 3.0)  # rectangle scaled by 3, in world space
    assert scene.params["ball.radius"].shape == ()
    assert float(scene.params["ball.radius"]) == pytest.approx(0.6)
    v[:, 2] += 0.0  # no change
    assert scene.update() == []


def test_update_applies_only_what_changed(scene_dict):
    scene = limn.load_dict(scene_dict)
    before = scene.render(seed=1)
    scene.params["ball.center"] = [0.5, 0.0, 0.7]
    assert scene.update() == ["ball.center"]
    moved = scene.render(seed=1)
    assert np.abs(moved - before).max() > 0.05
    scene.params["ball.center"][...] = [0.0, 0.0, 0.7]  # in-place edit of the view, applied by render()
    np.testing.assert_array_equal(scene.render(seed=1), before)

    # Moving vertices refits the BVH: lifting the floor into the sphere changes the image.
    scene.params["floor.vertex_positions"][:, 2] = 0.5
    assert scene.update() == ["floor.vertex_positions"]
    assert np.abs(scene.render(seed=1) - before).max() > 0.05
    scene.params["ball.reflectance"] = [0.0, 0.0, 0.0]
    scene.params["light.radiance"] = [40.0, 40.0, 40.0]
    assert sorted(scene.update()) == ["ball.reflectance", "light.radiance"]


def test_mesh_from_numpy_arrays():
    d = sphere_over_plane()
    d["tri"] = {"type": "mesh",
                "vertex_positions": np.array([[-1, -1, 1.5], [1, -1, 1.5], [0, 1, 1.5]], dtype=np.float32),
                "faces": np.array([[0, 1, 2]], dtype=np.int32)}
    scene = limn.load_dict(d)
    np.testing.assert_allclose(scene.params["tri.vertex_positions"][2], [0, 1, 1.5])


def test_mesh_files_obj_and_ply(tmp_path):
    positions = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    limn.write_ply(tmp_path / "quad.ply", positions, faces)
    (tmp_path / "quad.obj").write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                                       "f 1/1 2/2 3/3 4/4\n")  # a quad: triangulated on load
    results = []
    for name, kind in (("quad.ply", "ply"), ("quad.obj", "obj")):
        d = sphere_over_plane()
        del d["floor"]
        d["floor"] = {"type": kind, "filename": name, "to_world": {"scale": 3}}
        scene = limn.load_dict(d, base_dir=tmp_path)
        assert scene.params["floor.vertex_positions"].shape == (4, 3)
        results.append(scene.render(seed=2))
    d = sphere_over_plane()
    reference = limn.load_dict(d).render(seed=2)
    for img in results:  # same geometry as the built-in rectangle (smooth normals of a flat quad)
        np.testing.assert_allclose(img, reference, atol=1e-5)


def test_welding_makes_uv_seams_topological(tmp_path):
    # A quad written with duplicated corner vertices (as UV seams do) is welded to 4 vertices.
    (tmp_path / "seam.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 0 0\nv 1 1 0\nv 0 1 0\n"
                                       "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3\nf 4/4 5/5 6/6\n")
    d = sphere_over_plane()
    d["seam"] = {"type": "obj", "filename": "seam.obj"}
    scene = limn.load_dict(d, base_dir=tmp_path)
    assert scene.params["seam.vertex_positions"].shape == (4, 3)


def test_image_round_trips(tmp_path):
    rng = np.random.default_rng(0)
    img = rng.random((7, 5, 3), dtype=np.float32) * 4.0
    limn.write_image(tmp_path / "a.exr", img)
    np.testing.assert_array_equal(limn.read_image(tmp_path / "a.exr"), img)
    limn.write_image(tmp_path / "a.hdr", img)
    # RGBE shares one exponent per pixel: each channel is within 2^-7 of the pixel's largest one.
    hdr_err = np.abs(limn.read_image(tmp_path / "a.hdr") - img)
    assert (hdr_err <= img.max(axis=2, keepdims=True) * 2.0 ** -7).all()
    ldr = np.clip(img, 0, 1)
    limn.write_image(tmp_path / "a.png", ldr)
    back = limn.read_image(tmp_path / "a.png")  # sRGB-decoded to linear
    np.testing.assert_allclose(back, ldr, atol=0.01)
    grey = limn.read_image(tmp_path / "a.png", raw=True)
    assert grey.max() <= 1.0 and not np.allclose(grey, back)
    with pytest.raises(ValueError, match="shape"):
        limn.write_image(tmp_path / "b.exr", np.zeros((4, 4, 2)))


def test_tall_tiled_and_grey_images_read_whole(tmp_path):
    # Scanline files are read in blocks of at least 64 rows (image_io.cpp): a height that is not a multiple of
    # the block, a tiled file and a one-channel file must come back pixel for pixel.
    import shutil
    import subprocess
    oiiotool = shutil.which("oiiotool")
    assert oiiotool, "oiiotool (Debian's openimageio-tools, installed by bootstrap.sh) is missing"
    h, w = 150, 5
    img = np.zeros((h, w, 3), np.float32)
    img[..., 0] = np.arange(h)[:, None] / h
    img[..., 1] = np.arange(w)[None, :] / w
    img[..., 2] = 0.25
    limn.write_image(tmp_path / "a.exr", img)
    subprocess.run([oiiotool, tmp_path / "a.exr", "--tile", "16", "16", "-o", tmp_path / "tiled.exr"], check=True)
    subprocess.run([oiiotool, tmp_path / "a.exr", "--ch", "R", "-o", tmp_path / "grey.exr"], check=True)
    subprocess.run([oiiotool, tmp_path / "a.exr", "-d", "float", "-o", tmp_path / "a.tif"], check=True)
    np.testing.assert_array_equal(limn.read_image(tmp_path / "a.exr"), img)
    np.testing.assert_array_equal(limn.read_image(tmp_path / "tiled.exr"), img)
    np.testing.assert_array_equal(limn.read_image(tmp_path / "a.tif"), img)
    np.testing.assert_array_equal(limn.read_image(tmp_path / "grey.exr"), np.repeat(img[..., :1], 3, axis=2))


def test_bitmap_texture(tmp_path):
    tex = np.zeros((2, 2, 3), dtype=np.float32)
    tex[:, 0] = [1, 0, 0]  # left half red, right half blue
    tex[:, 1] = [0, 0, 1]
    limn.write_image(tmp_path / "tex.exr", tex)
    d = sphere_over_plane()
    d["floor"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "bitmap", "filename": "tex.exr"}}
    scene = limn.load_dict(d, base_dir=tmp_path)
    assert scene.params["floor.reflectance"].shape == (2, 2, 3)
    img = scene.render(seed=0)
    left, right = img[-3:, :8].mean(axis=(0, 1)), img[-3:, -8:].mean(axis=(0, 1))
    assert left[0] > 3 * left[2] and right[2] > 3 * right[0]


def test_cli_render(tmp_path):
    out = tmp_path / "x.exr"
    r = subprocess.run([sys.executable, "-m", "limn", "render", os.path.join(SCENES, "default.json"), "-o", str(out),
                        "--spp", "1"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert out.exists() and (tmp_path / "x.png").exists()
    assert "M samples/s" in r.stdout and str(out) in r.stdout
    assert limn.read_image(out).shape == (256, 256, 3)
    bad = subprocess.run([sys.executable, "-m", "limn", "render", str(tmp_path / "missing.json")],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "missing.json" in bad.stderr


def test_cli_bench_writes_the_table_with_noise(tmp_path):
    out = tmp_path / "report"
    args = [sys.executable, "-m", "limn", "bench", os.path.join(SCENES, "projective", "sphere.json"), "--param", "shape.center",
            "--methods", "projective_grid", "--budgets", "1", "4", "--fd-spp", "8", "--eps", "0.01", "--runs", "2", "--out", str(out)]
    env = dict(os.environ, LIMN_FD_CACHE=str(tmp_path / "fd"))
    r = subprocess.run(args, capture_output=True, text=True, cwd=ROOT, env=env)
    assert r.returncode == 0, r.stderr
    rows = [line.strip("|").split("|") for line in (out / "sphere.md").read_text().splitlines() if line.startswith("| projective_grid |")]
    assert [int(c[1]) for c in rows] == [1, 4]
    for c in rows:
        rmse, noise = float(c[4]), float(c[7])
        assert np.isfinite(noise) and 0.0 < noise and np.isfinite(rmse) and rmse > 0.0
    bad = subprocess.run(args[:7] + ["--methods", "octre"] + args[9:], capture_output=True, text=True, cwd=ROOT, env=env)
    assert bad.returncode != 0 and "unknown method 'octre'" in bad.stderr


def test_examples_are_not_imported_with_the_library():
    """The demos and the bench live in limn.examples, outside the API: `import limn` loads none of them."""
    r = subprocess.run([sys.executable, "-c", "import sys, limn; print(sorted(m for m in sys.modules if m.startswith('limn.')))"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "examples" not in r.stdout and not any("demo" in name or "bench" in name for name in limn.__all__)


def test_cli_shadows_demo_runs_outside_the_checkout(tmp_path):
    """python3 -m limn demo shadows from a folder that is not the checkout: the scene comes from the
    installed package, and the results go only to -o."""
    from limn.examples import shadows
    assert os.path.commonpath([shadows.scene_dir(), os.path.dirname(limn.__file__)]) == os.path.dirname(limn.__file__)
    r = subprocess.run([sys.executable, "-m", "limn", "demo", "shadows", "-o", "result", "--iterations", "2"],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr + r.stdout
    assert sorted(os.listdir(tmp_path)) == ["result"]
    assert {"result.ply", "result.png", "target.png", "initial.png", "history.json"} <= set(os.listdir(tmp_path / "result"))


def test_max_depth_zero_is_black(scene_dict):
    scene_dict["integrator"]["max_depth"] = 0
    assert limn.load_dict(scene_dict).render().max() == 0.0


def test_flip_normals_keeps_texture_coordinates(tmp_path):
    tex = np.zeros((2, 2, 3), dtype=np.float32)
    tex[:, 0], tex[:, 1] = [1, 0, 0], [0, 0, 1]
    limn.write_image(tmp_path / "tex.exr", tex)
    images = []
    for flip in (False, True):
        d = sphere_over_plane()
        d["floor"]["flip_normals"] = flip
        d["floor"]["bsdf"] = {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {"type": "bitmap", "filename": "tex.exr"}}}
        images.append(limn.load_dict(d, base_dir=tmp_path).render(spp=256, seed=0))
    # Same texture layout either way: compare 4x4 block means (per-pixel noise differs, as the
    # flipped frames turn the same random numbers into other directions).
    blocks = [im.reshape(8, 4, 8, 4, 3).mean(axis=(1, 3)) for im in images]
    assert np.abs(blocks[0] - blocks[1]).max() < 0.1 * blocks[0].max()
