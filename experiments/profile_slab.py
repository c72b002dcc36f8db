"""Path-traced check of the measurement pipeline (issues 7 and 50): the medium back from a slab.

A flat slab of a known medium is lit at a small spot and rendered with Mitsuba 3
(volpath); a white Lambertian slab (albedo 1, the Spectralon stand-in) is rendered
under a 0.3 mm spot light and the same camera. Both go through ``invsss profile``'s
steps (measure_profile with the spot's area from the reference's power,
trusted_radii, fit_medium with the samples' standard errors) for each model, and
the fitted sigma_s' and sigma_a are printed against the medium's.

    python experiments/profile_slab.py [--medium thesis-940 | --coefficients S,A]
        [--boundary rough-dielectric|index-matched] [--roughness 0.5] [--spp 256]
        [--out DIR] [--from DIR] [--reference FILE] [--models transport,burley,...]

The light: with ``--boundary index-matched`` the spot light itself (a searchlight:
model ``transport``, eta 1). Through a dielectric, volpath cannot reach a spot light
from inside the slab, so the slab is lit by a square Lambertian emitter of the spot's
area and power just above it (a diffuse source: ``transport-diffuse``, or
``transport-diffuse-rough`` for the default Beckmann 0.5 boundary); its back is black
(Mitsuba's default grey BSDF would return half the light leaving beneath it).

The reference sets the profile's level (its power over its lit level is the spot's
area), and the fitted albedo hangs on that level: at 16 spp the partly lit pixels of a
0.3 mm spot at 0.2 mm per pixel moved the area by 9 % between seeds and sigma_a by
27 %. Render it once at 4096 spp (``--reference-spp``) and pass it to every run of the
same frame (``--reference``). Too slow for CI on two cores (minutes a render); the CI
tests are tests/measurement/test_path_traced_slab.py (one small render shipped) and
tests/measurement/test_profile_pipeline.py (a dipole-made image). The measured
table is in docs/capture.md, "The spot measurement".
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np

from invsss.io import read_image, write_image
from invsss.measurement.measure import measure_profile
from invsss.measurement.medium_fit import MODEL_NAMES, fit_medium
from invsss.measurement.trusted_radii import trusted_radii
from invsss.scenes import parse_config
from invsss.scenes.config import Medium

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
    from invsss.scenes.mitsuba_scene import scene_dict

    content = scene_dict(mi, config, kind, coefficients=config.medium.coefficients(), **extra)
    for key, value in content.items():
        if key.startswith("light_") and value.get("type") == "rectangle":
            # Mitsuba's default BSDF of a shape is a grey diffuse (0.5): the contact light's
            # back would send half the light leaving beneath it back into the slab, a
            # second source the profile models know nothing of. Black, it absorbs.
            value["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
    scene = mi.load_dict(content)
    return np.asarray(mi.render(scene, spp=spp, seed=seed), np.float64)  # (H, W, 3)


def render_pair(args, medium):
    """``(skin, reference)``, (H, W, 3) each: the scattering slab and the white slab."""
    from invsss.scenes.mitsuba_scene import import_mitsuba

    matched = args.boundary == "index-matched"
    shape = (medium, args.width, args.height, args.pitch, args.spp, args.seed)
    config = slab_config(*shape, light="spot" if matched else "contact")
    mi = import_mitsuba(config.variant)
    t0 = time.perf_counter()
    skin = render(mi, config, "target", args.spp, args.seed)
    if not matched:  # an index-matched boundary reflects nothing
        skin = skin - render(mi, config, "specular", args.spp, args.seed)
    # The reference's level over its lit pixels gives the spot's area, and so the profile's
    # level: at 16 spp the partly lit edge pixels of a 0.3 mm spot moved it by 9 % between
    # seeds (and sigma_a by 27 %); 1024 spp keeps it within 1 %.
    reference = render(mi, slab_config(*shape, light="spot"), "source", args.reference_spp, args.seed + 1,
                       albedo=1.0)
    print(f"rendered {args.width}x{args.height} px at {args.pitch} mm, {args.spp} spp in "
          f"{time.perf_counter() - t0:.0f} s")
    return skin, reference


def measure_channel(skin, reference, args):
    """The measured profile of one channel, normalised by the spot's effective area."""
    options = dict(filter_factor=1.0, saturation=None, lit_radius_mm=args.lit_radius_mm,
                   max_radius_mm=0.5 * args.width * args.pitch + 15 * args.pitch - 1.0)
    first = measure_profile(skin, reference, None, args.pitch, **options)
    # The reference's lit pixels at >= half its peak miss the partly lit edge pixels:
    # its whole reflected power over the mean level is the spot's effective area.
    spot_area = float(reference.sum()) * args.pitch**2 / float(first.spectralon_level)
    return measure_profile(skin, reference, None, args.pitch, spot_area_mm2=spot_area, **options)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--medium", default="thesis-940", help="medium preset (default thesis-940)")
    parser.add_argument("--coefficients", default=None, metavar="S,A",
                        help="sigma_s' and sigma_a (1/mm) instead of the preset, eta 1.3")
    parser.add_argument("--channels", default="0", help="channels to measure, e.g. 0,1 (jensen-skin1: "
                        "red, green)")
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--width", type=int, default=110)
    parser.add_argument("--height", type=int, default=50)
    parser.add_argument("--pitch", type=float, default=0.1, help="mm per pixel on the slab")
    parser.add_argument("--lit-radius-mm", type=float, default=1.5)
    parser.add_argument("--boundary", default="rough-dielectric",
                        choices=["rough-dielectric", "index-matched"],
                        help="index-matched: no dielectric, so the spot light itself lights "
                        "the skin (next-event estimation reaches it from inside the beam)")
    parser.add_argument("--roughness", type=float, default=0.5, help="Beckmann alpha of the dielectric")
    parser.add_argument("--models", default=",".join(MODEL_NAMES), help="models to fit, comma-separated")
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--reference", default=None,
                        help="reference.exr to use instead of the run's (same frame and spot)")
    parser.add_argument("--out", default=None, help="folder to write skin.exr and reference.exr to")
    parser.add_argument("--from", dest="source", default=None,
                        help="folder with skin.exr and reference.exr of an earlier run: no render")
    args = parser.parse_args()

    matched = args.boundary == "index-matched"
    if args.coefficients:
        s, a = (float(v) for v in args.coefficients.split(","))
        medium = {"sigma_s_prime": s, "sigma_a": a, **({} if matched else {"eta": 1.3})}
        args.medium = f"{s:g},{a:g}"
    else:
        medium = {"preset": args.medium}
    medium.update({"boundary": "index-matched"} if matched else {"roughness": args.roughness})
    truth = Medium(**medium).coefficients()
    if args.source:
        skin, reference = (np.asarray(read_image(os.path.join(args.source, f"{name}.exr")), np.float64)
                           for name in ("skin", "reference"))
    else:
        skin, reference = render_pair(args, medium)
    if args.reference:
        reference = np.asarray(read_image(args.reference), np.float64)
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        write_image(os.path.join(args.out, "skin.exr"), skin.astype(np.float32))
        write_image(os.path.join(args.out, "reference.exr"), reference.astype(np.float32))
    eta = float(truth["eta"])
    print(f"{'medium':12}{'ch':>3} {'model':18}{'sigma_s_prime':>22}{'err':>8}{'sigma_a':>24}{'err':>8}"
          f"{'chi2':>7}  radii")
    for c in (int(k) for k in args.channels.split(",")):
        measured = measure_channel(skin[..., c], reference[..., c], args)
        trusted = trusted_radii(measured, args.pitch)
        m = trusted.mask
        s_true, a_true = (float(np.ravel(truth[k])[c % np.size(truth[k])]) for k in ("sigma_s_prime", "sigma_a"))
        for name in args.models.split(","):
            fit = fit_medium(measured.r_mm[m], measured.reflectance[m], model=name, eta=eta,
                             stderr=measured.reflectance_stderr[m])
            s, a = float(fit.sigma_s_prime), float(fit.sigma_a)
            print(f"{args.medium:12}{c:3d} {name:18}{s:10.4f} +- {float(fit.sigma_s_prime_stderr):.4f} "
                  f"({s_true:.4f}){s / s_true - 1:+8.1%}{a:10.4f} +- {float(fit.sigma_a_stderr):.4f} "
                  f"({a_true:.4f}){a / a_true - 1:+8.1%}{float(fit.reduced_chi2):7.2f}  "
                  f"{float(trusted.r_min_mm):.2f}-{float(trusted.r_max_mm):.2f} mm")


if __name__ == "__main__":
    main()
