"""Monte Carlo of what a camera on the spot's axis reads around a spot on a thick medium (issue 50).

Writes ``invsss/measurement/transport_table.py``: the tables behind the
``"transport"`` profile model (``invsss.measurement.transport_profile``).

Why: every published profile model (Jensen's dipole, d'Eon's better dipole, photon
beam diffusion, Christensen & Burley's normalized diffusion) gives the *exitance*
``R(r)``, the power leaving the surface per unit area in every direction. A camera
looking down on the spot reads the *radiance* leaving along the normal, and the
measurement turns it into ``pi L(r)`` (the exitance only if the surface were
Lambertian). It is not: near the spot the light leaves obliquely (low-order
scattering from the beam), far away the diffusion regime's radiance peaks along the
normal. For the thesis's 940 nm medium without a boundary, ``pi L / R`` is 0.76 at
1.3 mm, 0.92 at 3.3 mm and 1.01 at 6.2 mm (``--check``; Mitsuba's render of the same
slab agrees within its noise), so a fit of any exitance model misreads the medium.

The transport: a semi-infinite medium, isotropic scattering, extinction 1 (lengths in
mean free paths), single-scattering albedo ``alpha``, a smooth boundary of relative
index ``eta`` (Fresnel reflection and refraction both ways, total internal
reflection), lit at one point either by a pencil beam along the normal
(``searchlight``) or by light from every direction of the hemisphere, cosine
weighted (``diffuse``: a Lambertian source on the surface). The camera's reading at
distance ``r`` is estimated at every collision (next-event estimation along the
vertical: ``w alpha e^{-z} / (4 pi)`` times the normal's Fresnel transmission over
``eta^2``), so it is smooth even where few photons leave. A medium of extinction
``sigma_t`` and the same albedo reads ``sigma_t^2 T(sigma_t r)``.

    python experiments/searchlight_transport.py [--photons 400000] [--only diffuse:1.3:0.5] [--check]

``--check`` prints the camera reading against the exitance for the thesis's medium.
At 400k photons per albedo, 4 to 9 minutes a table on two shared cores (run it with nice):
searchlight eta 1.0 450 s, eta 1.3 540 s, diffuse 390 s, diffuse through the rough boundary 257 s.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

#: Albedos of the table: 1 - alpha geometric from 0.6 to 0.0015.
ONE_MINUS_ALPHA = np.geomspace(0.6, 0.003, 20)
#: Bin edges in mean free paths: fine near the spot, log-spaced beyond.
EDGES = np.geomspace(0.2, 60.0, 73)
#: The tables, (incidence, eta, Beckmann roughness; 0 smooth): a focused spot with and
#: without a boundary (skin, and the index-matched check), and a Lambertian source on skin
#: (the path-traced slabs' contact light) through a smooth and a rough (0.5, the scenes'
#: default) boundary.
TABLES = (("searchlight", 1.0, 0.0), ("searchlight", 1.3, 0.0), ("diffuse", 1.3, 0.0), ("diffuse", 1.3, 0.5))


def fresnel(cos_i, eta):
    """Unpolarised reflectance at the boundary for light inside a medium of relative index eta."""
    sin2_t = eta**2 * (1.0 - cos_i**2)
    cos_t = np.sqrt(np.clip(1.0 - sin2_t, 0.0, None))
    rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    return np.where(sin2_t >= 1.0, 1.0, 0.5 * (rs**2 + rp**2))


def _entry(n, eta, incidence, rng):
    """Weights and downward direction cosines of the light that entered."""
    if incidence == "searchlight":
        mu = np.ones(n)
        weight = np.full(n, 1.0 - ((eta - 1.0) / (eta + 1.0)) ** 2)
    else:
        # Cosine-weighted outside; Snell inside; Fresnel of the outside side is the
        # inside one's at the refracted angle (reciprocity of the unpolarised Fresnel).
        mu_out = np.sqrt(rng.random(n))
        mu = np.sqrt(1.0 - (1.0 - mu_out**2) / eta**2)
        weight = 1.0 - fresnel(mu, eta)
    return weight, mu


def simulate(alpha, eta, incidence, photons, seed=0, batches=8):
    """``(exitance, camera, camera_stderr)`` per unit incident power and area on EDGES' bins (mfp^-2).

    The standard error is that of the mean of ``batches`` independent batches.
    """
    rng = np.random.default_rng(seed)
    exitance = np.zeros(EDGES.size - 1)
    cameras = []
    t0 = 1.0 - ((eta - 1.0) / (eta + 1.0)) ** 2
    for _ in range(batches):
        n = photons // batches
        camera = np.zeros(EDGES.size - 1)
        cameras.append(camera)
        w, uz = _entry(n, eta, incidence, rng)
        phi = 2 * np.pi * rng.random(n)
        s = np.sqrt(1.0 - uz**2)
        ux, uy = s * np.cos(phi), s * np.sin(phi)
        x, y, z = np.zeros(n), np.zeros(n), np.zeros(n)
        while n:
            t = -np.log(rng.random(n))
            z_new = z + uz * t
            out = z_new < 0.0
            # Reaching the boundary: the transmitted part leaves, the rest reflects.
            tt = np.where(out, -z / np.where(out, uz, -1.0), t)
            x, y = x + ux * tt, y + uy * tt
            z = np.where(out, 0.0, z_new)
            f = np.where(out, fresnel(np.abs(uz), eta), 1.0)
            r = np.hypot(x, y)
            exitance += np.histogram(r[out], EDGES, weights=(w * (1.0 - f))[out])[0]
            uz = np.where(out, -uz, uz)
            w = w * f
            # Collisions: the camera's reading, then scattering.
            hit = ~out
            contribution = w[hit] * alpha * np.exp(-z[hit]) * t0 / (4.0 * np.pi * eta**2)
            camera += np.histogram(r[hit], EDGES, weights=contribution)[0]
            w = np.where(hit, w * alpha, w)
            c = 2.0 * rng.random(n) - 1.0
            p = 2.0 * np.pi * rng.random(n)
            s = np.sqrt(1.0 - c * c)
            ux = np.where(hit, s * np.cos(p), ux)
            uy = np.where(hit, s * np.sin(p), uy)
            uz = np.where(hit, c, uz)
            # Russian roulette below 1e-3 of the entering weight.
            low = w < 1e-3
            survive = rng.random(n) < 0.2
            w = np.where(low, np.where(survive, w * 5.0, 0.0), w)
            keep = w > 0.0
            x, y, z, ux, uy, uz, w = (a[keep] for a in (x, y, z, ux, uy, uz, w))
            n = int(keep.sum())
    area = np.pi * (EDGES[1:] ** 2 - EDGES[:-1] ** 2) * (photons // batches)
    cameras = np.pi * np.array(cameras) / area
    return (exitance / area / batches, cameras.mean(axis=0),
            cameras.std(axis=0, ddof=1) / np.sqrt(batches))


# --------------------------------------------------------------------------- a rough boundary
# Walter, Marschner, Li & Torrance 2007, "Microfacet Models for Refraction through Rough
# Surfaces": Beckmann normals sampled in proportion to D(m) cos(theta_m), Smith's shadowing
# (its exact Beckmann form, as Mitsuba's roughdielectric), the Fresnel term at the
# microfacet. Directions are (x, y, z) with z the depth (into the medium).


def _beckmann_normals(n, roughness, rng, sign):
    tan2 = -roughness**2 * np.log1p(-rng.random(n))
    cos_t = 1.0 / np.sqrt(1.0 + tan2)
    sin_t = np.sqrt(1.0 - cos_t**2)
    phi = 2.0 * np.pi * rng.random(n)
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), sign * cos_t], axis=-1)


def _smith_g1(cos_v, roughness):
    from scipy.special import erf

    cos_v = np.clip(np.abs(cos_v), 1e-9, 1.0)
    tan = np.sqrt(1.0 - cos_v**2) / cos_v
    a = 1.0 / np.maximum(roughness * tan, 1e-12)
    lam = np.where(a < 1e6, 0.5 * (erf(a) - 1.0) + np.exp(-a * a) / (2.0 * a * np.sqrt(np.pi)), 0.0)
    return 1.0 / (1.0 + lam)


def _beckmann_d(cos_m, roughness):
    c2 = cos_m**2
    return np.exp(-(1.0 - c2) / (c2 * roughness**2)) / (np.pi * roughness**2 * c2**2)


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def _cross_in(d, eta, roughness, rng):
    """Light arriving from outside along ``d`` (z > 0): ``(weight factor, direction inside)``."""
    i = -d
    m = _beckmann_normals(d.shape[0], roughness, rng, -1.0)
    c = _dot(i, m)
    eta_r = 1.0 / eta
    f = fresnel(np.clip(c, 0.0, 1.0), eta_r)
    root = np.sqrt(np.clip(1.0 + eta_r**2 * (c**2 - 1.0), 0.0, None))
    t = (eta_r * c - root)[:, None] * m - eta_r * i
    ok = (c > 0) & (t[:, 2] > 0)
    g = _smith_g1(i[:, 2], roughness) * _smith_g1(t[:, 2], roughness)
    weight = np.where(ok, (1.0 - f) * c * g / (np.abs(i[:, 2]) * np.abs(m[:, 2])), 0.0)
    return weight, t


def _camera_rough(pos, w, alpha, eta, roughness, rng):
    """Each collision's share of the camera's reading through a rough boundary: ``(r, value)``.

    A microfacet normal ``h`` is drawn from ``D(h) cos``, the inside direction ``i`` that
    refracts through it straight up to the camera follows, and the ray from the collision
    back along ``i`` meets the surface at distance ``r`` from the spot. Divided by the
    density of ``i``, Walter's BTDF leaves ``(1 - F(i.h)) G1(i) / (eta^2 i_z)``; the ray's
    transmittance is ``exp(-z / i_z)`` (smooth limit: the vertical estimate of :func:`simulate`).
    """
    h = _beckmann_normals(pos.shape[0], roughness, rng, 1.0)
    s = h[:, 2] - np.sqrt(h[:, 2] ** 2 + eta**2 - 1.0)
    i = (np.array([0.0, 0.0, 1.0]) - s[:, None] * h) / eta
    ih = _dot(i, h)
    ok = (i[:, 2] > 1e-6) & (ih > 0)
    iz = np.where(ok, i[:, 2], 1.0)
    length = pos[:, 2] / iz
    x = pos[:, 0] - length * i[:, 0]
    y = pos[:, 1] - length * i[:, 1]
    value = (w * alpha / (4.0 * np.pi) * np.exp(-length) * (1.0 - fresnel(np.clip(ih, 0.0, 1.0), eta))
             * _smith_g1(iz, roughness) / (eta**2 * iz))
    return np.hypot(x, y), np.where(ok, value, 0.0)


def simulate_rough(alpha, eta, incidence, photons, roughness, seed=0, batches=8):
    """As :func:`simulate` (no exitance) with a rough (Beckmann) boundary (:func:`_camera_rough`)."""
    rng = np.random.default_rng(seed)
    cameras = []
    for _ in range(batches):
        n = photons // batches
        camera = np.zeros(EDGES.size - 1)
        cameras.append(camera)
        if incidence == "searchlight":
            d = np.tile([0.0, 0.0, 1.0], (n, 1))
        else:
            mu = np.sqrt(rng.random(n))
            phi = 2 * np.pi * rng.random(n)
            s = np.sqrt(1.0 - mu**2)
            d = np.stack([s * np.cos(phi), s * np.sin(phi), mu], axis=-1)
        w, d = _cross_in(d, eta, roughness, rng)
        pos = np.zeros((n, 3))
        while n:
            t = -np.log(rng.random(n))
            z_new = pos[:, 2] + d[:, 2] * t
            out = z_new < 0.0
            tt = np.where(out, -pos[:, 2] / np.where(out, d[:, 2], -1.0), t)
            pos = pos + d * tt[:, None]
            pos[out, 2] = 0.0
            # At the boundary: reflection (or leaving).
            i = -d[out]
            m = _beckmann_normals(i.shape[0], roughness, rng, 1.0)
            c = _dot(i, m)
            f = fresnel(np.clip(c, 0.0, 1.0), eta)
            o = 2.0 * c[:, None] * m - i
            reflect = (rng.random(i.shape[0]) < f) & (c > 0) & (o[:, 2] > 0)
            g = _smith_g1(i[:, 2], roughness) * _smith_g1(o[:, 2], roughness)
            w_out = np.where(reflect, w[out] * c * g / (np.abs(i[:, 2]) * np.abs(m[:, 2])), 0.0)
            d[out] = o
            w[out] = w_out
            # Collisions: the camera's reading, then scattering.
            hit = ~out
            r, value = _camera_rough(pos[hit], w[hit], alpha, eta, roughness, rng)
            camera += np.histogram(r, EDGES, weights=value)[0]
            w = np.where(hit, w * alpha, w)
            cz = 2.0 * rng.random(n) - 1.0
            p = 2.0 * np.pi * rng.random(n)
            s = np.sqrt(1.0 - cz * cz)
            d[hit] = np.stack([s * np.cos(p), s * np.sin(p), cz], axis=-1)[hit]
            low = w < 1e-3
            survive = rng.random(n) < 0.2
            w = np.where(low, np.where(survive, w * 5.0, 0.0), w)
            keep = w > 0.0
            pos, d, w = pos[keep], d[keep], w[keep]
            n = int(keep.sum())
    area = np.pi * (EDGES[1:] ** 2 - EDGES[:-1] ** 2) * (photons // batches)
    cameras = np.pi * np.array(cameras) / area
    return None, cameras.mean(axis=0), cameras.std(axis=0, ddof=1) / np.sqrt(batches)


def smooth_log(values, stderr, half_width=2.5):
    """Local weighted quadratic regression of ``log values`` over ``log rho``, bin by bin.

    Weights: the inverse variance of ``log values`` (``(stderr / values)^2``) times a
    Gaussian of the bin distance (``half_width`` bins a standard deviation); empty
    bins weigh nothing, so beyond the last photon the curve is extrapolated from the
    nearest reliable window.
    """
    x = np.log(np.sqrt(EDGES[1:] * EDGES[:-1]))
    ok = (values > 0) & (stderr > 0)
    y = np.log(np.where(ok, values, 1.0))
    w = np.where(ok, (values / np.where(ok, stderr, 1.0)) ** 2, 0.0)
    out = np.empty_like(x)
    for j in range(x.size):
        k = w * np.exp(-0.5 * ((np.arange(x.size) - j) / half_width) ** 2)
        if np.count_nonzero(k > 1e-12 * k.max()) < 4:
            k = w  # far beyond the photons: the whole reliable range
        basis = np.stack([np.ones_like(x), x - x[j], (x - x[j]) ** 2], axis=1)
        coef = np.linalg.lstsq(basis * np.sqrt(k)[:, None], y * np.sqrt(k), rcond=None)[0]
        out[j] = coef[0]
    return out


def _numbers(values, digits, indent):
    """``values`` as Python list lines of at most 100 characters."""
    items = [f"{round(float(v), digits)!r}" for v in values]
    lines, line = [], indent + "["
    for item in items:
        if len(line) + len(item) + 2 > 100:
            lines.append(line.rstrip())
            line = indent + " "
        line += item + ", "
    return lines + [line.rstrip(", ") + "]"]


def _write(path, tables):
    lines = [
        '"""Monte Carlo tables of the camera reading around a spot (made by experiments/searchlight_transport.py).',
        "",
        "Do not edit: rerun the script. ``LOG_READING[(incidence, eta, roughness)][i][j]`` is",
        "``log(pi L / sigma_t^2)`` at ``RHO[j]`` mean free paths for ``1 - alpha = ONE_MINUS_ALPHA[i]``.",
        '"""',
        "",
        "RHO = (",
        *_numbers(np.sqrt(EDGES[1:] * EDGES[:-1]), 6, "    "),
        ")",
        "ONE_MINUS_ALPHA = (",
        *_numbers(ONE_MINUS_ALPHA, 8, "    "),
        ")",
        "LOG_READING = {",
    ]
    for key, table in tables.items():
        lines.append(f"    {key!r}: [")
        for row in table:
            block = _numbers(row, 3, "        ")
            block[-1] += ","
            lines += block
        lines.append("    ],")
    lines.append("}")
    with open(path, "w") as handle:
        handle.write("\n".join(lines) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--photons", type=int, default=400_000)
    parser.add_argument("--check", action="store_true")
    parser.add_argument("--only", default=None, metavar="INCIDENCE:ETA:ROUGHNESS",
                        help="make one table, e.g. diffuse:1.3:0.5 (its module holds only it)")
    parser.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "..", "invsss",
                                                      "measurement", "transport_table.py"))
    args = parser.parse_args()
    if args.check:
        s, a = 0.7748, 0.02808
        ex, cam, err = simulate(s / (s + a), 1.0, "searchlight", args.photons)
        smooth = np.exp(smooth_log(cam, err))
        rho = np.sqrt(EDGES[1:] * EDGES[:-1])
        for j in range(0, rho.size, 4):
            print(f"r {rho[j] / (s + a):6.2f} mm  exitance {ex[j] * (s + a) ** 2:.5f}  "
                  f"pi L {cam[j] * (s + a) ** 2:.5f} +- {err[j] / cam[j]:.1%}  smoothed "
                  f"{smooth[j] / cam[j]:.3f}  pi L / exitance {cam[j] / ex[j]:.3f}")
        return
    tables = {}
    for incidence, eta, roughness in TABLES:
        if args.only and args.only != f"{incidence}:{eta}:{roughness}":
            continue
        t0 = time.perf_counter()
        if roughness:
            rows = [smooth_log(*simulate_rough(1.0 - m, eta, incidence, args.photons, roughness, seed=k)[1:])
                    for k, m in enumerate(ONE_MINUS_ALPHA)]
        else:
            rows = [smooth_log(*simulate(1.0 - m, eta, incidence, args.photons, seed=k)[1:])
                    for k, m in enumerate(ONE_MINUS_ALPHA)]
        tables[(incidence, eta, roughness)] = rows
        print(f"{incidence} eta {eta} roughness {roughness}: {time.perf_counter() - t0:.0f} s", flush=True)
    _write(args.out, tables)


if __name__ == "__main__":
    main()
