"""The Lambertian albedo that reflects the same energy as a slab of the medium.

The source image stands for "the same skin without subsurface scattering": a
Lambertian surface whose albedo is the medium's total diffuse reflectance, so
that on a flat, uniformly lit patch the source and the target agree and only
the spatial spread differs.

The dipole's closed form (:func:`invsss.forward.profiles.jensen_dipole_total`) is not
accurate enough for that against the path tracer. For the thesis's 940 nm medium
Mitsuba 3.9.1 gives a diffuse albedo about 13 % lower than the dipole's 0.462
behind a Beckmann boundary of alpha 0.5, and about 4 % lower at alpha 0.2: the
single-scattering microfacet boundary loses energy each time light crosses it, and
light crosses it (or is reflected back by it) many times. So the albedo is
measured with the path tracer itself, in the same settings as the target: a thick
slab of the medium under a uniform white sky, looked at straight down, with the
boundary's own reflection subtracted (rendered separately with a black interior).
Under uniform light of radiance 1 the reflected radiance is the directional albedo,
which a Lambertian surface of that albedo reproduces. The standard error of the
mean comes with it. An index-matched boundary (``null`` surface) reflects nothing,
so there is nothing to subtract.
"""

from __future__ import annotations

import numpy as np

from .mitsuba_scene import boundary_bsdf, medium_dict

__all__ = ["CALIBRATION_SPP", "CALIBRATION_PIXELS", "slab_albedo"]

#: Samples per pixel and image side of the calibration render: about 65k paths,
#: a standard error near 0.5 % of the albedo, about 2 s on two cores in scalar_rgb.
CALIBRATION_SPP = 256
CALIBRATION_PIXELS = 16


def _slab_scene(mi, interior: dict, boundary: dict, thickness: float, max_depth: int) -> dict:
    width = 50.0 * thickness  # wide enough that no path that matters reaches the sides
    return {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": max_depth},
        "sensor": {
            "type": "perspective", "fov": 1.0, "fov_axis": "x",
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 10 * thickness], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": CALIBRATION_PIXELS, "height": CALIBRATION_PIXELS,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": CALIBRATION_SPP},
        },
        "slab": {"type": "cube", "bsdf": boundary, "interior": interior,
                 "to_world": mi.ScalarTransform4f().translate([0, 0, -thickness / 2])
                 .scale([width / 2, width / 2, thickness / 2])},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
    }


def slab_albedo(mi, medium: dict, *, max_depth: int = 256, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Diffuse albedo of a semi-infinite slab of the medium, path traced, and its standard error.

    Parameters
    ----------
    mi : module
        Mitsuba with a variant set.
    medium : dict
        :meth:`~invsss.scenes.config.Medium.coefficients`: ``sigma_s_prime`` and
        ``sigma_a`` in 1/mm (1 or 3 values), ``eta``, ``boundary``, ``roughness``.
    max_depth, seed : int
        As in the target render.

    Returns
    -------
    (albedo, standard_error) : two arrays of shape (C,), C the number of coefficients

    Examples
    --------
    >>> from invsss.scenes.mitsuba_scene import import_mitsuba
    >>> medium = {"sigma_s_prime": [0.7748], "sigma_a": [0.02808], "eta": 1.3,
    ...           "boundary": "rough-dielectric", "roughness": 0.5}
    >>> albedo, error = slab_albedo(import_mitsuba("scalar_rgb"), medium)
    >>> bool(abs(albedo[0] - 0.404) < 5 * error[0]), bool(error[0] < 0.005)  # the dipole says 0.462
    (True, True)
    """
    sigma_s_prime, sigma_a = medium["sigma_s_prime"], medium["sigma_a"]
    boundary = boundary_bsdf(medium)
    s = np.asarray(sigma_s_prime, np.float64)
    a = np.asarray(sigma_a, np.float64)
    # Semi-infinite: 30 diffusion lengths (1 / sigma_tr) of the most penetrating channel.
    diffusion_length = 1.0 / np.sqrt(3.0 * a * (s + a))
    thickness = float(max(30.0 * diffusion_length.max(), 20.0 / (s + a).min()))
    black = {"type": "homogeneous", "sigma_t": 1e4, "albedo": {"type": "rgb", "value": 0.0}}
    channels = s.size
    total = np.asarray(mi.render(mi.load_dict(_slab_scene(mi, medium_dict(s.tolist(), a.tolist()), boundary,
                                                          thickness, max_depth)), seed=seed), np.float64)
    if medium["boundary"] == "index-matched":
        mirror = np.zeros_like(total)  # nothing to reflect
    else:
        mirror = np.asarray(mi.render(mi.load_dict(_slab_scene(mi, black, boundary, thickness, max_depth)),
                                      seed=seed + 1), np.float64)
    diffuse = (total - mirror)[..., :channels].reshape(-1, channels)
    albedo = diffuse.mean(axis=0)
    error = diffuse.std(axis=0, ddof=1) / np.sqrt(diffuse.shape[0])
    return albedo, error
