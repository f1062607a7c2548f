"""Curve objects in the add-on (curves.py): legacy Curve objects with a round bevel and hair Curves
objects exported as limn fibre curves (bsplinecurve), optimised and written back. Headless, in
Debian's Blender 3.4 and in the bpy module (4.5 LTS)."""
from __future__ import annotations

import math
import re
import time

import bpy  # first: with the bpy module, addon_utils becomes importable only after bpy
import addon_utils
import numpy as np
import pytest

import scene_builder

# Control points (x, y, z) of the test curve and their radii (Blender point radius; the tube is
# bevel_depth times that).
POINTS = np.array([[-1.6, 0.0, 0.9], [-0.9, 0.2, 1.3], [-0.2, -0.1, 0.8], [0.5, 0.1, 1.2], [1.2, 0.0, 0.9],
                   [1.8, 0.1, 1.1]])
RADII = np.array([1.0, 1.2, 0.9, 1.1, 1.0, 1.0])
BEVEL = 0.12
# Hair points: the curve passes through them (the natural spline), so they bend more gently than
# POINTS, whose spline through them would fold a tube of this radius.
HAIR_POINTS = np.array([[-1.6, 0.0, 1.0], [-0.9, 0.1, 1.15], [-0.2, 0.0, 1.0], [0.5, 0.05, 1.12], [1.2, 0.0, 1.0],
                        [1.8, 0.05, 1.06]])


@pytest.fixture
def addon():
    """The test scene's camera, the curve alone under a sun (direct light only, black world): a delta
    light and no floor keep the renders nearly noise-free, so the loss measures the geometry."""
    scene_builder.build_sphere_over_plane(width=48, height=36)
    for name in ("ball", "floor", "lamp"):
        bpy.data.objects.remove(bpy.data.objects[name])
    bpy.context.scene.world = None
    if hasattr(bpy.context.scene, "cycles"):
        bpy.context.scene.cycles.max_bounces = 0
    # A longer lens than the sphere scene's 35 mm: the tubes are about 3 pixels wide, so that a
    # change of their radius by a third is half a pixel.
    bpy.data.objects["camera"].data.lens = 60.0
    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.data.energy = 3.0
    sun.rotation_euler = (math.radians(40), math.radians(20), 0.0)
    bpy.context.scene.collection.objects.link(sun)
    addon_utils.enable("limn_blender", default_set=True)
    import limn_blender
    return limn_blender


@pytest.fixture
def limn(addon):
    from limn_blender.render_ops import _limn
    return _limn()


def _curve(name, kind="NURBS", points=POINTS, radii=RADII, bevel=BEVEL, order=4, cyclic=False, material=True):
    """A legacy Curve object with one spline of `kind` through / on `points`."""
    return scene_builder.add_curve(name, kind, points, radii, bevel, order, cyclic, material)


def _hair(name, kind="POLY", points=POINTS, radii=RADII):
    """A hair Curves object made from a legacy curve (Blender 3.4 cannot add hair curves from Python)."""
    legacy = _curve(name, kind, points, radii, bevel=0.0, material=False)  # a bevelled curve does not convert
    bpy.ops.object.select_all(action="DESELECT")
    legacy.select_set(True)
    bpy.context.view_layer.objects.active = legacy
    assert bpy.ops.object.convert(target="CURVES") == {"FINISHED"}
    obj = bpy.context.view_layer.objects.active
    assert obj.type == "CURVES", obj.type
    obj.data.materials.append(bpy.data.materials.new(f"{name}_mat"))
    return obj


def _legacy_points(obj) -> np.ndarray:
    """(n, 4) local positions and radii of the first spline."""
    sp = obj.data.splines[0]
    if sp.type == "BEZIER":
        return np.array([(*p.co, p.radius) for p in sp.bezier_points])
    return np.array([(*p.co[:3], p.radius) for p in sp.points])


def _hair_points(obj) -> np.ndarray:
    return np.array([(*p.position, p.radius) for p in obj.data.points])


def _set_legacy(obj, pts):
    for p, v in zip(obj.data.splines[0].points, pts):
        p.co, p.radius = (*v[:3], 1.0), v[3]
    obj.data.update_tag()


def _set_hair(obj, pts):
    for p, v in zip(obj.data.points, pts):
        p.position, p.radius = v[:3], v[3]
    obj.data.update_tag()


def _knot_values(cp):
    """The uniform cubic B-spline's values at its knots: (P_i + 4 P_i+1 + P_i+2) / 6."""
    return (cp[:-2] + 4.0 * cp[1:-1] + cp[2:]) / 6.0


# ---- export ---------------------------------------------------------------------------------------------
def test_nurbs_of_order_4_is_exported_exactly(addon):
    """Points become control points and bevel x radius x scale the radii, in world space; a cyclic
    spline repeats its first three points; one shape with curve offsets."""
    obj = _curve("fibre")
    sp = obj.data.splines.new("NURBS")
    sp.points.add(4)
    ring = [(math.cos(a), math.sin(a), 2.0, 1.0) for a in np.linspace(0, 2 * math.pi, 5, endpoint=False)]
    for p, co in zip(sp.points, ring):
        p.co, p.radius = co, 0.5
    sp.order_u, sp.use_cyclic_u = 4, True
    obj.location, obj.rotation_euler, obj.scale = (0.3, -0.2, 0.1), (0.2, 0.0, 0.7), (1.5, 1.5, 1.5)
    bpy.context.view_layer.update()
    desc, warnings = addon.export_scene(spp=4)
    shape = desc["fibre"]
    assert shape["type"] == "bsplinecurve" and warnings == []
    # Once: not also as the bevelled mesh Blender lists as the curve's instance.
    assert not [k for k, v in desc.items() if isinstance(v, dict) and v.get("type") in ("mesh", "bsplinecurve") and k != "fibre"]
    world = np.array(obj.matrix_world)
    local = np.concatenate([POINTS, np.array(ring)[:, :3], np.array(ring)[:3, :3]])
    expected = local @ world[:3, :3].T + world[:3, 3]
    np.testing.assert_allclose(shape["control_points"][:, :3], expected, atol=1e-5)
    np.testing.assert_allclose(shape["control_points"][:, 3], np.concatenate([RADII, [0.5] * 8]) * BEVEL * 1.5,
                               rtol=1e-6)
    np.testing.assert_array_equal(shape["curve_offsets"], [0, 6])


def test_poly_and_bezier_splines_are_converted_with_the_stated_approximation(addon):
    """A poly spline becomes the cubic spline through its points (stated in a warning): its knot
    values are the points, radii are the points' (ends repeated). A Bezier spline whose handles
    are those of a uniform B-spline is exported exactly (no warning); one with automatic handles is
    fitted, with the residual stated."""
    poly = _curve("poly", "POLY")
    desc, warnings = addon.export_scene(spp=4)
    cp = desc["poly"]["control_points"].astype(np.float64)
    assert cp.shape == (len(POINTS) + 2, 4)
    np.testing.assert_allclose(_knot_values(cp[:, :3]), POINTS, atol=1e-5)
    np.testing.assert_allclose(cp[:, 3], np.concatenate([RADII[:1], RADII, RADII[-1:]]) * BEVEL, rtol=1e-6)
    assert any("spline 0: poly spline approximated by the cubic spline through its 6 points" in w for w in warnings)
    bpy.data.objects.remove(poly)

    # A Bezier spline in the Bezier form of a known B-spline.
    truth = np.concatenate([POINTS[:1] - [0.5, 0, 0], POINTS, POINTS[-1:] + [0.4, 0.1, 0]])
    knots = _knot_values(truth)
    bez = _curve("bez", "BEZIER", knots, RADII)
    for j, p in enumerate(bez.data.splines[0].bezier_points):
        p.handle_left_type = p.handle_right_type = "FREE"
        p.handle_left = (truth[j] + 2 * truth[j + 1]) / 3
        p.handle_right = (2 * truth[j + 1] + truth[j + 2]) / 3
    desc, warnings = addon.export_scene(spp=4)
    np.testing.assert_allclose(desc["bez"]["control_points"][:, :3], truth, atol=1e-5)
    assert warnings == []
    p = bez.data.splines[0].bezier_points[2]
    p.handle_right = tuple(np.array(p.handle_right) + [0, 0, 0.2])  # no longer C2
    desc, warnings = addon.export_scene(spp=4)
    assert any(w.startswith("object 'bez', spline 0: Bezier spline approximated") and "off by up to" in w
               for w in warnings), warnings


def test_hair_export_reads_positions_and_radii(addon):
    """Hair curves (through the depsgraph): Catmull-Rom / poly curves through their points, radii from the
    'radius' attribute (no bevel); a hair NURBS of order 4 exactly."""
    hair = _hair("hair", "POLY")
    hair.location = (0.0, 0.5, 0.0)
    bpy.context.view_layer.update()
    desc, warnings = addon.export_scene(spp=4)
    cp = desc["hair"]["control_points"].astype(np.float64)
    np.testing.assert_allclose(_knot_values(cp[:, :3]), POINTS + [0, 0.5, 0], atol=1e-5)
    np.testing.assert_allclose(cp[1:-1, 3], RADII, rtol=1e-6)
    assert any("hair object 'hair': 1 Catmull-Rom / poly curve(s) approximated" in w for w in warnings), warnings
    bpy.data.objects.remove(hair)
    nurbs = _hair("hairn", "NURBS")
    desc, warnings = addon.export_scene(spp=4)
    np.testing.assert_allclose(desc["hairn"]["control_points"], np.concatenate([POINTS, RADII[:, None]], 1), atol=1e-6)
    assert warnings == []
    # A hair object without a radius attribute (a new one in 3.4 and 4.5 has only 'position'): skipped
    # by the export with a warning, refused by the optimisation.
    nurbs.data.attributes.remove(nurbs.data.attributes["radius"])
    desc, warnings = addon.export_scene(spp=4)
    assert "hairn" not in desc
    assert any("hair object 'hairn' has no 'radius' attribute" in w and w.endswith("skipped") for w in warnings), warnings
    img = bpy.data.images.new("t", 48, 36, float_buffer=True)
    with pytest.raises(ValueError, match="hair object 'hairn' has no 'radius' attribute"):
        addon.optimize(nurbs, [(bpy.data.objects["camera"], img)], iterations=1)


@pytest.mark.parametrize("change, message", [
    (lambda sp: setattr(sp, "order_u", 3), r"object 'fibre', spline 0: NURBS order 3"),
    (lambda sp: setattr(sp, "use_endpoint_u", True), r"object 'fibre', spline 0: NURBS knots are endpoint"),
    (lambda sp: setattr(sp.points[2], "co", (0.0, 0.0, 1.0, 2.5)), r"object 'fibre', spline 0: point 2 has NURBS weight 2.5"),
])
def test_unsupported_curves_are_named(addon, change, message):
    """Curves limn cannot represent: the export falls back to Blender's mesh with a warning naming
    the object, spline and value; the optimisation refuses with the same message."""
    obj = _curve("fibre")
    change(obj.data.splines[0])
    desc, warnings = addon.export_scene(spp=4)
    assert desc["fibre"]["type"] == "mesh"
    assert any(re.search(message, w) and "exported as Blender's tessellated mesh instead" in w for w in warnings), warnings
    img = bpy.data.images.new("t", 48, 36, float_buffer=True)
    with pytest.raises(ValueError, match=message):
        addon.optimize(obj, [(bpy.data.objects["camera"], img)], iterations=1)


def test_curves_that_are_not_tubes_or_cannot_be_written_back_are_refused(addon):
    obj = _curve("flat", bevel=0.0)
    img = bpy.data.images.new("t", 48, 36, float_buffer=True)
    cam = bpy.data.objects["camera"]
    with pytest.raises(ValueError, match="curve object 'flat' is not rendered as limn fibre curves: its bevel depth is 0"):
        addon.optimize(obj, [(cam, img)], iterations=1)
    with pytest.raises(ValueError, match="object 'flat' is a curve object; choose the curve mode"):
        addon.optimize(obj, [(cam, img)], iterations=1, mode="MESH")
    bpy.ops.mesh.primitive_plane_add()
    with pytest.raises(ValueError, match="object 'Plane' is a mesh object; the curve mode"):
        addon.optimize(bpy.context.active_object, [(cam, img)], iterations=1, mode="CURVE")
    obj.data.bevel_depth = BEVEL
    obj.scale = (1.0, 2.0, 1.0)
    bpy.context.view_layer.update()
    desc, warnings = addon.export_scene(spp=4)
    assert desc["flat"]["type"] == "mesh"
    assert any("object 'flat': its transform scales non-uniformly" in w and "tessellated mesh instead" in w
               for w in warnings), warnings
    with pytest.raises(ValueError, match="object 'flat': its transform scales non-uniformly"):
        addon.optimize(obj, [(cam, img)], iterations=1)
    obj.scale = (1.0, 1.0, 1.0)
    obj.data.bevel_factor_end = 0.5
    desc, _ = addon.export_scene(spp=4)
    assert desc["flat"]["type"] == "mesh" and "flat.2" not in desc  # Blender's partial tube, as one mesh
    with pytest.raises(ValueError, match=r"'flat' is not rendered as limn fibre curves: its bevel covers only part"):
        addon.optimize(obj, [(cam, img)], iterations=1)
    obj.data.bevel_factor_end = 1.0
    obj.data.use_radius = False
    desc, _ = addon.export_scene(spp=4)
    np.testing.assert_allclose(desc["flat"]["control_points"][:, 3], BEVEL, rtol=1e-6)  # point radii ignored
    with pytest.raises(ValueError, match="curve object 'flat': its option Radius"):
        addon.optimize(obj, [(cam, img)], iterations=1)
    obj.data.use_radius = True
    obj.data.splines[0].points[1].radius = 0.0
    with pytest.raises(ValueError, match="object 'flat', spline 0: control point 1 has radius 0"):
        addon.optimize(obj, [(cam, img)], iterations=1)


# ---- optimisation ------------------------------------------------------------------------------------
def test_gradient_is_the_chain_rule_of_the_projection(addon):
    """For every piece kind, Source.gradient(g) is the gradient of g . project(x) with respect to x
    (finite differences; project is linear in the entries it keeps, so they are exact up to rounding):
    derived entries get 0, the free ones the share of the derived ones they are made of."""
    c = addon.curves
    rng = np.random.default_rng(3)
    for piece in (c._Piece("natural", 5), c._Piece("nurbs", 6, wrap=True), c._Piece("nurbs", 5), c._Piece("bezier", 4)):
        x = rng.normal(size=(piece.count, 4))
        g = rng.normal(size=(piece.count, 4))
        loss = lambda x: float((g * _projected(c, piece, x)).sum())
        numeric = np.zeros_like(x)
        for idx in np.ndindex(*x.shape):
            e = np.zeros_like(x)
            e[idx] = 1e-3
            numeric[idx] = (loss(x + e) - loss(x - e)) / 2e-3
        chained = g.copy()
        c._chain_piece(piece, chained)
        np.testing.assert_allclose(chained, numeric, atol=1e-9, err_msg=piece.kind)


@pytest.mark.parametrize("kind", ["NURBS", "CYCLIC", "POLY", "BEZIER", "HAIR"])
def test_write_back_exports_again_to_the_same_control_points(addon, kind):
    """Any projected control points written into the object (same type, same point counts) read back
    as the same control points: NURBS and cyclic NURBS points, poly points (knot values), Bezier knots
    and handles (set to Free), hair positions and radii; under a rotation, translation and scale."""
    if kind == "HAIR":
        obj = _hair("obj", "POLY", HAIR_POINTS)
    else:
        obj = _curve("obj", "NURBS" if kind == "CYCLIC" else kind, cyclic=kind == "CYCLIC")
    obj.location, obj.rotation_euler, obj.scale = (0.2, 0.1, -0.3), (0.1, 0.3, -0.2), (1.3, 1.3, 1.3)
    bpy.context.view_layer.update()
    world = np.array([list(r) for r in obj.matrix_world])
    src = addon.curves.Source(obj)
    counts = src.counts()
    x = src.world_control(world).astype(np.float64)
    x += np.random.default_rng(1).normal(scale=0.03, size=x.shape)
    x = src.project(x, world)
    src.write_back(x, world)
    again = addon.curves.Source(obj)
    assert again.counts() == counts and obj.type == ("CURVES" if kind == "HAIR" else "CURVE")
    np.testing.assert_allclose(again.world_control(world), x, atol=2e-5)
    if kind == "BEZIER":
        assert all(p.handle_left_type == p.handle_right_type == "FREE" for p in obj.data.splines[0].bezier_points)


def _projected(c, piece, x):
    y = x.copy()
    c._project_piece(piece, y)
    return y


TRUTH_SHIFT = np.array([0.0, 0.0, 0.25])   # the target's curve is this much higher ...
TRUTH_RADIUS = 1.4                         # ... and this much thicker


def _targets(addon, limn, obj, read, write, truth):
    """Target images of the object with points `truth` (local (n, 4)) from the camera and a side
    camera; the object gets its start points back. Returns ([(camera, image)], the truth's limn
    control points (local, tube radii))."""
    scene = bpy.context.scene
    cam2 = bpy.data.objects.new("cam2", bpy.data.cameras.new("cam2"))
    scene.collection.objects.link(cam2)
    cam2.location, cam2.rotation_euler = (5.5, 0.0, 2.5), (math.radians(68), 0.0, math.radians(90))
    start = read(obj)
    write(obj, truth)
    truth_control = addon.curves.Source(obj).control.copy()
    out = []
    for i, cam in enumerate([bpy.data.objects["camera"], cam2]):
        scene.camera = cam
        bpy.context.view_layer.update()
        desc, _ = addon.export_scene(spp=32)
        img = limn.load_dict(desc).render(spp=64, seed=3 + i)
        im = bpy.data.images.new(f"target{i}", img.shape[1], img.shape[0], float_buffer=True)
        rgba = np.ones((img.shape[0], img.shape[1], 4), np.float32)
        rgba[..., :3] = img[::-1]
        im.pixels.foreach_set(rgba.ravel())
        out.append((cam, im))
    scene.camera = out[0][0]
    write(obj, start)
    bpy.context.view_layer.update()
    return out, truth_control


def _tube(cp, samples=9):
    """Centre line and radius (m, 4) of the uniform cubic B-spline with control points cp (n, 4),
    `samples` per span: what the image shows (the end control points alone are barely seen)."""
    t = np.linspace(0.0, 1.0, samples)[:, None]
    basis = np.concatenate([(1 - t) ** 3, 3 * t ** 3 - 6 * t ** 2 + 4, -3 * t ** 3 + 3 * t ** 2 + 3 * t + 1, t ** 3], 1) / 6
    return np.concatenate([basis @ cp[i:i + 4] for i in range(len(cp) - 3)])


def _errors(cp, truth):
    """(mean distance of the centre lines, mean radius difference) along the tube, control points (n, 4)."""
    a, b = _tube(cp), _tube(truth)
    return float(np.linalg.norm(a[:, :3] - b[:, :3], axis=1).mean()), float(np.abs(a[:, 3] - b[:, 3]).mean())


def _check_moves_towards(addon, name, obj, start, truth, out):
    """The loss falls, and the tube (centre line and radius, from the object's points as the exporter
    reads them) moves towards the truth's."""
    losses = out["losses"]
    p0, r0 = _errors(start, truth)
    p1, r1 = _errors(addon.curves.Source(obj).control, truth)
    print(f"{name}: loss {losses[0]:.5f} -> {min(losses[-3:]):.5f}, centre-line error {p0:.3f} -> {p1:.3f}, "
          f"radius error {r0:.4f} -> {r1:.4f} (along the tube, mean), {len(losses)} iterations in {out['seconds']:.1f} s")
    assert min(losses[-3:]) < 0.6 * losses[0], losses
    assert p1 < 0.6 * p0, (p0, p1)
    assert r1 < 0.8 * r0, (r0, r1)


def test_curve_object_moves_towards_the_target_and_is_written_back(addon, limn):
    """A NURBS curve object, targets from the same curve raised and thickened: the loss and the
    control-point error fall, the result is in the spline's points and radii (same count), in one
    undo step through the operator. The UI's worker-thread job does the same."""
    obj = _curve("fibre")
    start = _legacy_points(obj)
    truth = start.copy()
    truth[:, :3] += TRUTH_SHIFT
    truth[:, 3] *= TRUTH_RADIUS
    start_control = addon.curves.Source(obj).control.copy()
    targets, truth_control = _targets(addon, limn, obj, _legacy_points, _set_legacy, truth)
    out = addon.optimize(obj, targets, iterations=40, spp=8, lr=0.01)
    assert out["mode"] == "CURVE" and not out["cancelled"]
    assert obj.type == "CURVE" and len(obj.data.splines[0].points) == len(POINTS)
    _check_moves_towards(addon, "NURBS curve object", obj, start_control, truth_control, out)

    # The operator: the same loop, one undo step.
    _set_legacy(obj, start)
    s = bpy.context.scene.limn
    s.optimize_object = obj
    for cam, im in targets:
        t = s.targets.add()
        t.camera, t.image = cam, im
    s.iterations, s.spp, s.learning_rate = 4, 4, 0.01
    cameras = [(cam.name, im.name) for cam, im in targets]  # undo replaces the datablocks
    bpy.ops.ed.undo_push(message="before limn")
    assert bpy.ops.limn.optimize("EXEC_DEFAULT", True) == {"FINISHED"}
    moved = _legacy_points(bpy.data.objects["fibre"])
    assert np.abs(moved - start).max() > 1e-3
    bpy.ops.ed.undo()
    np.testing.assert_allclose(_legacy_points(bpy.data.objects["fibre"]), start, atol=1e-6)

    # The UI path: the worker-thread job, polled as the modal operator's timer does; a cancel keeps the last state.
    obj = bpy.data.objects["fibre"]
    targets = [(bpy.data.objects[c], bpy.data.images[im]) for c, im in cameras]
    ops = addon.optimize_ops
    job = ops.OptimizeJob(ops.Problem(obj, targets, 4), iterations=200, spp=4, lr=0.01, lambda_=0.0, write_every=1)
    job.start()
    t0 = time.perf_counter()
    while (status := job.poll())["status"] == "running" and status["iteration"] < 3:
        assert time.perf_counter() - t0 < 60, status
        time.sleep(0.02)
    job.cancel()
    while (status := job.poll())["status"] == "running":
        time.sleep(0.02)
    assert status["status"] == "cancelled" and status["iteration"] < 199, status
    assert job.writes >= 2
    assert np.abs(_legacy_points(obj) - start).max() > 1e-3


@pytest.mark.parametrize("kind", ["POLY", "BEZIER"])
def test_poly_and_bezier_splines_move_towards_the_target(addon, limn, kind):
    """Legacy poly and Bezier splines (converted, module docstring of curves.py): the loss and the
    tube's error fall; the result is in the spline's points (Bezier: knots and free handles)."""
    obj = _curve("fibre", kind, HAIR_POINTS)
    read = lambda o: np.array([(*p.co[:3], p.radius) for p in (o.data.splines[0].bezier_points if kind == "BEZIER"
                                                                else o.data.splines[0].points)])

    def write(o, pts):
        sp = o.data.splines[0]
        for p, v in zip(sp.bezier_points if kind == "BEZIER" else sp.points, pts):
            if kind == "BEZIER":  # automatic handles follow the knots
                p.co, p.radius = v[:3], v[3]
            else:
                p.co, p.radius = (*v[:3], 1.0), v[3]
        o.data.update_tag()

    start = read(obj)
    truth = start.copy()
    truth[:, :3] += TRUTH_SHIFT
    truth[:, 3] *= TRUTH_RADIUS
    start_control = addon.curves.Source(obj).control.copy()
    targets, truth_control = _targets(addon, limn, obj, read, write, truth)
    out = addon.optimize(obj, targets, iterations=40, spp=8, lr=0.01)
    sp = obj.data.splines[0]
    assert sp.type == kind and len(sp.bezier_points if kind == "BEZIER" else sp.points) == len(HAIR_POINTS)
    _check_moves_towards(addon, f"{kind.lower()} spline", obj, start_control, truth_control, out)


def test_hair_object_moves_towards_the_target_and_is_written_back(addon, limn):
    """A hair Curves object (poly curve: the spline through its points): the loss and the error of
    its points fall; the result is in its 'position' and 'radius' attributes, point count unchanged."""
    obj = _hair("hair", "POLY", HAIR_POINTS)
    start = _hair_points(obj)
    truth = start.copy()
    truth[:, :3] += TRUTH_SHIFT
    truth[:, 3] *= TRUTH_RADIUS
    # The hair radius is the tube radius itself: make it a tube of the same size as the legacy one.
    start[:, 3] *= BEVEL
    truth[:, 3] *= BEVEL
    _set_hair(obj, start)
    start_control = addon.curves.Source(obj).control.copy()
    targets, truth_control = _targets(addon, limn, obj, _hair_points, _set_hair, truth)
    out = addon.optimize(obj, targets, iterations=40, spp=8, lr=0.01)
    after = _hair_points(obj)
    assert obj.type == "CURVES" and len(obj.data.points) == len(POINTS) and len(obj.data.curves) == 1
    _check_moves_towards(addon, "hair object", obj, start_control, truth_control, out)
    # What was written exports again to the control points the optimiser ended with.
    desc, _ = addon.export_scene(spp=4)
    cp = desc["hair"]["control_points"].astype(np.float64)
    np.testing.assert_allclose(_knot_values(cp[:, :3]), after[:, :3], atol=1e-5)


def test_radii_stay_positive(addon, limn):
    """Targets without the curve pull its radii towards 0: they are clamped at 1/100 of the smallest
    starting radius (curves.RADIUS_FLOOR), never refused by the scene, and the curve stays a curve."""
    obj = _curve("fibre")
    start = _legacy_points(obj)
    targets, _ = _targets(addon, limn, obj, _legacy_points, _set_legacy, start * [1, 1, 1, 1e-3])
    out = addon.optimize(obj, targets, iterations=25, spp=4, lr=0.05)
    after = _legacy_points(obj)
    floor = addon.curves.RADIUS_FLOOR * start[:, 3].min()
    print(f"radii: {start[:, 3].min():.3f}..{start[:, 3].max():.3f} -> {after[:, 3].min():.5f}..{after[:, 3].max():.5f} "
          f"(floor {floor:.5f}), loss {out['losses'][0]:.5f} -> {out['losses'][-1]:.5f}")
    assert len(out["losses"]) == 25  # not stopped by a refused radius
    assert after[:, 3].min() >= floor * (1 - 1e-6)
    assert after[:, 3].max() < 0.5 * start[:, 3].min()

