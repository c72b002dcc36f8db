"""Would the transport as a whole close the gap? The directional dipole over the surface (issue 29, item 5)

The light terms (docs/model.md, section 8) put a shift and a reflectance law around a
screen-space blur; the probes of ``layers_probe.py`` found no local layer that closes
the 5-6 dB left between the best term fit and the noise ceiling on the tuning pairs,
and docs/model.md named the next candidate: the transport as a whole, the directional
dipole of Frisvad, Hachisuka and Kjeldsen (2014, "Directional dipole model for
subsurface scattering", ACM TOG 34(1)) integrated over the surface. This script
measures that before anything is built: it predicts the target from the buffers with
no fitted shape at all, only the medium's own coefficients from ``scene.json``.

For every pixel ``x_o`` on the mask eroded by 2 px it sums, over the pixels ``x_i`` of
the mask within ``--radius`` px,

    L(x_o) = sum_i  S_d(x_i, l_i; x_o) E(x_i) A(x_i)

with ``E`` the light arriving at ``x_i`` (the key light's part ``K`` of the Lambertian
source, and the other lights' part ``S - K`` with the second light's direction from
``fill_light.exr``; both in the source's units, which a gain absorbs), ``A`` the
pixel's footprint on the tangent plane at ``x_i`` (the pixel's corners cast onto it,
the cosine to the ray at least 0.2), and ``S_d`` either

* the **standard dipole** (Jensen et al. 2001): ``R_d(r) / pi`` of the distance ``r``
  between the two points, no direction; or
* the **directional dipole**: the real source along the refracted ray (``-l`` for
  the index-matched media of the tuning pairs), the virtual one mirrored in the
  modified tangent plane, and the terms in ``x . w``, ``w . n_o`` and ``x . n_o``
  that make the exitant light depend on where the light came from and on both
  normals (their equations 11-21, with ``eta = 1``: ``C_phi = 1/4``, ``C_E = 1/2``,
  ``A = 1``; ``d_e = 2.131 D / sqrt(alpha')``).

Pixels within 2 px of ``x_o`` (Chebyshev) are integrated with 4 x 4 points on their footprint,
farther ones with their centre. Each prediction is scored as
``experiments/fidelity.py`` scores a fit's, as the least-squares mix of the key and
the other lights' predictions plus an offset (as the fit's linear weights would mix
them), against the plain fit and the ``shift,law,fill`` fit; and mixed into that fit,
to see whether it holds anything the fit lacks.

Index-matched pairs only (the rough dielectrics would need the Fresnel terms); run it
on tuning pairs (data_synthetic/SPLIT.toml)::

    python experiments/dipole_probe.py data_synthetic/pt_face_940 data_synthetic/pt_proc_area_940
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

import invsss

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from fidelity import eroded, load_scene_pair  # noqa: E402
from layers_probe import shifted  # noqa: E402
from reflectance_probe import mixed_psnr  # noqa: E402

#: The near pixels (Chebyshev distance, px) integrated over their footprint.
NEAR = 2
#: Points per footprint side for the near pixels (none at the centre, so x_i != x_o).
SUBSAMPLES = 4


class Medium:
    """The diffusion quantities of an isotropic, index-matched medium (mm, 1/mm)."""

    def __init__(self, sigma_s_prime: float, sigma_a: float):
        self.sigma_t = sigma_s_prime + sigma_a
        self.alpha = sigma_s_prime / self.sigma_t
        self.D = 1.0 / (3.0 * self.sigma_t)
        self.sigma_tr = np.sqrt(sigma_a / self.D)
        self.d_e = 2.131 * self.D / np.sqrt(self.alpha)  # the extrapolated boundary's depth
        self.c_phi, self.c_e, self.A = 0.25, 0.5, 1.0  # eta = 1

    def standard(self, r):
        """Jensen's dipole ``R_d(r) / pi`` (radiance per incident flux, per mm^2)."""
        z_r = 1.0 / self.sigma_t
        z_v = z_r + 4.0 * self.A * self.D
        d_r, d_v = np.sqrt(r**2 + z_r**2), np.sqrt(r**2 + z_v**2)
        s = self.sigma_tr
        return self.alpha / (4.0 * np.pi**2) * (z_r * (1 + s * d_r) * np.exp(-s * d_r) / d_r**3
                                                + z_v * (1 + s * d_v) * np.exp(-s * d_v) / d_v**3)

    def _s_prime(self, x, w, n_o, r):
        """Equation 11 of Frisvad et al. for one source: ``x`` from it to ``x_o``, its direction ``w``."""
        s_r = self.sigma_tr * r
        x_w, w_n, x_n = (np.sum(a * b, axis=-1) for a, b in ((x, w), (w, n_o), (x, n_o)))
        first = self.c_phi * (r**2 / self.D + 3.0 * (1 + s_r) * x_w)
        second = self.c_e * (3.0 * self.D * (1 + s_r) * w_n
                             - (1 + s_r + 3.0 * self.D * (3.0 * (1 + s_r) + s_r**2) / r**2 * x_w) * x_n)
        return np.exp(-s_r) / (4.0 * np.pi**2 * r**3) * (first - second)

    def directional(self, x_i, n_i, w, x_o, n_o):
        """The directional dipole ``S_d`` for light entering at ``x_i`` (normal ``n_i``)
        along ``w`` (the refracted direction, into the medium) and leaving at ``x_o``."""
        x = x_o - x_i
        r2 = np.maximum(np.sum(x * x, axis=-1), 1e-12)
        side = np.cross(n_i, x)
        side /= np.maximum(np.linalg.norm(side, axis=-1, keepdims=True), 1e-12)
        n_star = np.cross(x / np.sqrt(r2)[..., None], side)  # the modified tangent plane's normal
        x_w = np.sum(x * w, axis=-1)
        cos_beta = -np.sqrt(np.maximum(r2 - x_w**2, 0.0) / (r2 + self.d_e**2))
        mu0 = -np.sum(w * n_o, axis=-1)
        z_r2 = np.where(mu0 > 0, self.D * mu0 * (self.D * mu0 - 2.0 * self.d_e * cos_beta),
                        1.0 / (3.0 * self.sigma_t) ** 2)
        d_r = np.sqrt(r2 + z_r2)
        x_v = x_i + 2.0 * self.A * self.d_e * n_star
        w_v = w - 2.0 * np.sum(w * n_star, axis=-1, keepdims=True) * n_star  # w mirrored in that plane
        to_v = x_o - x_v
        d_v = np.linalg.norm(to_v, axis=-1)
        value = self._s_prime(x, w, n_o, d_r) - self._s_prime(to_v, w_v, n_o, d_v)
        return np.maximum(value / (4.0 * self.c_phi), 0.0)


def ray_directions(config, shape, within=(0.0, 0.0)) -> np.ndarray:
    """Camera-space directions (H, W, 3; not unit, depth 1) of the rays through every
    pixel's centre moved by ``within`` = (rows, cols) pixels."""
    from invsss.scenes.path_tracing import camera_points

    return camera_points(config, np.ones(shape), within)


def footprint_points(config, points, normal, a: float, b: float):
    """Where the ray through ``(row + b, col + a)`` meets each pixel's tangent plane (the
    plane through its point with its normal), camera space, (H, W, 3)."""
    ray = ray_directions(config, points.shape[:2], (b, a))
    # The cosine to the ray at least 0.2, as in pixel_area: a plane seen edge-on (or a
    # normal facing away) would send the point off to infinity.
    along = np.minimum(np.sum(normal * ray, axis=-1), -0.2 * np.linalg.norm(ray, axis=-1))
    return ray * (np.sum(normal * points, axis=-1) / along)[..., None]


def pixel_area(config, points, normal) -> np.ndarray:
    """Each pixel's footprint on its tangent plane (mm^2): its solid angle,
    ``1 / (f^2 |ray|^3)`` for the ray ``(x / f, y / f, -1)``, times the squared distance
    ``depth^2 |ray|^2``, over the cosine between the normal and the ray (at least 0.2)."""
    depth = -points[..., 2]
    f = config.camera.focal_length_px
    ray = ray_directions(config, points.shape[:2])
    length = np.linalg.norm(ray, axis=-1)
    cosine = np.maximum(np.abs(np.sum(normal * ray, axis=-1)) / length, 0.2)
    return (depth / f) ** 2 / length / cosine


def predictions(pair, radius: int) -> dict:
    """The standard and directional dipole predictions of the key light's part and of
    the other lights', each (H, W): ``{"standard": (key, fill), "directional": (key, fill)}``."""
    info = pair["info"]
    from invsss.scenes import parse_config
    from invsss.scenes.path_tracing import camera_points

    config = parse_config(info["config"])
    medium = Medium(float(info["medium"]["sigma_s_prime"][0]), float(info["medium"]["sigma_a"][0]))
    if float(info["medium"].get("eta", 1.0)) != 1.0:
        raise SystemExit("dipole_probe: index-matched pairs only (eta 1)")
    mask = np.asarray(pair["mask"], np.float64) > 0.5
    points = camera_points(config, np.asarray(pair["depth"], np.float64))
    buffers = pair["buffers"]
    normal = np.asarray(buffers.normal, np.float64)
    lights = [np.asarray(buffers.light, np.float64)]
    key = np.asarray(buffers.key, np.float64)[..., 0]
    parts = [key]
    if buffers.fill_light is not None:
        lights.append(np.asarray(buffers.fill_light, np.float64))
        parts.append(np.asarray(pair["source"], np.float64)[..., 0] - key)
    area = pixel_area(config, points, normal)
    offsets = [(a, b) for a in (np.arange(SUBSAMPLES) + 0.5) / SUBSAMPLES - 0.5
               for b in (np.arange(SUBSAMPLES) + 0.5) / SUBSAMPLES - 0.5]
    fine = [footprint_points(config, points, normal, a, b) for a, b in offsets]
    out = {"standard": [np.zeros_like(key) for _ in parts], "directional": [np.zeros_like(key) for _ in parts]}
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            if dy * dy + dx * dx > radius * radius:
                continue
            on = shifted(mask.astype(np.float64), dy, dx) * mask
            if not on.any():
                continue
            n_i = shifted(normal, dy, dx)
            weight = shifted(area, dy, dx)
            near = max(abs(dy), abs(dx)) <= NEAR
            sources = [shifted(p, dy, dx) for p in fine] if near else [shifted(points, dy, dx)]
            share = weight / len(sources)
            for k, (light, part) in enumerate(zip(lights, parts)):
                into = -shifted(light, dy, dx)  # the refracted ray, eta = 1
                flux = shifted(part, dy, dx) * share * on
                for x_i in sources:
                    r = np.linalg.norm(points - x_i, axis=-1)
                    out["standard"][k] += medium.standard(r) * flux
                    out["directional"][k] += medium.directional(x_i, n_i, into, points, normal) * flux
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--radius", type=int, default=12, help="the sum's radius in pixels (default 12)")
    parser.add_argument("pairs", nargs="+", type=pathlib.Path)
    args = parser.parse_args()
    for folder in args.pairs:
        pair = load_scene_pair(folder)
        keep = eroded(pair["mask"], 2) > 0
        target = np.asarray(pair["target"], np.float64)[..., 0]
        found = predictions(pair, args.radius)
        scores = {}
        for terms in (None, "shift,law,fill"):
            fit = invsss.fit_pair(pair["source"], pair["target"], pair["depth"], pair["mask"],
                                  light_terms=terms, light_buffers=pair["buffers"] if terms else None)
            prediction = np.asarray(fit.fitted[0], np.float64).reshape(np.shape(pair["target"]))[..., 0]
            scores["plain fit" if terms is None else f"fit + {terms}"] = mixed_psnr(target, keep, [prediction])
        best = prediction
        for name, images in found.items():
            scores[f"{name} dipole"] = mixed_psnr(target, keep, images)
            scores[f"fit + {name} dipole mixed in"] = mixed_psnr(target, keep, [best, *images])
        ceiling = pair["info"]["noise"]["noise_ceiling_db"]
        print(f"{folder.name} (noise ceiling {ceiling:.2f} dB, radius {args.radius} px): "
              + " | ".join(f"{name} {value:.2f}" for name, value in scores.items()), flush=True)


if __name__ == "__main__":
    main()
