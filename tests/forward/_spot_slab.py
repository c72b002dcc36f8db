"""A flat slab of a known medium lit by a small disc spot, for the profile-measurement
tests: each pixel's exitance is the Jensen dipole summed over the lit pixels."""

from __future__ import annotations

import jax
import numpy as np

from invsss.forward.profiles import jensen_dipole

PITCH = 0.1  # mm per pixel
SPOT_RADIUS = 0.3  # mm
H, W = 41, 121
CENTRE = (20.0, 15.0)
MEDIA = [(0.7748, 0.02808), (2.4, 0.1)]  # thesis-940, and a denser, darker one


def spot_images(sigma_s_prime, sigma_a, irradiance=3.0):
    """A flat slab of the medium lit by a disc spot (the Jensen dipole summed over the lit
    pixels), and the white Lambertian reference that shows the spot's irradiance."""
    rows, cols = np.mgrid[0:H, 0:W].astype(np.float64)
    lit = np.hypot(rows - CENTRE[0], cols - CENTRE[1]) * PITCH <= SPOT_RADIUS
    reference = np.where(lit, irradiance, 0.0)
    skin = np.zeros((H, W))
    with jax.enable_x64(True):
        for y, x in zip(*np.nonzero(lit)):
            r = np.hypot(rows - y, cols - x) * PITCH
            skin += irradiance * PITCH**2 * np.asarray(jensen_dipole(r, sigma_s_prime, sigma_a))
    return skin, reference
