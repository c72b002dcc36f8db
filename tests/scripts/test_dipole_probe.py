"""The transport references of experiments/dipole_probe.py (issue 29, item 5): the
standard dipole against Jensen's closed-form total, the directional dipole's symmetry
and the side its light leaves on, and the sum over pixel footprints against the
integral over the plane, so that what the probe reports is about the dipoles."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

import invsss
from tests import ROOT

pytest.importorskip("mitsuba")  # the probe reads scene configs with invsss.scenes

_PATH = ROOT / "experiments" / "dipole_probe.py"
_SPEC = importlib.util.spec_from_file_location("dipole_probe", _PATH)
dipole_probe = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(dipole_probe)

MEDIUM = dipole_probe.Medium(0.7748, 0.02808)  # the thesis-940 preset


def _plane(radius=60.0, count=24000, angles=72):
    """Points of the plane z = 0 around the origin (polar grid) and each one's area."""
    r = (np.arange(count) + 0.5) * radius / count
    phi = np.arange(angles) * 2.0 * np.pi / angles
    rr, pp = np.meshgrid(r, phi, indexing="ij")
    points = np.stack([rr * np.cos(pp), rr * np.sin(pp), np.zeros_like(rr)], axis=-1)
    return points, rr * (radius / count) * (2.0 * np.pi / angles)


def test_the_standard_dipole_sends_back_jensens_total():
    points, area = _plane()
    total = np.pi * np.sum(MEDIUM.standard(np.linalg.norm(points, axis=-1)) * area)
    alpha = MEDIUM.alpha
    root = np.sqrt(3.0 * (1.0 - alpha))
    expected = alpha / 2.0 * (1.0 + np.exp(-4.0 / 3.0 * MEDIUM.A * root)) * np.exp(-root)  # Jensen et al. 2001
    assert total == pytest.approx(expected, rel=2e-3)


def test_the_directional_dipole_is_symmetric_head_on_and_sends_light_on_along_its_way():
    points, area = _plane()
    up = np.broadcast_to([0.0, 0.0, 1.0], points.shape)
    origin = np.zeros_like(points)
    head_on = MEDIUM.directional(origin, up, np.broadcast_to([0.0, 0.0, -1.0], points.shape), points, up)
    np.testing.assert_allclose(head_on, np.broadcast_to(head_on[:, :1], head_on.shape), rtol=1e-9)  # every angle alike
    shifts = []
    for degrees in (30.0, 60.0):
        t = np.radians(degrees)
        oblique = MEDIUM.directional(origin, up, np.broadcast_to([np.sin(t), 0.0, -np.cos(t)], points.shape),
                                     points, up)
        centroid = np.sum(oblique[..., None] * points * area[..., None], axis=(0, 1)) / np.sum(oblique * area)
        assert abs(centroid[1]) < 1e-6
        shifts.append(centroid[0])
    # Light travelling towards +x leaves the surface displaced towards +x, more at 60 degrees.
    assert 0.0 < shifts[0] < shifts[1]


def test_the_sum_over_pixel_footprints_is_the_integral_over_the_plane():
    # A flat card facing the camera, lit head-on and evenly: inside, every pixel sums
    # the dipole over the pixels within the radius, which must equal the integral over
    # that disk of the plane (the near pixels integrated over their footprints).
    size, depth_mm, radius = 48, 400.0, 10
    from invsss.scenes import parse_config

    config = parse_config({
        "object": {"primitive": "sphere", "radius": 40.0},
        "camera": {"position": [0.0, 0.0, depth_mm], "look_at": [0.0, 0.0, 0.0], "fov": 20.0,
                   "width": size, "height": size},
        "lights": [{"type": "directional", "direction": [0.0, 0.0, -1.0], "irradiance": 1.0}],
        "medium": {"preset": "thesis-940"},
    })
    normal = np.broadcast_to([0.0, 0.0, 1.0], (size, size, 3)).copy()
    ones = np.ones((size, size, 1))
    pair = {
        "info": {"config": config.model_dump(mode="json"),
                 "medium": {"sigma_s_prime": [0.7748], "sigma_a": [0.02808], "eta": 1.0}},
        "mask": np.ones((size, size)), "depth": np.full((size, size), depth_mm), "source": ones,
        "buffers": invsss.LightBuffers(normal=normal, light=normal.copy(), key=ones),
    }
    key, = dipole_probe.predictions(pair, radius)["standard"]
    inside = key[radius:-radius, radius:-radius]
    np.testing.assert_allclose(inside, inside.mean(), rtol=1e-6)
    pixel = depth_mm / config.camera.focal_length_px  # mm per pixel, near the centre
    points, area = _plane(radius=radius * pixel)
    disk = np.sum(MEDIUM.standard(np.linalg.norm(points, axis=-1)) * area)
    assert float(inside.mean()) == pytest.approx(disk, rel=0.01)
