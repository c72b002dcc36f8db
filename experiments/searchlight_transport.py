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

    python experiments/searchlight_transport.py [--photons 400000] [--check]

``--check`` prints the camera reading against the exitance for the thesis's medium.
About 15 minutes on two cores for the whole table (run it with nice).
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
#: The tables: a focused spot with and without a boundary (skin, and the index-matched
#: check), and a Lambertian source on skin (the path-traced slabs' contact light).
TABLES = (("searchlight", 1.0), ("searchlight", 1.3), ("diffuse", 1.3))


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
        "Do not edit: rerun the script. ``LOG_READING[(incidence, eta)][i][j]`` is",
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
            block = _numbers(row, 4, "        ")
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
    for incidence, eta in TABLES:
        t0 = time.perf_counter()
        rows = [smooth_log(*simulate(1.0 - m, eta, incidence, args.photons, seed=k)[1:])
                for k, m in enumerate(ONE_MINUS_ALPHA)]
        tables[(incidence, eta)] = rows
        print(f"{incidence} eta {eta}: {time.perf_counter() - t0:.0f} s", flush=True)
    _write(args.out, tables)


if __name__ == "__main__":
    main()
