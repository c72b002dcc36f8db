"""A visible-light photograph as the source: how far is its fit from the truth? (issue 33)

The bundled two-wavelength pair ``data_synthetic/twowave_face`` is one face, pose and
lights path-traced twice by ``invsss scene``: ``visible/`` with Jensen's skin1 green
channel and the scan's colour map as a pigment layer at full contrast, ``nir/`` with the
thesis's 940 nm medium and the pigment's contrast reduced as melanin's absorption falls
(experiments/scenes/face_twowave_*.toml). Each folder also has its Lambertian source
(albedo map = calibrated albedo times that wavelength's pigment), depth and mask.

Two routes to the near-infrared blur:

``render``
    each wavelength's target fitted against its own Lambertian source (a renderer's
    route, with a face scan): profiles ``P_vis`` and ``P_nir``. The blur that takes
    the visible image to the near-infrared one has, for any kernels, the second moment
    ``sigma_nir^2 - sigma_vis^2`` (variances of independent spreads add: ``P_nir =
    P_vis * P_extra``);
``photo``
    the near-infrared target fitted against the *visible* target as the source (the
    user's route, two photographs): its profile is ``P_extra`` directly.

Each fit is made with the depth map and with ``distance`` (one depth for the face, the
median skin depth rounded to 10 mm; ``correction``, ``maxdd`` held), on the clean renders
and on a simulated one-camera capture (``camera``: shot noise of 2000 electrons at the 99th
percentile and 2 e- read noise, 8-bit sRGB codes exposed so the 99.5th percentile is at
90 % of full scale, clipped pixels left out; ``splitter``: the same with the near-infrared
image moved by (0.4, -0.3) px as a beam splitter's second sensor would, fitted with
``align="translation"``). ``photo, pigment matched`` fits the photo route with the
visible photograph's pigment contrast brought down to the near-infrared one's
(multiplied by ``source_nir / source_vis``, the two albedo maps' ratio): a user cannot
do that, but it isolates the bias that the pigment's fading brings. ``photo, mask made``
uses the skin mask made from the pair (:mod:`invsss.io.skin_mask`) instead of the scene's.

Blur of a fitted profile, in mm on the skin: each Gaussian's variance ``v`` becomes
``v (L / f)^2`` (``L`` the fitted sss_level, ``f`` the camera's focal length in pixels
from scene.json; depth in mm), then ``r50`` is the radius holding half the profile's
energy and ``sigma`` the root of its per-axis second moment ``sum w v / sum w``::

    python experiments/twowave_fit.py [--pair data_synthetic/twowave_face] [--conditions clean,camera,splitter]
        [--starts 4] [--seed 1] [--masks] [--single] [--border PX]

``--masks`` prints the mask maker's IoU against every bundled pair's mask instead.

``--single`` (issue 47) adds, for each condition at the one distance, the photo route as
the command line now fits it by default: one Gaussian (``profile="single"``), with the
pigment field off and at degree 2, and the camera's focal length, so that the fit's own
``blur`` record gives the width in mm with its standard error. Its ``sigma`` is compared
with the render route's ``sigma_extra`` of the table above (the default profile's fits) and
with the ``sigma_extra`` of the render route fitted with one Gaussian too. ``--border PX``
leaves the outer PX pixels of the frame out of every fit's mask (0, the default, leaves the
mask as the scene made it): on a crop that is skin to the frame's edge, the model reads the
source clamped there while the target holds light scattered in from outside the frame.
Neither option changes the table without it. The pair at 0.29 mm a pixel,
``data_synthetic/twowave_fine`` (held out, docs/scenes.md), is fitted with
``--pair data_synthetic/twowave_fine``.

``--transfer`` (issue 47) prints, instead of the fits above, the extra blur each route sees
band by band in spatial frequency, measured from the clean images without a model (the
least-squares transfer: the cross-spectrum over the source's power in each band, Hann
window, jackknife errors over angular sectors), and the same bands for the kernels fitted
with each of ``--transfer-profiles`` (docs/capture.md, "What the two routes agree on").
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

import invsss
from invsss.runtime.determinism import use_deterministic_scheduler
from invsss.io.photo_pair import HELD_WITH_CONSTANT_DEPTH, constant_depth_pair
from invsss.io.skin_mask import skin_mask_from_pair

sys.path.insert(0, str(Path(__file__).resolve().parent))
from photo_robustness import eight_bit_srgb, misregister, shot_noise  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
SPLITTER_SHIFT_PX = (0.4, -0.3)


def effective_level(params, depth, mask) -> float:
    """The median over the skin of ``L d / (d + c min(|dd|, maxdd))`` (both axes): the
    sss_level that gives the same blur without the slope correction."""
    from invsss.forward.stretch import depth_slopes

    d = np.asarray(depth, np.float64)
    skin = np.asarray(mask) > 0.5
    level, c, delta = float(params.sss_level), float(params.correction), float(params.maxdd)
    values = [level * d / (d + c * np.minimum(slope, delta)) for slope in depth_slopes(d)]
    return float(np.median(np.concatenate([v[skin] for v in values])))


def profile_mm(params, focal_px: float, level: float) -> tuple[np.ndarray, np.ndarray]:
    """Normalised weights (K,) and variances in mm^2 on the skin (K,) of a fitted
    one-channel profile: ``v (level / f)^2``, ``level`` the sss_level without correction."""
    w = np.asarray(params.weights, np.float64).reshape(len(params.variances), -1)[:, 0]
    v = np.asarray(params.variances, np.float64) * (level / focal_px) ** 2
    return w / w.sum(), v


def half_energy_radius(weights, variances) -> float:
    """The radius (mm) within which half of a 2D sum of Gaussians' energy lies."""
    def inside(r):
        return float(np.sum(weights * (1.0 - np.exp(-r * r / (2.0 * variances))))) - 0.5

    return brentq(inside, 0.0, 50.0 * np.sqrt(variances.max()))


def rms_width(weights, variances) -> float:
    """The root of the per-axis second moment (mm): variances of convolved kernels add."""
    return float(np.sqrt(np.sum(weights * variances)))


def read_folder(folder: Path) -> dict:
    return {
        "source": invsss.read_image(folder / "source.exr"),
        "target": invsss.read_image(folder / "target.exr"),
        "depth": invsss.read_depth(folder / "depth.exr"),
        "mask": invsss.read_mask(folder / "mask.png"),
        "info": json.loads((folder / "scene.json").read_text()),
    }


def capture(image: np.ndarray, condition: str, rng, shift=None) -> tuple[np.ndarray, float | None]:
    """The photograph of ``image`` under ``condition``, and its clipping level (None: none)."""
    if condition == "clean":
        return image, None
    if shift is not None:
        image = misregister(image, shift=shift)
    return eight_bit_srgb(shot_noise(image, 2000.0, 2.0, rng))


def fit(source, target, depth, mask, distance, *, starts, saturation, align="none"):
    if distance is None:
        pair = invsss.ImagePair(source, target, invsss.forward.pair.fill_background_depth(depth), mask)
        fix = None
    else:
        pair = constant_depth_pair(source, target, distance, mask)
        fix = HELD_WITH_CONSTANT_DEPTH
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = invsss.fit_pairs([pair], fix=fix, n_starts=starts, saturation=saturation, align=align)
    return result, time.perf_counter() - t0, pair


def run(args) -> None:
    folder = Path(args.pair)
    vis, nir = read_folder(folder / "visible"), read_folder(folder / "nir")
    focal = float(vis["info"]["focal_px"])
    mask = vis["mask"]
    skin = mask > 0.5
    distance = float(np.round(np.median(vis["depth"][skin]), -1))
    made_mask = skin_mask_from_pair(vis["target"], nir["target"])
    iou = float((made_mask > 0.5)[skin].sum() / ((made_mask > 0.5) | skin).sum())
    if args.border:
        mask, made_mask = without_border(mask, args.border), without_border(made_mask, args.border)
        print(f"--border {args.border}: the outer {args.border} px of the frame left out of every mask "
              f"({int((mask > 0.5).sum())} of {mask.size} px on the scene's mask)")
    print(f"pair {folder}: focal {focal:.1f} px, median skin depth {np.median(vis['depth'][skin]):.1f} mm "
          f"(--distance {distance:g}), mask made from the pair: IoU {iou:.4f} against the scene's")
    # The visible photograph with the near-infrared pigment contrast (the albedo maps' ratio).
    # The media's own (dipole) profiles as sums of Gaussians: what the widths would be
    # if the screen-space fit recovered them exactly.
    from invsss.forward.profiles import JENSEN_SKIN1_SOG, THESIS_NIR_940

    refs = {}
    for label, table, column in (("skin1 green", JENSEN_SKIN1_SOG, 1), ("thesis-nir", THESIS_NIR_940, None)):
        w = np.asarray(table["weights"], np.float64)
        w = w[:, column] if column is not None else w
        v = np.asarray(table["variances"], np.float64)
        refs[label] = (half_energy_radius(w / w.sum(), v), rms_width(w / w.sum(), v))
    print("published profiles: " + ", ".join(f"{k} r50 {r:.3f} mm, sigma {s:.3f} mm" for k, (r, s) in refs.items())
          + f"; sigma_extra {np.sqrt(refs['thesis-nir'][1] ** 2 - refs['skin1 green'][1] ** 2):.3f} mm")
    # Rendered with the visible source's seed (--matched-source), the two albedo maps'
    # ratio has next to no Monte Carlo noise of its own.
    nir_source = invsss.read_image(args.matched_source) if args.matched_source else nir["source"]
    ratio = np.where(vis["source"] > 0, nir_source / np.maximum(vis["source"], 1e-12), 0.0)
    rows = []
    single_rows = []
    for condition in args.conditions.split(","):
        rng = np.random.default_rng(args.seed)
        shift = SPLITTER_SHIFT_PX if condition == "splitter" else None
        vis_photo, vis_clip = capture(vis["target"], condition, rng)
        nir_photo, nir_clip = capture(nir["target"], condition, rng, shift)
        align = "translation" if shift is not None else "none"
        for depth_kind in ("depth map", "distance"):
            d = None if depth_kind == "depth map" else distance
            plans = {
                "render, visible": lambda: fit(vis["source"], vis_photo, vis["depth"], mask, d, starts=args.starts,
                                               saturation=vis_clip),
                "render, 940 nm": lambda: fit(nir["source"], nir_photo, nir["depth"], mask, d, starts=args.starts,
                                              saturation=nir_clip, align=align),
                "photo": lambda: fit(vis_photo, nir_photo, vis["depth"], mask, d, starts=args.starts,
                                     saturation=nir_clip, align=align),
                "photo, pigment matched": lambda: fit(vis_photo * ratio, nir_photo, vis["depth"], mask, d,
                                                      starts=args.starts, saturation=nir_clip, align=align),
            }
            if depth_kind == "distance":
                plans["photo, mask made"] = lambda: fit(vis_photo, nir_photo, vis["depth"], made_mask, d,
                                                        starts=args.starts, saturation=nir_clip, align=align)
            wanted = None if args.rows is None else [r.strip() for r in args.rows.split(";")]
            fits = {name: plan() for name, plan in plans.items() if wanted is None or name in wanted}
            widths = {}
            for name, (result, seconds, pair) in fits.items():
                level = effective_level(result.params, pair.depth, pair.mask)
                w, v = profile_mm(result.params, focal, level)
                widths[name] = (half_energy_radius(w, v), rms_width(w, v))
                rows.append((condition, depth_kind, name, float(result.params.sss_level),
                             float(result.params.correction), level, widths[name][0], widths[name][1], result.psnr,
                             seconds))
            if args.single and depth_kind == "distance":
                extra_default = None
                if "render, visible" in widths and "render, 940 nm" in widths:
                    extra_default = float(np.sqrt(max(widths["render, 940 nm"][1] ** 2
                                                      - widths["render, visible"][1] ** 2, 0.0)))
                single_rows.extend(one_gaussian_rows(
                    args, condition, vis, nir, vis_photo, nir_photo, mask, d, focal,
                    (vis_clip, nir_clip), align, extra_default))
            if "render, visible" not in widths or "render, 940 nm" not in widths:
                continue
            s_vis, s_nir = widths["render, visible"][1], widths["render, 940 nm"][1]
            extra = np.sqrt(max(s_nir**2 - s_vis**2, 0.0))
            rows.append((condition, depth_kind, "render: nir - vis (variances subtract)", np.nan, np.nan, np.nan,
                         1.1774 * extra, extra, np.nan, 0.0))
            for name in [n for n in fits if n.startswith("photo")]:
                r50, sigma = widths[name]
                rows.append((condition, depth_kind, f"{name} - render (sigma, %)", np.nan, np.nan, np.nan, np.nan,
                             100.0 * (sigma - extra) / extra, np.nan, 0.0))
            print_table(rows)
    print_table(rows, final=True)
    if args.single:
        print_one_gaussian_table(single_rows)


#: Radial frequency bands (cycles per pixel) of the ``--transfer`` table: from a few
#: periods across a 112 px frame to where the near-infrared target's noise takes over.
TRANSFER_BANDS = (0.005, 0.02, 0.04, 0.06, 0.09, 0.13, 0.2, 0.3)
#: Angular sectors of the half plane left out one at a time for the standard errors.
TRANSFER_SECTORS = 8


def _spectra(images: dict, shape) -> tuple[dict, np.ndarray, np.ndarray]:
    """Each image's Hann-windowed spectrum (mean removed: the frame's edges and its mean
    would swamp the lowest band), the radial frequency and a half-plane sector per bin."""
    height, width = shape
    window = np.outer(np.hanning(height), np.hanning(width))
    spectra = {name: np.fft.fft2((image - image.mean()) * window) for name, image in images.items()}
    fy, fx = np.meshgrid(np.fft.fftfreq(height), np.fft.fftfreq(width), indexing="ij")
    # k and -k carry conjugate values: sectors over the half plane keep each pair together.
    angle = np.mod(np.arctan2(fy, fx), np.pi)
    sector = np.minimum((angle / np.pi * TRANSFER_SECTORS).astype(int), TRANSFER_SECTORS - 1)
    return spectra, np.hypot(fy, fx), sector


def band_transfer(spectra: dict, frequency, keep, pairs, bands=TRANSFER_BANDS) -> np.ndarray:
    """The least-squares transfer from source to target in each band, as ratios of routes.

    ``pairs`` is a tuple of routes, each a tuple of ``(source, target)`` names whose
    transfers multiply (a ``-1`` third element divides): the photo route is one pair, the
    render route's extra blur the near-infrared pair over the visible one. Returns
    ``(bands - 1, routes)``, each column divided by its first band: the routes' gains
    differ, their shapes are what is compared.
    """
    rows = []
    for low, high in zip(bands[:-1], bands[1:]):
        inside = (frequency >= low) & (frequency < high) & keep
        row = []
        for route in pairs:
            value = 1.0
            for source, target, power in route:
                a, b = spectra[source][inside], spectra[target][inside]
                value *= (np.sum(b * np.conj(a)).real / np.sum(np.abs(a) ** 2)) ** power
            row.append(value)
        rows.append(row)
    rows = np.asarray(rows)
    return rows / rows[0]


def transfer_with_errors(spectra, frequency, sector, pairs, bands=TRANSFER_BANDS):
    """:func:`band_transfer` over the whole plane, its jackknife standard errors over the
    sectors, and the same two for the first route over the second (``(bands - 1,)``)."""
    whole = band_transfer(spectra, frequency, np.ones_like(frequency, bool), pairs, bands)
    left_out = np.stack([band_transfer(spectra, frequency, sector != j, pairs, bands)
                         for j in range(TRANSFER_SECTORS)])
    n = TRANSFER_SECTORS

    def jackknife(values):
        return np.sqrt((n - 1) / n * np.sum((values - values.mean(axis=0)) ** 2, axis=0))

    ratio = whole[:, 0] / whole[:, 1]
    return whole, jackknife(left_out), ratio, jackknife(left_out[:, :, 0] / left_out[:, :, 1])


def kernel_transfer(weights, sigmas_px, frequency, power=None, bands=TRANSFER_BANDS) -> np.ndarray:
    """A fitted sum of Gaussians' transfer in each band, divided by its first band (the
    measured transfers' normalisation). A measured band is the mean of the transfer over
    its bins weighted by the source's power there; ``power`` (the source's ``|FFT|^2``,
    the frequencies' shape) weights these the same way (None: uniformly)."""
    weights, sigmas_px = np.asarray(weights, float), np.asarray(sigmas_px, float)
    power = np.ones_like(frequency) if power is None else np.asarray(power, float)
    values = []
    for low, high in zip(bands[:-1], bands[1:]):
        inside = (frequency >= low) & (frequency < high)
        gaussians = np.exp(-2.0 * np.pi**2 * np.outer(frequency[inside] ** 2, sigmas_px**2))
        values.append(float(np.average(gaussians @ weights, weights=power[inside])))
    values = np.asarray(values)
    return values / values[0]


def fitted_kernel_px(result, distance: float) -> tuple[np.ndarray, np.ndarray]:
    """Normalised weights and sigmas (px) of a fit at one ``distance`` (correction held at
    0, so each Gaussian's sigma is ``sqrt(v) sss_level / distance`` pixels)."""
    params = result.params
    scale = float(params.sss_level) / distance
    w = np.asarray(params.weights, np.float64).reshape(len(params.variances), -1)[:, 0]
    return w / w.sum(), np.sqrt(np.asarray(params.variances, np.float64)) * scale


def transfer(args) -> None:
    """``--transfer``: the extra blur each route sees, band by band, measured from the
    images without a model, and the fitted kernels' transfers in the same bands."""
    folder = Path(args.pair)
    vis, nir = read_folder(folder / "visible"), read_folder(folder / "nir")
    images = {"vis_source": vis["source"][..., 0], "vis_target": vis["target"][..., 0],
              "nir_source": nir["source"][..., 0], "nir_target": nir["target"][..., 0]}
    images = {name: np.asarray(image, np.float64) for name, image in images.items()}
    spectra, frequency, sector = _spectra(images, images["vis_target"].shape)
    routes = ((("vis_target", "nir_target", 1),),
              (("nir_source", "nir_target", 1), ("vis_source", "vis_target", -1)))
    whole, errors, ratio, ratio_errors = transfer_with_errors(spectra, frequency, sector, routes)
    focal = float(vis["info"]["focal_px"])
    mask = without_border(vis["mask"], args.border) if args.border else vis["mask"]
    skin = vis["mask"] > 0.5
    distance = float(np.round(np.median(vis["depth"][skin]), -1))
    mm_per_px = distance / focal
    fitted = {}
    for profile in args.transfer_profiles.split(","):
        photo = fit_profile(images["vis_target"], images["nir_target"], mask, distance, focal, profile, args.starts)
        render_vis = fit_profile(images["vis_source"], images["vis_target"], mask, distance, focal, profile,
                                 args.starts)
        render_nir = fit_profile(images["nir_source"], images["nir_target"], mask, distance, focal, profile,
                                 args.starts)
        power = {name: np.abs(spectrum) ** 2 for name, spectrum in spectra.items()}
        fitted[profile] = (
            kernel_transfer(*fitted_kernel_px(photo, distance), frequency, power["vis_target"]),
            kernel_transfer(*fitted_kernel_px(render_nir, distance), frequency, power["nir_source"])
            / kernel_transfer(*fitted_kernel_px(render_vis, distance), frequency, power["vis_source"]))
    print(f"pair {folder}: the extra blur's transfer, each route divided by its first band "
          f"(Hann window, jackknife over {TRANSFER_SECTORS} sectors; {mm_per_px:.3f} mm a pixel at "
          f"--distance {distance:g}; fits with --border {args.border})")
    header = ("| band (cycles/px) | (cycles/mm) | photo, measured | render, measured | photo / render | "
              + " | ".join(f"photo, fitted `{p}` | render, fitted `{p}`" for p in fitted) + " |")
    print(header)
    print("|" + "---|" * header.count(" | ") + "---|")
    for i, (low, high) in enumerate(zip(TRANSFER_BANDS[:-1], TRANSFER_BANDS[1:])):
        cells = [f"{low:.3f}-{high:.3f}", f"{low / mm_per_px:.2f}-{high / mm_per_px:.2f}",
                 f"{whole[i, 0]:.3f} ± {errors[i, 0]:.3f}", f"{whole[i, 1]:.3f} ± {errors[i, 1]:.3f}",
                 f"{ratio[i]:.3f} ± {ratio_errors[i]:.3f}"]
        for photo_t, render_t in fitted.values():
            cells += [f"{photo_t[i]:.3f}", f"{render_t[i]:.3f}"]
        print("| " + " | ".join(cells) + " |")
    sys.stdout.flush()


def fit_profile(source, target, mask, distance, focal, profile, starts):
    """The photo route's fit of ``target`` from ``source`` at one distance with ``profile``."""
    pair = constant_depth_pair(source[..., None].astype(np.float32), target[..., None].astype(np.float32),
                               distance, mask)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return invsss.fit_pairs([pair], profile=profile, fix=HELD_WITH_CONSTANT_DEPTH, n_starts=starts,
                                focal_px=focal)


def without_border(mask: np.ndarray, border: int) -> np.ndarray:
    """``mask`` with its outer ``border`` pixels (each side of the frame) set to 0."""
    inner = np.zeros_like(mask)
    inner[border:-border, border:-border] = mask[border:-border, border:-border]
    return inner


def fit_one_gaussian(source, target, mask, distance, focal, *, starts, saturation, align, pigment):
    """The photo route's default fit (one Gaussian, correction and maxdd held) at one distance."""
    pair = constant_depth_pair(source, target, distance, mask)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = invsss.fit_pairs([pair], profile="single", fix=HELD_WITH_CONSTANT_DEPTH, n_starts=starts,
                                  saturation=saturation, align=align, pigment=pigment, focal_px=focal)
    return result, time.perf_counter() - t0


def one_gaussian_rows(args, condition, vis, nir, vis_photo, nir_photo, mask, distance, focal, clips, align,
                      extra_default) -> list[dict]:
    """``--single``: the render route's two fits and the photo route's (pigment 0 and 2) with
    one Gaussian at ``distance``; widths from each fit's ``blur`` record (mm with ``focal``)."""
    vis_clip, nir_clip = clips
    plans = {
        "render, visible": (vis["source"], vis_photo, vis_clip, "none", 0),
        "render, 940 nm": (nir["source"], nir_photo, nir_clip, align, 0),
        "photo, pigment 0": (vis_photo, nir_photo, nir_clip, align, 0),
        "photo, pigment 2": (vis_photo, nir_photo, nir_clip, align, 2),
    }
    out = []
    sigma = {}
    for name, (source, target, clip, how, degree) in plans.items():
        result, seconds = fit_one_gaussian(source, target, mask, distance, focal, starts=args.starts,
                                           saturation=clip, align=how, pigment=degree)
        blur = result.blur
        sigma[name] = blur["sigma_mm"][0]
        out.append({"condition": condition, "fit": name, "sss_level": float(result.values["sss_level"]),
                    "sss_stderr": result.stderr["sss_level"], "sigma_px": blur["sigma_px"][0],
                    "stderr_px": blur["stderr_px"][0], "sigma_mm": blur["sigma_mm"][0],
                    "stderr_mm": blur["stderr_mm"][0], "resolved": blur["resolved"], "psnr": result.psnr,
                    "psnr_without": None if result.pigment is None else result.pigment["psnr_without"],
                    "seconds": seconds})
    extra_single = float(np.sqrt(max(sigma["render, 940 nm"] ** 2 - sigma["render, visible"] ** 2, 0.0)))
    for row in out:
        if row["fit"].startswith("photo"):
            row["vs_default"] = None if not extra_default else 100.0 * (row["sigma_mm"] - extra_default) / extra_default
            row["vs_single"] = 100.0 * (row["sigma_mm"] - extra_single) / extra_single if extra_single else None
    out.append({"condition": condition, "fit": "render: sigma_extra (one Gaussian; default profile)",
                "extra_single": extra_single, "extra_default": extra_default})
    return out


def print_one_gaussian_table(rows) -> None:
    def pm(value, err, digits):
        return f"{value:.{digits}f}" + ("" if err is None else f" ± {err:.{digits}f}")

    print()
    print("One Gaussian at the distance (--single): widths from each fit's blur record; photo rows against the "
          "render route's sigma_extra (default profile / one Gaussian)")
    print("| capture | fit | sss_level | sigma (px) | sigma (mm) | resolved | PSNR (dB) | PSNR without the field | "
          "vs sigma_extra, default profile | vs sigma_extra, one Gaussian | time (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if "extra_single" in r:
            default = "-" if r["extra_default"] is None else f"{r['extra_default']:.3f}"
            print(f"| {r['condition']} | {r['fit']} | | | {r['extra_single']:.3f}; {default} | | | | | | |")
            continue
        vs = [("-" if r.get(k) is None else f"{r[k]:+.1f} %") for k in ("vs_default", "vs_single")]
        without = "-" if r["psnr_without"] is None else f"{r['psnr_without']:.2f}"
        print(f"| {r['condition']} | {r['fit']} | {pm(r['sss_level'], r['sss_stderr'], 1)} | "
              f"{pm(r['sigma_px'], r['stderr_px'], 3)} | {pm(r['sigma_mm'], r['stderr_mm'], 3)} | {r['resolved']} | "
              f"{r['psnr']:.2f} | {without} | {vs[0]} | {vs[1]} | {r['seconds']:.0f} |")
    sys.stdout.flush()


def print_table(rows, final: bool = False) -> None:
    if not final:
        return
    print("| capture | depth | fit | sss_level | correction | L without c | r50 (mm) | sigma (mm) | PSNR (dB) | time (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for condition, depth_kind, name, level, correction, flat, r50, sigma, psnr, seconds in rows:
        if name.endswith("(sigma, %)"):
            print(f"| {condition} | {depth_kind} | {name} | | | | | {sigma:+.1f} % | | |")
            continue
        if name.startswith("render: nir"):
            print(f"| {condition} | {depth_kind} | {name} | | | | ({r50:.3f}) | {sigma:.3f} | | |")
            continue
        print(f"| {condition} | {depth_kind} | {name} | {level:.1f} | {correction:.1f} | {flat:.1f} | {r50:.3f} | "
              f"{sigma:.3f} | {psnr:.2f} | {seconds:.0f} |")
    sys.stdout.flush()


def masks() -> None:
    """The mask maker's IoU against each bundled pair's own mask (source and target as the pair)."""
    from invsss.scenes.split import read_split

    split = read_split(REPO / "data_synthetic" / "SPLIT.toml")
    print("| pair | part | IoU | mask pixels | made | missed | extra |")
    print("|---|---|---|---|---|---|---|")
    folders = sorted(p for p in (REPO / "data_synthetic").iterdir() if (p / "mask.png").is_file())
    for folder in folders:
        name = folder.name
        part = split.get(name, "model-made")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            made = skin_mask_from_pair(invsss.read_image(folder / "source.exr"),
                                       invsss.read_image(folder / "target.exr")) > 0.5
            truth = invsss.read_mask(folder / "mask.png") > 0.5
        iou = (made & truth).sum() / (made | truth).sum()
        print(f"| `{name}` | {part} | {iou:.4f} | {truth.sum()} | {made.sum()} | {(truth & ~made).sum()} | "
              f"{(made & ~truth).sum()} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pair", default=str(REPO / "data_synthetic" / "twowave_face"))
    parser.add_argument("--conditions", default="clean,camera,splitter")
    parser.add_argument("--starts", type=int, default=4)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--matched-source", default=None, metavar="EXR",
                        help="the near-infrared Lambertian source rendered with the visible one's seed "
                        "(invsss scene experiments/scenes/face_twowave_940.toml --source-only --seed 5 --spp 4096), "
                        "for the pigment-matched rows (default: nir/source.exr, whose own noise then enters)")
    parser.add_argument("--rows", default=None, metavar="NAMES",
                        help="only these fits, separated by ';' (e.g. 'photo;photo, pigment matched'); default all")
    parser.add_argument("--masks", action="store_true", help="the mask maker's IoU on every bundled pair instead")
    parser.add_argument("--single", action="store_true",
                        help="also the photo route's default fit (one Gaussian, pigment 0 and 2, focal length from "
                        "scene.json) and the render route with one Gaussian, at the distance")
    parser.add_argument("--border", type=int, default=0, metavar="PX",
                        help="leave the outer PX pixels of the frame out of every mask (default 0: none)")
    parser.add_argument("--transfer", action="store_true",
                        help="the extra blur's transfer band by band, measured from the images for both routes, "
                        "against the fitted kernels' (clean renders only) instead")
    parser.add_argument("--transfer-profiles", default="single", metavar="NAMES",
                        help="profiles (names or JSON files, separated by ',') whose fitted kernels --transfer "
                        "adds (default single)")
    args = parser.parse_args()
    use_deterministic_scheduler()
    if args.masks:
        masks()
    elif args.transfer:
        transfer(args)
    else:
        run(args)


if __name__ == "__main__":
    main()
