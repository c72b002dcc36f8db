"""A small sphere scene's config (the scene tests of scenes and of the command line), and
the camera's rays built without Mitsuba, to compute what a render should hold."""

from __future__ import annotations

import numpy as np

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


def pixel_rays(config, n: int = 8):
    """Unnormalised ray directions (H, W, n, n, 3) through an n x n grid in each pixel.

    Built from the camera's definition, not Mitsuba: pixel (row i, column j)
    spans [j, j + 1] x [i, i + 1], image right is camera right, image down is
    camera down, the optical axis meets the image at the centre plus
    ``principal_offset_px``, and a direction has unit component along the optical axis, so
    the ray parameter of a hit is its eye z.
    """
    camera = config.camera
    origin = np.asarray(camera.position, float)
    forward = np.asarray(camera.look_at, float) - origin
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, camera.up)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    f = camera.focal_length_px
    sub = (np.arange(n) + 0.5) / n
    u = np.arange(camera.width)[None, :, None, None] + sub[None, None, None, :]
    v = np.arange(camera.height)[:, None, None, None] + sub[None, None, :, None]
    # The optical axis meets the image at the centre plus the principal offset.
    x = (u - camera.width / 2 - camera.principal_offset_px[1]) / f
    y = -(v - camera.height / 2 - camera.principal_offset_px[0]) / f
    x, y = np.broadcast_arrays(x, y)
    directions = forward + x[..., None] * right + y[..., None] * up
    return origin, directions, (right, up, forward)
