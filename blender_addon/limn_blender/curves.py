"""Blender curve objects as limn fibre curves (the ``bsplinecurve`` shape: cubic uniform B-spline
tubes with a radius per control point), and optimised control points back into Blender.

Two Blender object types:
- legacy ``Curve`` objects (type CURVE) with a round bevel (the tube radius is bevel_depth x the
  point radius): one limn curve per spline;
- hair ``Curves`` objects (type CURVES, Blender 3.3+; the tube radius is the point attribute
  ``radius``): one limn curve per curve, read from the evaluated object (depsgraph).

How each kind of spline becomes B-spline control points, and what is approximated:
- NURBS of order 4 with uniform knots (neither Endpoint nor Bezier knots) and all weights 1 is a
  cubic uniform B-spline: its points are the control points, exactly (a cyclic one repeats its
  first three points at the end, which closes it exactly). Other orders, Endpoint / Bezier knots
  and weights other than 1 are refused with the object, spline and value.
- POLY splines and hair curves of type Catmull-Rom or poly: the natural cubic spline through the
  points (the B-spline passes through every point; second derivative zero at the ends), with one
  extra control point at each end. Approximated: Blender draws straight segments (poly) or a
  Catmull-Rom spline through the same points; the tube's radius is the B-spline average of the
  points' radii (exact for a constant radius).
- BEZIER splines: the B-spline whose Bezier form (each span's knots and handles) is closest to the
  spline's knots and handles in least squares; exact when the spline is C2 (as one written back by
  limn), otherwise the largest distance is stated in a warning. Radii as for poly splines.
- Cyclic poly and Bezier splines, hair Bezier curves and hair NURBS other than the above are refused.

Write-back inverts these maps: every spline keeps its point count (Blender 3.4 cannot resize hair
curves from Python), so a run never needs a resize. The extra end points of the natural spline
and the repeated points of a cyclic NURBS are not free: `project` re-derives them after every
optimiser step, and their share of the gradient goes to the points they are made of (`gradient`,
the chain rule), so the optimiser moves the free points and what is written back exports again to
the same control points."""
from __future__ import annotations

import numpy as np

# Hair curve types (the CURVE-domain attribute "curve_type") and NURBS knot modes ("knots_mode").
_HAIR_TYPES = {0: "CATMULL_ROM", 1: "POLY", 2: "BEZIER", 3: "NURBS"}
_KNOTS = {0: "NORMAL", 1: "ENDPOINT", 2: "BEZIER", 3: "ENDPOINT_BEZIER"}
# Radii are clamped to at least this share of the smallest starting radius after every optimiser
# step: limn refuses radius <= 0, and a floor far below the starting radii leaves a thin tube.
RADIUS_FLOOR = 1e-2


def fibre_reason(obj) -> str:
    """Why a legacy Curve object is not exported as limn fibre curves ("" if it is): only a round
    bevel tube without extrusion, offset, taper or bevel object, and without modifiers."""
    cu = obj.data
    if cu.bevel_depth <= 0.0:
        return "its bevel depth is 0 (Blender draws no tube)"
    if getattr(cu, "bevel_mode", "ROUND") != "ROUND":
        return f"its bevel mode is {cu.bevel_mode} (not Round)"
    if cu.bevel_object is not None or cu.taper_object is not None:
        return "it has a bevel or taper object"
    if cu.extrude != 0.0 or cu.offset != 0.0:
        return f"it has extrude {cu.extrude:g} / offset {cu.offset:g}"
    if getattr(cu, "bevel_factor_start", 0.0) > 0.0 or getattr(cu, "bevel_factor_end", 1.0) < 1.0:
        return f"its bevel covers only part of it (bevel start {cu.bevel_factor_start:g}, end {cu.bevel_factor_end:g})"
    if cu.dimensions != "3D" or cu.fill_mode != "FULL":
        return f"it is a {cu.dimensions} curve with fill mode {cu.fill_mode} (needs 3D, Full)"
    active = [m.name for m in obj.modifiers if m.show_render]
    if active:
        return f"it has modifiers ({', '.join(active)})"
    return ""


# ---- the linear maps between Blender's points and B-spline control points -----------------------
def _knot_rows(n: int) -> np.ndarray:
    """(n, n + 2): the uniform cubic B-spline's value at its n knots from its n + 2 control points."""
    a = np.zeros((n, n + 2))
    for i in range(n):
        a[i, i:i + 3] = (1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0)
    return a


def _natural(n: int) -> np.ndarray:
    """(n + 2, n + 2): knot values and the two natural end conditions P0 - 2 P1 + P2 = 0 (and at the
    end); invertible for n >= 2."""
    a = np.zeros((n + 2, n + 2))
    a[:n] = _knot_rows(n)
    a[n, :3] = (1.0, -2.0, 1.0)
    a[n + 1, -3:] = (1.0, -2.0, 1.0)
    return a


def _bezier_rows(m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(knots, right handles, left handles) of the Bezier form of a uniform cubic B-spline with
    m + 2 control points, each (m, m + 2): k_j = (P_j + 4 P_j+1 + P_j+2) / 6,
    h_j = (2 P_j+1 + P_j+2) / 3, l_j = (P_j + 2 P_j+1) / 3."""
    k = _knot_rows(m)
    h, l = np.zeros((m, m + 2)), np.zeros((m, m + 2))
    for j in range(m):
        h[j, j + 1:j + 3] = (2.0 / 3.0, 1.0 / 3.0)
        l[j, j:j + 2] = (1.0 / 3.0, 2.0 / 3.0)
    return k, h, l


class _Piece:
    """One spline / hair curve: how its Blender points map to its control points.
    kind: "nurbs" (points are control points; `wrap` repeats the first 3 at the end), "natural"
    (poly / Catmull-Rom through the points) or "bezier"."""

    def __init__(self, kind: str, n: int, wrap: bool = False):
        self.kind, self.n, self.wrap = kind, n, wrap
        self.count = n + 3 if wrap else (n if kind == "nurbs" else n + 2)


def _to_control(piece: _Piece, co: np.ndarray, radius: np.ndarray, handles=None) -> tuple[np.ndarray, float]:
    """Control points (count, 4) in local units from the points (n, 3), radii (n,) and, for
    Bezier, (left, right) handles (n, 3) each. Also the largest fitting residual (Bezier)."""
    n = piece.n
    if piece.kind == "nurbs":
        cp = np.concatenate([co, radius[:, None]], axis=1)
        return (np.concatenate([cp, cp[:3]]) if piece.wrap else cp), 0.0
    r = np.concatenate([radius[:1], radius, radius[-1:]])
    if piece.kind == "natural":
        rhs = np.concatenate([co, np.zeros((2, 3))])
        p = np.linalg.solve(_natural(n), rhs)
        return np.concatenate([p, r[:, None]], axis=1), 0.0
    k, h, l = _bezier_rows(n)
    left, right = handles
    a = np.concatenate([k, h[:-1], l[1:]])
    b = np.concatenate([co, right[:-1], left[1:]])
    p = np.linalg.lstsq(a, b, rcond=None)[0]
    residual = float(np.linalg.norm(a @ p - b, axis=1).max())
    return np.concatenate([p, r[:, None]], axis=1), residual


def _from_control(piece: _Piece, cp: np.ndarray):
    """Inverse of _to_control: (points (n, 3), radii (n,), handles (left, right) or None)."""
    n = piece.n
    if piece.kind == "nurbs":
        return cp[:n, :3], cp[:n, 3], None
    radius = cp[1:n + 1, 3]
    if piece.kind == "natural":
        return _knot_rows(n) @ cp[:, :3], radius, None
    k, h, l = _bezier_rows(n)
    return k @ cp[:, :3], radius, (l @ cp[:, :3], h @ cp[:, :3])


def _project_piece(piece: _Piece, cp: np.ndarray) -> None:
    """Re-derives, in place, the control points that are not free (see the module's docstring)."""
    n = piece.n
    if piece.kind == "nurbs":
        if piece.wrap:
            cp[n:] = cp[:3]
        return
    if piece.kind == "natural":
        cp[0, :3] = 2.0 * cp[1, :3] - cp[2, :3]
        cp[-1, :3] = 2.0 * cp[-2, :3] - cp[-3, :3]
    cp[0, 3], cp[-1, 3] = cp[1, 3], cp[-2, 3]


def _chain_piece(piece: _Piece, g: np.ndarray) -> None:
    """The chain rule of _project_piece, in place: the gradient of each derived control point goes to
    the free ones it is made of (P0 = 2 P1 - P2: g1 += 2 g0, g2 -= g0), and is then zero."""
    n = piece.n
    if piece.kind == "nurbs":
        if piece.wrap:
            g[:3] += g[n:]
            g[n:] = 0.0
        return
    if piece.kind == "natural":
        for d, a, b in ((0, 1, 2), (-1, -2, -3)):
            g[a, :3] += 2.0 * g[d, :3]
            g[b, :3] -= g[d, :3]
            g[d, :3] = 0.0
    g[1, 3] += g[0, 3]
    g[-2, 3] += g[-1, 3]
    g[0, 3] = g[-1, 3] = 0.0


def _attribute(data, name: str, domain_size: int, default, width: int = 1) -> np.ndarray:
    """A hair attribute as a float64 array (domain_size, width) or (domain_size,), or `default`."""
    attr = data.attributes.get(name)
    if attr is None:
        out = np.empty((domain_size, width) if width > 1 else domain_size)
        out[...] = default
        return out
    prop = "vector" if width == 3 else "value"
    if attr.data_type == "BOOLEAN":
        buf = np.empty(domain_size * width, dtype=bool)
    elif attr.data_type in ("INT8", "INT"):
        buf = np.empty(domain_size * width, dtype=np.int32)
    else:
        buf = np.empty(domain_size * width, dtype=np.float32)
    attr.data.foreach_get(prop, buf)
    buf = buf.astype(np.float64)
    return buf.reshape(domain_size, width) if width > 1 else buf


class Source:
    """The fibre curves of a Blender curve object (main thread only). `data_obj` is where the points
    are read (the evaluated object when exporting, the original when optimising); `obj` names the
    object in messages. Attributes: pieces, control (K, 4) local control points, offsets, kind
    ("curve" or "hair"), warnings (what was approximated)."""

    def __init__(self, obj, data_obj=None):
        self.obj = obj
        data_obj = data_obj or obj
        self.warnings: list[str] = []
        self.pieces: list[_Piece] = []
        controls = []
        if obj.type == "CURVE":
            self.kind = "curve"
            self.scale = float(data_obj.data.bevel_depth)
            splines = list(data_obj.data.splines)
            if not splines:
                raise ValueError(f"curve object '{obj.name}' has no splines")
            for i, sp in enumerate(splines):
                controls.append(self._legacy_spline(i, sp))
            self.materials = sorted({sp.material_index for sp in splines})
            # "Radius" off (Curve > Geometry): Blender's bevel ignores the point radii.
            self.use_radius = bool(getattr(data_obj.data, "use_radius", True))
            if data_obj.data.use_fill_caps:
                self.warnings.append(f"curve object '{obj.name}': Fill Caps are not drawn (limn's tubes are open at "
                                     "both ends)")
        elif obj.type == "CURVES":
            self.kind = "hair"
            self.scale = 1.0
            controls = self._hair(data_obj.data)
            self.materials = [0]
        else:
            raise ValueError(f"object '{obj.name}' is a {obj.type.lower()}, not a curve (Curve or hair Curves) object")
        self.control = np.concatenate(controls)
        if self.kind == "curve" and not self.use_radius:
            self.control[:, 3] = 1.0
        self.control[:, 3] *= self.scale
        self.offsets = np.cumsum([0] + [p.count for p in self.pieces[:-1]]).astype(np.int64)
        bad = np.flatnonzero(~(self.control[:, 3] > 0))
        if len(bad):
            c, j = self._locate(int(bad[0]))
            what = "the bevel depth times the point radius" if self.kind == "curve" else "the point radius"
            raise ValueError(f"object '{obj.name}', {self._piece_name(c)}: control point {j} has radius "
                             f"{self.control[bad[0], 3]:g} ({what}); limn's fibre curves need radii > 0")
        self.radius_floor = RADIUS_FLOOR * float(self.control[:, 3].min())

    def _piece_name(self, c: int) -> str:
        return f"spline {c}" if self.kind == "curve" else f"curve {c}"

    def _locate(self, row: int) -> tuple[int, int]:
        c = int(np.searchsorted(self.offsets, row, side="right")) - 1
        return c, row - int(self.offsets[c])

    # ---- legacy Curve ----------------------------------------------------------------------------
    def _legacy_spline(self, i: int, sp) -> np.ndarray:
        what = f"object '{self.obj.name}', spline {i}"
        if sp.type == "BEZIER":
            pts = sp.bezier_points
            n = len(pts)
            co, left, right = (np.empty(n * 3, np.float32) for _ in range(3))
            pts.foreach_get("co", co)
            pts.foreach_get("handle_left", left)
            pts.foreach_get("handle_right", right)
            radius = np.empty(n, np.float32)
            pts.foreach_get("radius", radius)
            co, left, right = (a.reshape(-1, 3).astype(np.float64) for a in (co, left, right))
            if sp.use_cyclic_u:
                raise ValueError(f"{what}: cyclic Bezier splines are not supported; open it or make it a NURBS "
                                 "spline of order 4 without Endpoint or Bezier knots")
            if n < 2:
                raise ValueError(f"{what}: a Bezier spline needs at least 2 points (has {n})")
            piece = _Piece("bezier", n)
            cp, residual = _to_control(piece, co, radius.astype(np.float64), (left, right))
            if residual > 1e-5 * max(1.0, float(np.abs(co).max())):
                self.warnings.append(f"{what}: Bezier spline approximated by a uniform cubic B-spline (least-squares "
                                     f"fit to its points and handles, off by up to {residual:.3g}; radius: the "
                                     "B-spline average of the point radii)")
            self.pieces.append(piece)
            return cp
        pts = sp.points
        n = len(pts)
        co4 = np.empty(n * 4, np.float32)
        pts.foreach_get("co", co4)
        co4 = co4.reshape(-1, 4).astype(np.float64)
        radius = np.empty(n, np.float32)
        pts.foreach_get("radius", radius)
        radius = radius.astype(np.float64)
        if sp.type == "POLY":
            if sp.use_cyclic_u:
                raise ValueError(f"{what}: cyclic poly splines are not supported; open it or make it a NURBS "
                                 "spline of order 4 without Endpoint or Bezier knots")
            if n < 2:
                raise ValueError(f"{what}: a poly spline needs at least 2 points (has {n})")
            piece = _Piece("natural", n)
            self.warnings.append(f"{what}: poly spline approximated by the cubic spline through its {n} points "
                                 "(corners are rounded; radius: the B-spline average of the point radii)")
            self.pieces.append(piece)
            return _to_control(piece, co4[:, :3], radius)[0]
        if sp.type != "NURBS":
            raise ValueError(f"{what}: spline type {sp.type} is not supported")
        self._check_nurbs(what, sp.order_u, "ENDPOINT" if sp.use_endpoint_u else ("BEZIER" if sp.use_bezier_u else
                                                                               "NORMAL"), co4[:, 3], n)
        piece = _Piece("nurbs", n, wrap=bool(sp.use_cyclic_u))
        self.pieces.append(piece)
        return _to_control(piece, co4[:, :3], radius)[0]

    @staticmethod
    def _check_nurbs(what: str, order: int, knots: str, weights: np.ndarray, n: int) -> None:
        if order != 4:
            raise ValueError(f"{what}: NURBS order {order}; limn's fibre curves are cubic uniform B-splines, which "
                             "only order 4 matches (set the order to 4)")
        if knots != "NORMAL":
            raise ValueError(f"{what}: NURBS knots are {knots.replace('_', ' + ').lower()}; only uniform knots match "
                             "limn's uniform B-splines (clear Endpoint and Bezier)")
        off = np.flatnonzero(weights != 1.0)
        if len(off):
            raise ValueError(f"{what}: point {off[0]} has NURBS weight {weights[off[0]]:g}; limn's B-splines are not "
                             "rational (all weights must be 1)")
        if n < 4:
            raise ValueError(f"{what}: an order-4 NURBS spline needs at least 4 points (has {n})")

    # ---- hair Curves -----------------------------------------------------------------------------
    def _hair(self, data) -> list[np.ndarray]:
        nc, npnt = len(data.curves), len(data.points)
        if nc == 0:
            raise ValueError(f"hair object '{self.obj.name}' has no curves")
        if data.attributes.get("radius") is None:
            raise ValueError(f"hair object '{self.obj.name}' has no 'radius' attribute, so its tubes have no "
                             "defined radius; give its points a radius (e.g. a Set Curve Radius node, applied)")
        first = np.empty(nc, np.int32)
        length = np.empty(nc, np.int32)
        data.curves.foreach_get("first_point_index", first)
        data.curves.foreach_get("points_length", length)
        pos = _attribute(data, "position", npnt, 0.0, 3)
        radius = _attribute(data, "radius", npnt, 0.0)
        types = _attribute(data, "curve_type", nc, 0).astype(int)
        cyclic = _attribute(data, "cyclic", nc, 0).astype(bool)
        order = _attribute(data, "nurbs_order", nc, 4).astype(int)
        knots = _attribute(data, "knots_mode", nc, 0).astype(int)
        weights = _attribute(data, "nurbs_weight", npnt, 1.0)
        out, approximated = [], 0
        for c in range(nc):
            what = f"hair object '{self.obj.name}', curve {c}"
            s = slice(first[c], first[c] + length[c])
            n = int(length[c])
            kind = _HAIR_TYPES.get(int(types[c]), str(types[c]))
            if kind == "NURBS":
                self._check_nurbs(what, int(order[c]), _KNOTS.get(int(knots[c]), str(knots[c])), weights[s], n)
                piece = _Piece("nurbs", n, wrap=bool(cyclic[c]))
            elif kind in ("CATMULL_ROM", "POLY"):
                if cyclic[c]:
                    raise ValueError(f"{what}: cyclic {kind.replace('_', '-').lower()} curves are not supported")
                if n < 2:
                    raise ValueError(f"{what}: needs at least 2 points (has {n})")
                piece = _Piece("natural", n)
                approximated += 1
            else:
                raise ValueError(f"{what}: curve type {kind} is not supported (Catmull-Rom, poly and order-4 "
                                 "uniform NURBS are)")
            self.pieces.append(piece)
            out.append(_to_control(piece, pos[s], radius[s])[0])
        self._hair_first, self._hair_length = first, length
        if approximated:
            self.warnings.append(f"hair object '{self.obj.name}': {approximated} Catmull-Rom / poly curve(s) "
                                 "approximated by the cubic spline through their points (radius: the B-spline "
                                 "average of the point radii)")
        return out

    # ---- export -------------------------------------------------------------------------------------
    @staticmethod
    def _placement(name: str, world) -> tuple[np.ndarray, float]:
        """(world 4x4, radius scale): the cube root of |det| scales radii; a non-uniform scale
        (which would make the tubes elliptical) is refused."""
        world = np.asarray(world, dtype=np.float64)
        a = world[:3, :3]
        s = abs(float(np.linalg.det(a))) ** (1.0 / 3.0)
        if s <= 0.0 or np.abs(a.T @ a - s * s * np.eye(3)).max() > 1e-4 * s * s:
            raise ValueError(f"object '{name}': its transform scales non-uniformly (or shears), which would make "
                             f"its tubes elliptical; apply the scale (column lengths "
                             f"{', '.join(f'{v:.4g}' for v in np.linalg.norm(a, axis=0))})")
        return world, s

    def world_control(self, world) -> np.ndarray:
        """(K, 4) float32 control points in world space (positions and radii)."""
        world, s = self._placement(self.obj.name, world)
        out = np.empty_like(self.control)
        out[:, :3] = self.control[:, :3] @ world[:3, :3].T + world[:3, 3]
        out[:, 3] = self.control[:, 3] * s
        return out.astype(np.float32)

    def shape(self, world, bsdf: dict) -> dict:
        return {"type": "bsplinecurve", "control_points": self.world_control(world),
                "curve_offsets": self.offsets.copy(), "bsdf": bsdf}

    # ---- optimisation ---------------------------------------------------------------------------------
    def counts(self) -> tuple:
        """The point count of every spline / curve of the object now (a changed count stops a run)."""
        data = self.obj.data
        if self.kind == "curve":
            return tuple(len(sp.bezier_points) if sp.type == "BEZIER" else len(sp.points) for sp in data.splines)
        length = np.empty(len(data.curves), np.int32)
        data.curves.foreach_get("points_length", length)
        return tuple(int(v) for v in length)

    def project(self, x: np.ndarray, world) -> np.ndarray:
        """x (K, 4) world control points after an optimiser step: radii clamped to at least
        `radius_floor` (world units: times the transform's scale), and the control points that are
        not free re-derived (module docstring)."""
        _, s = self._placement(self.obj.name, world)
        x[:, 3] = np.maximum(x[:, 3], self.radius_floor * s)
        for piece, start in zip(self.pieces, self.offsets):
            _project_piece(piece, x[start:start + piece.count])
        return x

    def gradient(self, g: np.ndarray) -> np.ndarray:
        """The loss gradient (K, 4) onto the free control points (see project)."""
        for piece, start in zip(self.pieces, self.offsets):
            _chain_piece(piece, g[start:start + piece.count])
        return g

    def write_back(self, x: np.ndarray, world) -> None:
        """Stores world control points x (K, 4) in the object's data (same point counts)."""
        world, s = self._placement(self.obj.name, world)
        inv = np.linalg.inv(world)
        local = np.empty(x.shape, dtype=np.float64)
        local[:, :3] = np.asarray(x[:, :3], np.float64) @ inv[:3, :3].T + inv[:3, 3]
        local[:, 3] = np.asarray(x[:, 3], np.float64) / (s * self.scale)
        parts = [_from_control(p, local[o:o + p.count]) for p, o in zip(self.pieces, self.offsets)]
        data = self.obj.data
        if self.kind == "curve":
            for sp, (co, radius, handles) in zip(data.splines, parts):
                if sp.type == "BEZIER":
                    pts = sp.bezier_points
                    for p in pts:  # free handles: Blender would recompute automatic / aligned ones
                        p.handle_left_type = p.handle_right_type = "FREE"
                    pts.foreach_set("co", co.astype(np.float32).ravel())
                    pts.foreach_set("handle_left", handles[0].astype(np.float32).ravel())
                    pts.foreach_set("handle_right", handles[1].astype(np.float32).ravel())
                    pts.foreach_set("radius", radius.astype(np.float32))
                    continue
                co4 = np.empty(len(sp.points) * 4, np.float32)
                sp.points.foreach_get("co", co4)
                co4 = co4.reshape(-1, 4)
                co4[:, :3] = co
                sp.points.foreach_set("co", co4.ravel())
                sp.points.foreach_set("radius", radius.astype(np.float32))
        else:
            npnt = len(data.points)
            pos = np.empty((npnt, 3), np.float32)
            data.attributes["position"].data.foreach_get("vector", pos.ravel())
            rad = np.empty(npnt, np.float32)
            data.attributes["radius"].data.foreach_get("value", rad)
            for f, n, (co, radius, _) in zip(self._hair_first, self._hair_length, parts):
                pos[f:f + n] = co
                rad[f:f + n] = radius
            data.attributes["position"].data.foreach_set("vector", pos.ravel())
            data.attributes["radius"].data.foreach_set("value", rad)
        data.update_tag()
        self.obj.update_tag()
