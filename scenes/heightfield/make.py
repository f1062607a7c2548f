"""Regenerates scenes/heightfield: `python3 scenes/heightfield/make.py`.

The heightfield paper's validation scenes (Tong et al. 2023): the cone of Figure 7 lit by a small
area light (the geometry grows along z; the light moves), a smooth random terrain seen from above
under a sky and a sun-like area light (Figure 8's set-up), and the worst case of Figure A2: a smooth
bump under a very large area light, where the peak search has to march across the whole field.
Heights are stored inline ("data"); terrain.exr holds the terrain's heights as an image as well, for
the "filename" form and for Blender's Displace modifier."""
import json
import os

import numpy as np

import limn
import limn.shapes

here = os.path.dirname(os.path.abspath(__file__))


cone, terrain, bump = limn.shapes.cone_heights, limn.shapes.terrain_heights, limn.shapes.bump_heights


def sensor(origin, target, res=32, spp=16, fov=40):
    return {"type": "perspective", "fov": fov, "to_world": {"look_at": {"origin": origin, "target": target, "up": [0, 0, 1]}},
            "film": {"type": "hdrfilm", "width": res, "height": res}, "sampler": {"type": "independent", "sample_count": spp}}


def heightfield(data, height_scale, reflectance=0.6):
    return {"type": "heightfield", "data": np.round(data, 6).tolist(), "size": [2, 2], "height_scale": height_scale,
            "bsdf": {"type": "diffuse", "reflectance": reflectance}}


def light(scale, position, radiance, target=None):
    """A square of half-size `scale` at `position`, facing `target` (default: straight down)."""
    if target is None:
        to_world = [{"scale": scale}, {"rotate": {"axis": [1, 0, 0], "angle": 180}}, {"translate": position}]
    else:
        to_world = [{"scale": scale}, {"look_at": {"origin": position, "target": target, "up": [0, 0, 1]}}]
    return {"type": "rectangle", "to_world": to_world, "emitter": {"type": "area", "radiance": radiance}}


SCENES = {
    "cone": {"type": "scene", "integrator": {"type": "path", "max_depth": 3},
             "sensor": sensor([0, -3.2, 2.4], [0, 0, 0.2]),
             "terrain": heightfield(cone(), 0.6),
             "light": light(0.25, [1.4, 0.9, 0.9], 40.0, target=[0, 0, 0]),
             "sky": {"type": "constant", "radiance": 0.1}},
    "terrain": {"type": "scene", "integrator": {"type": "path", "max_depth": 3},
                "sensor": sensor([0.0, -2.6, 2.6], [0, 0, 0.1]),
                "terrain": heightfield(terrain(), 0.35),
                "light": light(0.4, [1.8, 1.2, 1.0], 25.0, target=[0, 0, 0]),
                "sky": {"type": "constant", "radiance": 0.3}},
    "bump": {"type": "scene", "integrator": {"type": "path", "max_depth": 2},
             "sensor": sensor([0, -2.8, 2.2], [0, 0, 0.1]),
             "terrain": heightfield(bump(), 0.5),
             "light": light(20.0, [0.0, 0.0, 3.0], 0.5)},
}

if __name__ == "__main__":
    for name, scene in SCENES.items():
        with open(os.path.join(here, name + ".json"), "w") as f:
            json.dump(scene, f)
        limn.load(os.path.join(here, name + ".json"))  # they must load
    limn.write_image(os.path.join(here, "terrain.exr"), np.repeat(terrain()[:, :, None], 3, axis=2).astype(np.float32))
    print("wrote", ", ".join(SCENES), "and terrain.exr to", here)
