"""limn: a differentiable renderer for inverse shape optimisation.

    import limn
    scene = limn.load("scenes/default.json")
    image = scene.render(spp=64)            # (H, W, 3) float32, linear RGB
    limn.write_image("out.exr", image)

Scene descriptions follow Mitsuba 3's dictionary conventions; see docs/scene-format.md.
"""
from __future__ import annotations

from . import _core
from ._core import RenderCancelled
from .scene import Parameters, Scene, load, load_dict
from .images import read_image, write_image, write_ply
from .fd import fd
from . import optim
from .sdf import MeshSdf, mesh_from_sdf, sdf_from_mesh

__version__ = "0.1.0"
__all__ = ["Scene", "Parameters", "load", "load_dict", "read_image", "write_image", "write_ply", "fd", "optim", "RenderCancelled",
           "sdf_from_mesh", "mesh_from_sdf", "MeshSdf"]
