"""Blender objects as limn heightfields, and the way back.

Two kinds of source:
- "displace": a flat mesh (e.g. the default plane) with a Displace modifier driven by an image
  texture (texture coordinates UV, direction Normal or Z, local space). The image's pixels are the
  heights: heights = s * (intensity - mid_level), height_scale = |strength| * the object's z scale,
  s = +-1 from the strength's sign and the plane's facing; intensity is the mean of R, G, B (what
  Displace reads from a colour texture; no sRGB decoding, as Displace does not decode either).
- "grid": a mesh whose vertices form a regular rows x columns grid in local x, y (e.g.
  primitive_grid_add); the heights are the vertices' local z (height_scale = the object's z scale).

limn's frame: x across the width, y across the depth, z up; row 0 of the heights is the far edge
(y = +D/2, the image's top row: Blender stores image rows bottom first, so they are flipped),
column 0 is x = -W/2. limn's surface is a uniform cubic B-spline through the control heights: it
approximates them (smooths them), it does not interpolate them, so it is smoother than Blender's
mesh through the same heights, and its control points span the plane edge to edge (column j at
x = -W/2 + j W / (columns - 1)) where Blender's Displace samples pixel j around u = (j + 1/2) / columns:
the two differ by up to half a pixel."""
from __future__ import annotations

import bpy
import numpy as np


def _matrix(m) -> np.ndarray:
    return np.array([list(row) for row in m], dtype=np.float64)


def displace_modifier(obj):
    """The first render-enabled Displace modifier of `obj`, or None."""
    return next((m for m in obj.modifiers if m.type == "DISPLACE" and m.show_render), None)


def has_image_displace(obj) -> bool:
    m = displace_modifier(obj) if obj is not None and obj.type == "MESH" else None
    return m is not None and m.texture is not None and m.texture.type == "IMAGE" and m.texture.image is not None


def _local_co(mesh) -> np.ndarray:
    co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def _levels(values: np.ndarray, tol: float) -> np.ndarray:
    """Distinct values (sorted), merging those closer than tol."""
    v = np.sort(values)
    starts = np.concatenate([[True], np.diff(v) > tol])
    group = np.cumsum(starts) - 1
    return np.bincount(group, weights=v) / np.bincount(group)


def _image_intensity(image, what: str) -> np.ndarray:
    """(rows, columns) mean of R, G, B with row 0 the image's top row."""
    w, h = image.size
    if w < 2 or h < 2:
        raise ValueError(f"{what}: image '{image.name}' has no pixels (size {w} x {h}; is its file missing?)")
    px = np.empty(w * h * image.channels, dtype=np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(h, w, image.channels)[::-1]
    rgb = px[..., :3] if image.channels >= 3 else px[..., :1]
    return rgb.mean(axis=2).astype(np.float32)


def _not_in_place(image) -> str:
    """Why optimised heights cannot be written into `image` itself ("" if they can): they need a
    float buffer that packs as OpenEXR and is read back without a colour transform."""
    cs = image.colorspace_settings
    if not image.is_float:
        return "stores 8 bits per channel"
    if not (cs.is_data or cs.name.startswith("Linear")):
        return f"has colour space '{cs.name}' (not Non-Color or linear)"
    if image.source == "FILE" and image.file_format != "OPEN_EXR":
        return f"is a {image.file_format} file, not OpenEXR"
    if image.source not in ("FILE", "GENERATED"):
        return f"is a {image.source.lower()} image"
    return ""


class Source:
    """Where an object's heights live in Blender (main thread only). Attributes: kind, obj, rows,
    columns, heights (rows, columns) float32 as limn's control heights, size (W, D) and
    height_scale in the object's local units, centre (the local point under the heightfield's
    origin), warnings."""

    def __init__(self, obj):
        if obj is None or obj.type != "MESH":
            raise ValueError(f"'{getattr(obj, 'name', obj)}' is not a mesh object; a limn heightfield comes from "
                             "a plane with an image Displace modifier or from a regular grid mesh")
        self.obj = obj
        self.warnings: list[str] = []
        self.modifier = displace_modifier(obj)
        if self.modifier is not None:
            self._from_displace()
        else:
            self._from_grid()

    # ---- plane + Displace(image) ------------------------------------------------------------------
    def _from_displace(self):
        obj, m = self.obj, self.modifier
        self.kind = "displace"
        what = f"object '{obj.name}', modifier '{m.name}'"
        tex = m.texture
        if tex is None or tex.type != "IMAGE" or tex.image is None:
            got = "no texture" if tex is None else (f"texture '{tex.name}' of type {tex.type}" if tex.type != "IMAGE"
                                                   else f"image texture '{tex.name}' without an image")
            raise ValueError(f"{what}: a limn heightfield needs an image texture on the Displace modifier (got {got})")
        if m.texture_coords != "UV":
            raise ValueError(f"{what}: texture coordinates must be UV (got {m.texture_coords})")
        if m.direction not in ("NORMAL", "Z"):
            raise ValueError(f"{what}: direction must be Normal or Z (got {m.direction})")
        if m.direction == "Z" and m.space != "LOCAL":
            raise ValueError(f"{what}: space must be Local (got {m.space})")
        if m.vertex_group:
            raise ValueError(f"{what}: vertex group '{m.vertex_group}' weights the displacement, which a limn "
                             "heightfield cannot represent; remove it (use a mask image to hold heights fixed)")
        if m.strength == 0.0:
            raise ValueError(f"{what}: strength is 0; a limn heightfield needs a non-zero strength")
        for prop, default in (("intensity", 1.0), ("contrast", 1.0), ("saturation", 1.0), ("repeat_x", 1),
                              ("repeat_y", 1), ("crop_min_x", 0.0), ("crop_min_y", 0.0), ("crop_max_x", 1.0),
                              ("crop_max_y", 1.0), ("use_flip_axis", False), ("use_color_ramp", False)):
            value = getattr(tex, prop, default)
            if value != default:
                raise ValueError(f"{what}: texture '{tex.name}' has {prop} = {value!r}; limn maps the image as is "
                                 f"(needs {prop} = {default!r})")
        mesh = obj.data
        co = _local_co(mesh)
        if len(co) < 3:
            raise ValueError(f"object '{obj.name}': {len(co)} vertices, not a plane")
        lo, hi = co.min(0), co.max(0)
        ext = hi - lo
        if ext[0] <= 0 or ext[1] <= 0 or ext[2] > 1e-6 * max(ext[0], ext[1]):
            raise ValueError(f"object '{obj.name}': the mesh under the Displace modifier must be flat in its local "
                             f"x, y plane (its extent is {ext[0]:g} x {ext[1]:g} x {ext[2]:g})")
        # The UV map must be the plane's default layout: u = x / W + 1/2, v = y / D + 1/2.
        uv_layer = mesh.uv_layers.get(m.uv_layer) if m.uv_layer else mesh.uv_layers.active
        if uv_layer is None:
            raise ValueError(f"{what}: UV map '{m.uv_layer or '(active)'}' does not exist on mesh '{mesh.name}'")
        uv = np.empty(len(mesh.loops) * 2, dtype=np.float32)
        uv_layer.data.foreach_get("uv", uv)
        vi = np.empty(len(mesh.loops), dtype=np.int32)
        mesh.loops.foreach_get("vertex_index", vi)
        expected = (co[vi, :2] - lo[:2]) / ext[:2]
        bad = np.abs(uv.reshape(-1, 2) - expected).max() if len(vi) else 0.0
        if bad > 1e-4:
            raise ValueError(f"{what}: UV map '{uv_layer.name}' is not the plane's default layout (u = x / W + 1/2, "
                             f"v = y / D + 1/2; off by up to {bad:.3g}); reset the UVs or use a grid mesh")
        # Displace moves along +-local z: along the normal (the plane's facing) or along z.
        facing = 1.0
        if m.direction == "NORMAL" and len(mesh.polygons):
            nz = np.empty(len(mesh.polygons) * 3, dtype=np.float32)
            mesh.polygons.foreach_get("normal", nz)
            nz = nz.reshape(-1, 3)[:, 2]
            if (nz > 0).all():
                facing = 1.0
            elif (nz < 0).all():
                facing = -1.0
            else:
                raise ValueError(f"object '{obj.name}': its faces point both up and down; Displace along the normal "
                                 "is not a heightfield (recalculate the normals)")
        self.image = tex.image
        self.texture = tex
        self.sign = float(np.sign(m.strength)) * facing
        self.mid_level = float(m.mid_level)
        intensity = _image_intensity(self.image, what)
        self.heights = (self.sign * (intensity - self.mid_level)).astype(np.float32)
        self.rows, self.columns = self.heights.shape
        self.size = (float(ext[0]), float(ext[1]))
        self.height_scale = abs(float(m.strength))
        self.centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
        self.order = None
        later = [x.name for x in list(obj.modifiers)[list(obj.modifiers).index(m) + 1:] if x.show_render]
        if later:
            self.warnings.append(f"object '{obj.name}': modifiers after '{m.name}' ({', '.join(later)}) are ignored "
                                 "by the limn heightfield")
        why = _not_in_place(self.image)
        if why:
            self.warnings.append(f"object '{obj.name}': image '{self.image.name}' {why}; optimised heights go into "
                                 "a new float image")

    # ---- grid mesh ---------------------------------------------------------------------------------
    def _from_grid(self):
        obj = self.obj
        self.kind = "grid"
        co = _local_co(obj.data)
        n = len(co)
        if n < 4:
            raise ValueError(f"object '{obj.name}' is not a regular grid in its local x, y: it has {n} vertices")
        lo, hi = co.min(0), co.max(0)
        tol = 1e-5 * max(float(hi[0] - lo[0]), float(hi[1] - lo[1]), 1e-30)
        xs, ys = _levels(co[:, 0], tol), _levels(co[:, 1], tol)
        cols, rows = len(xs), len(ys)
        if cols < 2 or rows < 2 or cols * rows != n:
            raise ValueError(f"object '{obj.name}' is not a regular grid in its local x, y: its {n} vertices have "
                             f"{cols} distinct x and {rows} distinct y values ({cols} x {rows} = {cols * rows} grid "
                             "points); use a grid mesh (Add > Mesh > Grid) or a plane with an image Displace modifier")
        for axis, levels in (("x", xs), ("y", ys)):
            steps = np.diff(levels)
            if steps.max() - steps.min() > 1e-3 * steps.mean():
                raise ValueError(f"object '{obj.name}' is not a regular grid: its {axis} values are not evenly "
                                 f"spaced (steps from {steps.min():g} to {steps.max():g})")
        col = np.clip(np.searchsorted(xs, co[:, 0] - tol), 0, cols - 1)
        row = rows - 1 - np.clip(np.searchsorted(ys, co[:, 1] - tol), 0, rows - 1)  # row 0: largest y
        cell = row * cols + col
        if len(np.unique(cell)) != n:
            raise ValueError(f"object '{obj.name}' is not a regular grid: several vertices share a grid point of "
                             f"the {cols} x {rows} grid")
        self.order = np.empty(n, dtype=np.int64)
        self.order[cell] = np.arange(n)  # vertex index of each (row, column), row-major
        self.heights = co[self.order, 2].reshape(rows, cols).astype(np.float32)
        self.rows, self.columns = rows, cols
        self.size = (float(xs[-1] - xs[0]), float(ys[-1] - ys[0]))
        self.height_scale = 1.0
        self.centre = np.array([(xs[0] + xs[-1]) / 2, (ys[0] + ys[-1]) / 2, 0.0])
        active = [x.name for x in obj.modifiers if x.show_render]
        if active:
            self.warnings.append(f"object '{obj.name}': modifiers ({', '.join(active)}) are ignored by the limn "
                                 "heightfield made from its grid vertices")

    # ---- export ------------------------------------------------------------------------------------
    def shape(self, world, bsdf: dict) -> dict:
        """The limn heightfield for the object placed by `world` (4x4)."""
        world = np.asarray(world, dtype=np.float64)
        a = world[:3, :3]
        scale = np.linalg.norm(a, axis=0)
        if (scale <= 0).any():
            raise ValueError(f"object '{self.obj.name}': its transform has a zero scale")
        rot = a / scale
        if np.abs(rot.T @ rot - np.eye(3)).max() > 1e-4:
            raise ValueError(f"object '{self.obj.name}': its transform shears (a non-uniform scale under a rotated "
                             "parent?); a limn heightfield needs rotation, scale along the object's axes and translation")
        if np.linalg.det(rot) < 0:
            raise ValueError(f"object '{self.obj.name}': its transform mirrors (negative scale); apply the scale or "
                             "flip the object another way")
        to_world = np.eye(4)
        to_world[:3, :3] = rot
        to_world[:3, 3] = a @ self.centre + world[:3, 3]
        return {"type": "heightfield", "data": self.heights.copy(),
                "size": [self.size[0] * float(scale[0]), self.size[1] * float(scale[1])],
                "height_scale": self.height_scale * float(scale[2]),
                "to_world": [[float(x) for x in r] for r in to_world], "bsdf": bsdf}

    # ---- optimisation --------------------------------------------------------------------------------
    def mask(self, vertex_group: str = "", image=None):
        """(rows * columns,) 0/1 array, 0 = height held fixed, or None: zero weight in the vertex group
        (grid meshes; vertices outside the group count as 0) or zero intensity in the mask image (its
        size must be columns x rows; its top row is the far edge, like the heights)."""
        keep = np.ones(self.rows * self.columns, dtype=np.float32)
        used = False
        if vertex_group:
            group = self.obj.vertex_groups.get(vertex_group)
            if group is None:
                raise ValueError(f"object '{self.obj.name}' has no vertex group '{vertex_group}'")
            if self.kind != "grid":
                raise ValueError(f"object '{self.obj.name}': a vertex-group mask needs a grid mesh (its heights come "
                                 f"from image '{self.image.name}'); use a mask image instead")
            weights = np.zeros(len(self.obj.data.vertices), dtype=np.float32)
            gi = group.index
            for v in self.obj.data.vertices:
                for g in v.groups:
                    if g.group == gi:
                        weights[v.index] = g.weight
            keep *= (weights[self.order] > 0).astype(np.float32)
            used = True
        if image is not None:
            w, h = image.size
            if (h, w) != (self.rows, self.columns):
                raise ValueError(f"mask image '{image.name}' is {w} x {h}; the heights of object '{self.obj.name}' are "
                                 f"{self.columns} x {self.rows} (columns x rows)")
            keep *= (_image_intensity(image, f"mask for object '{self.obj.name}'") > 0).ravel().astype(np.float32)
            used = True
        return keep if used else None

    def write_back(self, heights, final: bool = True) -> None:
        """Stores limn heights (rows, columns) in the Blender source: the displacement image (a float
        image, packed into the .blend when `final`; a new one, "<name> (limn)" with the texture
        pointing at it, if the original stores bytes or is not a linear OpenEXR / generated image)
        or the grid vertices' z. Blender's undo does not restore the pixels of an image written in
        place (it restores the mesh, and the texture's original image when a new one was made)."""
        h = np.asarray(heights, dtype=np.float32).reshape(self.rows, self.columns)
        if self.kind == "grid":
            mesh = self.obj.data
            co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
            mesh.vertices.foreach_get("co", co)
            co = co.reshape(-1, 3)
            co[self.order, 2] = h.ravel()
            mesh.vertices.foreach_set("co", co.ravel())
            mesh.update()
            return
        if _not_in_place(self.image):  # e.g. 8 bits cannot hold optimised heights: a float image replaces it
            old = self.image
            img = bpy.data.images.new(f"{old.name} (limn)", width=self.columns, height=self.rows, alpha=False,
                                      float_buffer=True)
            img.colorspace_settings.name = "Non-Color"
            self.texture.image = img
            self.image = img
        value = self.sign * h + self.mid_level  # inverse of heights = sign * (intensity - mid_level)
        rgba = np.ones((self.rows, self.columns, 4), dtype=np.float32)
        rgba[..., :3] = value[::-1, :, None]  # Blender stores rows bottom first
        img = self.image
        img.pixels.foreach_set(rgba[..., :img.channels].ravel())
        img.update()
        if final:
            img.pack()  # float images pack as full-float OpenEXR
        self.texture.update_tag()
        self.obj.update_tag()
