"""A small sphere scene's config (the scene tests of scenes and of the command line)."""

from __future__ import annotations

from invsss.scenes import parse_config

CAMERA = {"position": [0.0, 0.0, 300.0], "look_at": [0.0, 0.0, 0.0], "fov": 20.0}
POINT_LIGHT = {"type": "point", "position": [150.0, 150.0, 300.0], "intensity": 1e5}


def sphere_config(**changes):
    """A 32 x 32 render of a 40 mm sphere of the thesis's 940 nm medium, one point light,
    2 spp; ``changes`` replace top-level entries."""
    content = {
        "object": {"primitive": "sphere", "radius": 40.0},
        "camera": {**CAMERA, "width": 32, "height": 32},
        "lights": [POINT_LIGHT],
        "medium": {"preset": "thesis-940"},
        "spp": 2,
    }
    content.update(changes)
    return parse_config(content, "test scene")
