"""Image and mesh files (OpenImageIO and the core's PLY writer); arrays are float32 linear RGB."""
from __future__ import annotations

import os

import numpy as np

from . import _core


def read_image(path: str | os.PathLike, raw: bool = False) -> np.ndarray:
    """Read an EXR/HDR/PNG/JPEG/... file as a (H, W, 3) float32 array of linear RGB.

    8- and 16-bit files are sRGB-decoded unless ``raw`` is true."""
    return _core.read_image(os.fspath(path), raw)


def write_image(path: str | os.PathLike, image) -> None:
    """Write a (H, W, 3) or (H, W) array. .exr/.hdr keep floats; other formats are clamped to
    [0, 1], sRGB-encoded and stored with 8 bits."""
    array = np.asarray(image, dtype=np.float32)
    if array.ndim not in (2, 3) or (array.ndim == 3 and array.shape[2] != 3):
        raise ValueError(f"write_image('{path}'): image must have shape (H, W, 3) or (H, W), got {array.shape}")
    _core.write_image(os.fspath(path), np.ascontiguousarray(array))


def write_ply(path: str | os.PathLike, positions, faces) -> None:
    """Write a triangle mesh as binary PLY (positions (N, 3), faces (F, 3))."""
    _core.write_ply(os.fspath(path), np.asarray(positions, dtype=np.float32), np.asarray(faces, dtype=np.uint32))
