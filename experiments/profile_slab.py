"""Path-traced check of the measurement pipeline (issue 7, item 5).

A flat slab of a known medium is lit by a narrow spot light and rendered with
Mitsuba 3 (volpath, rough-dielectric boundary, the specular reflection rendered
separately and subtracted, as ``invsss scene`` does); a white Lambertian slab
(albedo 1, the Spectralon stand-in) is rendered under the same light and camera.
Both go through ``invsss profile``'s steps (measure_profile, sum of Gaussians,
fit_dipole) and the fitted sigma_s' and sigma_a are compared with the medium's.

    python experiments/profile_slab.py [--spp 256] [--medium thesis-940] [--out DIR]

Too slow for CI on two cores (minutes); the CI test of the same pipeline on a
dipole-made image is tests/measurement/test_profile_pipeline.py.

Measured (Mitsuba 3.9.1 scalar_rgb, 2 CPU cores, thesis-940: sigma_s' 0.7748,
sigma_a 0.02808 /mm), the check does NOT pass its 10 % target yet:

    --spp 4096  --width 50 --height 26 --pitch 0.2   112 s   sigma_s' 0.416 (-46 %)  sigma_a 0.0501 (+79 %)
    --spp 16384 --width 44 --height 16 --pitch 0.2   127 s   sigma_s' 0.428 (-45 %)  sigma_a 0.0539 (+92 %)

    --boundary index-matched --spp 8192 (same frame)  46 s   sigma_s' 0.444 (-43 %)  sigma_a 0.0670 (+139 %)

Two causes, seen by dividing the radial samples by the dipole of the true medium
(normalised by the light's analytic power instead of the reference): the path
tracer's profile lies 25-30 % below ``jensen_dipole`` at every r from 1 to 6 mm
(a level difference, not a shape one), and the per-bin noise is still about
15 % at 16384 spp (light enters only under the 0.3 mm spot, which camera paths
reach rarely). The dipole fit reads a level change as a lower albedo, so it
trades sigma_s' for sigma_a. Not yet separated: the rough (Beckmann 0.5)
boundary's transmission, the emitter's diffuse incidence (more Fresnel loss than
a collimated spot) and the dipole's own error at 1-6 mm. The index-matched run
(no boundary at all, lit by the spot light itself, noise about 5 % per bin) still
lies at 0.63-0.66 of the dipole (eta 1) from 1 to 3.5 mm, rising to 0.78-0.86 at
5-6 mm: most of the gap is between the dipole and the exact transport, not in
the boundary or the light. The totals agree (index-matched slab albedo from
invsss.scenes.calibration.slab_albedo 0.591 +- 0.002, jensen_dipole_total 0.575),
so the path tracer keeps more of the energy within 1 mm (single and low-order
scattering, which the dipole leaves out) and less at 1-6 mm. So a dipole fit of a path-traced profile cannot give
the medium back within 10 %; a profile fitted directly (sum of Gaussians) can
still be used as `invsss fit --profile`.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

import numpy as np

from invsss.measurement.dipole_fit import fit_dipole
from invsss.io import write_image
from invsss.measurement.measure import measure_profile
from invsss.scenes import parse_config
from invsss.scenes.mitsuba_scene import import_mitsuba, scene_dict

CAMERA_Z = 300.0  # mm, camera on the slab's axis
LIGHT_Z = 150.0  # mm, the reference's spot light on the same axis
SPOT_RADIUS = 0.3  # mm on the slab
INTENSITY = 1e6  # W/sr of the spot light
#: The skin's light: a square emitter this far above the surface (mm), facing it.
CONTACT_HEIGHT = 0.01


def slab_config(medium: dict, width: int, height: int, pitch: float, spp: int, seed: int,
                light: str):
    """Slab whose front face is z = 0, camera looking down -z, light a quarter in.

    ``light="spot"``: a narrow spot light of radius SPOT_RADIUS on the slab, for the
    white reference. ``light="contact"``: a square area light of the same area and
    power almost touching the surface, for the scattering slab. Volpath connects
    to a light by next-event estimation from inside the medium, and a spot light
    is only reachable from points inside its narrow cone: rendered with the spot,
    the light scattered sideways never finds the light (the target is black
    beyond the spot). The contact emitter is reachable from every point.
    """
    fov = math.degrees(2.0 * math.atan(0.5 * width * pitch / CAMERA_Z))
    spot_x = -0.5 * width * pitch + 15 * pitch
    cutoff = math.degrees(math.atan(SPOT_RADIUS / LIGHT_Z))
    if light == "spot":
        lights = [{"type": "spot", "position": [spot_x, 0.0, LIGHT_Z], "look_at": [spot_x, 0.0, 0.0],
                   "intensity": INTENSITY, "cutoff": cutoff, "beam_width": 0.999 * cutoff}]
    else:
        side = math.sqrt(math.pi) * SPOT_RADIUS  # the spot's area
        power = INTENSITY * 2.0 * math.pi * (1.0 - math.cos(math.radians(cutoff)))
        # A one-sided Lambertian emitter of radiance L emits pi L per unit area.
        lights = [{"type": "area", "center": [spot_x, 0.0, CONTACT_HEIGHT],
                   "look_at": [spot_x, 0.0, 0.0], "width": side, "height": side,
                   "radiance": power / (math.pi * side**2)}]
    return parse_config({
        "object": {"primitive": "slab", "size": [200.0, 200.0, 60.0]},
        "camera": {"position": [0.0, 0.0, CAMERA_Z], "look_at": [0.0, 0.0, 0.0],
                   "fov": fov, "width": width, "height": height},
        "lights": lights, "medium": medium, "spp": spp, "seed": seed,
    }, "profile_slab")


def render(mi, config, kind, spp, seed, **extra):
    scene = mi.load_dict(scene_dict(mi, config, kind, coefficients=config.medium.coefficients(), **extra))
    return np.asarray(mi.render(scene, spp=spp, seed=seed), np.float64)[..., 0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--medium", default="thesis-940", help="medium preset (default thesis-940)")
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--width", type=int, default=110)
    parser.add_argument("--height", type=int, default=50)
    parser.add_argument("--pitch", type=float, default=0.1, help="mm per pixel on the slab")
    parser.add_argument("--lit-radius-mm", type=float, default=1.5)
    parser.add_argument("--boundary", default="rough-dielectric",
                        choices=["rough-dielectric", "index-matched"],
                        help="index-matched: no dielectric, so the spot light itself lights "
                        "the skin (next-event estimation reaches it from inside the beam)")
    parser.add_argument("--out", default=None, help="folder for skin.exr, reference.exr, profile.json")
    args = parser.parse_args()

    matched = args.boundary == "index-matched"
    medium = {"preset": args.medium, **({"boundary": "index-matched"} if matched else {})}
    shape = (medium, args.width, args.height, args.pitch, args.spp, 1)
    config = slab_config(*shape, light="spot" if matched else "contact")
    truth = config.medium.coefficients()
    mi = import_mitsuba(config.variant)
    t0 = time.perf_counter()
    skin = render(mi, config, "target", args.spp, 1)
    if not matched:  # an index-matched boundary reflects nothing
        skin = skin - render(mi, config, "specular", args.spp, 1)
    reference = render(mi, slab_config(*shape, light="spot"), "source", 16, 2, albedo=1.0)
    seconds = time.perf_counter() - t0

    options = dict(filter_factor=1.0, saturation=None, lit_radius_mm=args.lit_radius_mm,
                   max_radius_mm=0.5 * args.width * args.pitch + 15 * args.pitch - 1.0)
    first = measure_profile(skin, reference, None, args.pitch, **options)
    # The reference's lit pixels at >= half its peak miss the partly lit edge pixels:
    # its whole reflected power over the mean level is the spot's effective area.
    spot_area = float(reference.sum()) * args.pitch**2 / float(first.spectralon_level)
    measured = measure_profile(skin, reference, None, args.pitch, spot_area_mm2=spot_area, **options)
    dipole = fit_dipole(measured.r_mm, measured.reflectance, eta=float(truth["eta"]))
    gaussians = measured.fit(3)
    s_true, a_true = (float(np.ravel(truth[k])[0]) for k in ("sigma_s_prime", "sigma_a"))
    s_fit, a_fit = float(dipole.sigma_s_prime), float(dipole.sigma_a)
    print(f"medium {args.medium}: {args.width}x{args.height} px at {args.pitch} mm, {args.spp} spp, "
          f"render {seconds:.0f} s; lit area {first.lit_area_mm2:.3f} mm^2 (effective "
          f"{spot_area:.3f}, true {math.pi * SPOT_RADIUS**2:.3f}), "
          f"samples {measured.r_mm[0]:.2f}-{measured.r_mm[-1]:.2f} mm")
    print(f"{'':14}{'true':>10}{'fitted':>10}{'error':>9}")
    print(f"{'sigma_s_prime':14}{s_true:10.4f}{s_fit:10.4f}{s_fit / s_true - 1:+9.1%}")
    print(f"{'sigma_a':14}{a_true:10.4f}{a_fit:10.4f}{a_fit / a_true - 1:+9.1%}")
    print(f"dipole rms log error {float(dipole.rms_log_error):.3f}; "
          f"3 Gaussians rms {float(gaussians.rms):.3f}")
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        write_image(os.path.join(args.out, "skin.exr"), skin.astype(np.float32))
        write_image(os.path.join(args.out, "reference.exr"), reference.astype(np.float32))
        content = gaussians.to_dict()
        content["fit"]["dipole"] = dipole.to_dict()
        with open(os.path.join(args.out, "profile.json"), "w") as handle:
            json.dump(content, handle, indent=2)


if __name__ == "__main__":
    main()
