"""What is left between the best light-term fit and the noise ceiling? (issue 29, item 5)

The best term set (``shift,law``) leaves 5-6 dB between the fit and the target's
noise ceiling on the tuning pairs. This script asks two questions of that residual,
post hoc, on pairs written by ``invsss scene``:

1. **Would another image beside the blur explain it?** It fits the pair with
   ``--light-terms shift,law``, takes the prediction ``P``, and fits the target as a
   least-squares mix of ``P``, an offset and each candidate layer, printing the PSNR
   gain on the mask eroded by 2 px (scored as ``experiments/fidelity.py`` scores). A
   joint fit could start from such a gain; a layer that gains nothing post hoc is not
   worth a term. Candidates (``K`` the key light's part, ``S`` the source, ``t`` the
   law's fade of docs/model.md section 8, ``mu = n_z``, ``mu0 = n . l``):

   * ``single``: ``t K / (mu + mu0)``, single scattering relative to Lambert (its
     angular law differs from the multiply scattered light's, which the law gives),
     unblurred, and ``single blurred`` through the fitted blur;
   * ``key``, ``fill``: ``K`` and ``S - K`` unblurred (a sharp component);
   * ``P x curvature``, ``K x curvature``: light leaking from convex parts (the
     divergence of the normal buffer, per mm);
   * ``key edges``: the key light's gradient magnitude (shadow edges);
   * ``P x (1 - n_z)``: the grazing gain, again;
   * ``wider blur``, ``much wider blur``: the source through the fitted blur with every
     variance 3 and 10 times larger (a profile tail);
   * ``any angular law``: ``K`` cut into 8 x 8 bins of ``(mu, mu0)`` and ``S - K`` into 8
     bins of ``mu``, each through the fitted blur with its own weight: every reflectance
     law that depends on the two cosines alone, the law's form left free;
   * ``along the light``: the prediction's first and second derivatives along the key
     light's image direction and the second across it, each in 5 bins of ``mu0`` (a
     shift and an elongation of the profile that vary with the incidence);
   * ``other lights' angular law``: ``S - K`` in 8 x 8 bins of ``mu`` and of the cosine to
     the scene's second light (its direction rebuilt from the scene file), each blurred;
     and ``the law on the other lights``: the fit's law applied to ``S - K`` with that
     direction, ``(S - K)(g - 1)`` blurred, one image (the terms give the key light alone
     the law);
   * ``the law's change``: what the fit's law (and fill) add to the source, ``S' - S``,
     unblurred, and with its own profile (unblurred and through each of the fitted
     Gaussians alone, each with its own weight): whether the blur, which spreads the
     law's change with the whole profile, eats the angular contrast the law gives;
   * for an area key or second light, ``the law over an area light``: the law's gain
     averaged over 9 x 9 points of the light, weighted by the irradiance each sends, in
     place of the gain towards its centre (printed on its own line);
   * ``any 15 x 15 kernel``: the source as the fit lit it (its law and fill applied,
     masked) shifted by every offset up to 7 px, 225 images: every translation-invariant
     linear filter of it, so an upper bound on what another profile shape, an
     anisotropic kernel or one global shift could add;
   * ``a dielectric's angular law``: the key light's part under Fresnel transmission in
     and out of a boundary of index 1.3, alone and with the law at the refracted
     cosines (``w`` 0.3, 0.9, 0.99), each blurred (4 images): what a rough dielectric's
     boundary might add to the index-matched law;
   * ``shadow-edge profiles``: a free 1-D profile across the key light's shadow edges,
     per whole-pixel signed distance up to 7 px and in 3 bins of ``mu0`` (up to 42
     images, each an indicator times the lit level beside the edge): whatever the
     blurred edge should look like and the fitted profile does not give;
   * ``shape at 1-8 px``: convexity (smoothed normals' divergence) and a depth
     difference (smoothed depth minus depth) at 1, 2, 4 and 8 px, alone and times the
     prediction (16 images): light gathered in creases or lost at ridges over a few pixels.

   With ``--thickness`` (ray casts into the scene file's mesh, a few seconds) it adds
   ``light through thin parts``: the key light's irradiance where it enters the far
   side of the object, attenuated as ``exp(-s d)`` over the distance ``d`` through it
   (``s`` = 0.1, 0.26 and 0.6 per mm) and put through the fitted blur, as a renderer
   estimates translucency from a shadow map's depth (Jimenez et al. 2010).

   It also splits the residual by scale: the part a 1.5 px Gaussian keeps (structure
   over a few pixels) and what is left (the pixel scale, where the target's noise is).

With ``--averaged-buffers`` it renders the source and the key light's part again with
another seed and fits again with each the mean of the two renders (half the noise's
variance): what the buffers' own Monte Carlo noise costs the fit.

2. **How much of it is the source's own noise?** The noise ceiling takes the
   prediction to be noise-free, but the source is a Monte Carlo render too. With
   ``--source-noise`` the source is rendered again with another seed (the same scene
   file, ``seed + 1000``; about a minute at 128 px on 2 cores), the difference of the
   two renders (over the square root of 2) is put through the fitted blur and gain,
   and the script prints that noise, the target's, the residual's, and what is left
   of the residual once both are taken off (the model's own error, in quadrature).

Run it on tuning pairs only (data_synthetic/SPLIT.toml)::

    python experiments/layers_probe.py [--source-noise] [--thickness] [--facet-normals] [--averaged-buffers] data_synthetic/pt_face_940 ...
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import pathlib
import sys

import numpy as np

import invsss

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from fidelity import eroded, load_scene_pair, photometric_match  # noqa: E402
from reflectance_probe import mixed_psnr  # noqa: E402

SCENES = pathlib.Path(__file__).parent / "scenes"


@contextlib.contextmanager
def scene_folder():
    """Work in experiments/scenes while inside: scene files name their meshes relative to themselves."""
    here = os.getcwd()
    os.chdir(SCENES)
    try:
        yield
    finally:
        os.chdir(here)


def scene_file(folder) -> str:
    """The scene file a pair folder was rendered from (``pt_NAME`` from ``NAME.toml``)."""
    return f"{folder.name.removeprefix('pt_')}.toml"


def cosines(normal, light):
    """``(mu, mu0, t)``, each (H, W, 1): ``n_z``, ``n . l`` (both clipped to [0, 1]) and the law's fade."""
    mu = np.clip(normal[..., 2], 0.0, 1.0)[..., None]
    mu0 = np.clip(np.sum(normal * light, axis=-1), 0.0, 1.0)[..., None]
    return mu, mu0, np.clip(np.minimum(mu, mu0) / 0.1, 0.0, 1.0)


def surface_curvature(normal, depth):
    """The divergence of the normal's image-plane part, per mm up to one constant (a
    pixel's size grows with depth): positive where the surface is convex (image rows
    point down, hence the sign of y)."""
    divergence = np.gradient(normal[..., 0], axis=1) - np.gradient(normal[..., 1], axis=0)
    return (divergence / np.maximum(depth, 1e-6) * np.median(depth))[..., None]


def through_blur(image, pair, params, variance_factor=1.0):
    """``image`` through the fitted blur (variances scaled by ``variance_factor``), no light terms."""
    scaled = invsss.SSSParams(params.sss_level, params.correction, params.maxdd, params.weights,
                              np.asarray(params.variances) * variance_factor)
    out = invsss.render(np.asarray(image, np.float32), pair["depth"], pair["mask"], scaled)
    return np.asarray(out, np.float64).reshape(np.shape(image))


def cosine_bins(x, count: int) -> list[np.ndarray]:
    """Indicator images of ``count`` equal bins of ``x`` in [0, 1] (the last one closed)."""
    index = np.minimum((x * count).astype(int), count - 1)
    return [(index == k).astype(np.float64) for k in range(count)]


def along_the_light(prediction, light, mu0) -> list[np.ndarray]:
    """The prediction's derivatives along the key light's image direction (first and
    second) and across it (second), each cut into 5 bins of ``mu0``."""
    px, py = -light[..., 0], light[..., 1]  # image x right, rows down (as the shift term)
    norm = np.maximum(np.hypot(px, py), 1e-6)
    ux, uy = px / norm, py / norm
    gx, gy = np.gradient(prediction[..., 0], axis=1), np.gradient(prediction[..., 0], axis=0)
    gxx, gyy, gxy = np.gradient(gx, axis=1), np.gradient(gy, axis=0), np.gradient(gx, axis=0)
    first = ux * gx + uy * gy
    along = ux * ux * gxx + 2 * ux * uy * gxy + uy * uy * gyy
    across = uy * uy * gxx - 2 * ux * uy * gxy + ux * ux * gyy
    return [(d * b[..., 0])[..., None] for b in cosine_bins(mu0, 5) for d in (first, along, across)]


def shadow_edge_profiles(key, mu0, mask, reach: int = 7, bins: int = 3) -> tuple[list[np.ndarray], np.ndarray]:
    """A free profile across the key light's shadow edges: indicator images of the
    signed distance (whole pixels, ``-reach..reach - 1``; 0 and up on the lit side) to the
    nearest shadow edge, in ``bins`` bins of ``mu0``, each times the lit level beside
    the edge. Also returns where those pixels are (a boolean map: near an edge,
    facing the light, on the mask).

    A pixel is lit where the key light's part over Lambert's ``mu0`` is over a quarter
    of its 90th percentile on the mask (the texture and the light's fall-off vary far
    less than a shadow's depth); the terminator (``mu0`` < 0.15), where the light fades
    without a shadow, is left out. Each image is one free weight: any 1-D kernel
    across the edges, per incidence bin, that the blur's profile does not give."""
    from scipy import ndimage

    k = key[..., 0] * mask
    facing = (mu0[..., 0] >= 0.15) & (mask > 0)
    ratio = k / np.maximum(mu0[..., 0], 0.05)
    lit = ratio > 0.25 * (np.quantile(ratio[facing], 0.9) if np.any(facing) else np.inf)
    level = ndimage.maximum_filter(np.where(lit, k, 0.0), size=2 * reach + 1)
    distance = ndimage.distance_transform_edt(lit) - ndimage.distance_transform_edt(~lit)
    # The edt's distance is 1 at the first pixel on either side of the edge: those
    # two pixels get steps 0 (lit) and -1 (shadowed).
    step = np.floor(np.where(distance > 0, distance - 0.5, distance + 0.5)).astype(int)
    near = (step >= -reach) & (step < reach) & facing
    layers = []
    for b in cosine_bins(mu0, bins):
        for d in range(-reach, reach):
            image = (near & (step == d) & (b[..., 0] > 0)) * level
            if np.any(image):
                layers.append(image[..., None])
    return layers, near


def shape_at_scales(prediction, normal, depth, mask) -> list[np.ndarray]:
    """Convexity and a depth difference over 1 to 8 px, alone and times the prediction.

    At each scale ``s`` the normals and the depth are smoothed on the mask (a Gaussian
    of ``s`` px, normalised by the smoothed mask); the convexity is the divergence of
    the smoothed normals, the depth difference ``(smoothed depth - depth) / median
    depth``, as unsharp-masked depth buffers darken creases (Luft et al. 2006).
    """
    from scipy import ndimage

    m = np.asarray(mask, np.float64)

    def smoothed(x, s):
        return ndimage.gaussian_filter(x * m, s) / np.maximum(ndimage.gaussian_filter(m, s), 1e-6)

    layers = []
    for s in (1, 2, 4, 8):
        divergence = np.gradient(smoothed(normal[..., 0], s), axis=1) - np.gradient(smoothed(normal[..., 1], s), axis=0)
        difference = (smoothed(depth, s) - depth) / np.median(depth[m > 0])
        for field in (divergence[..., None], difference[..., None]):
            layers += [field, prediction * field]
    return layers


def other_lights(folder) -> np.ndarray | None:
    """Unit vectors (H, W, 3) towards the scene's second light (the first of the others):
    the folder's ``fill_light.exr`` (the ``fill`` term's buffer); None for one light."""
    path = pathlib.Path(folder) / "fill_light.exr"
    return invsss.read_image(path) if path.is_file() else None


def fill_law(fit, pair, fill_light) -> list[np.ndarray]:
    """The law (the fit's ``w``) applied to the other lights' part ``S - K`` as the fit
    applies it to the key's, with the other light's direction: ``(S - K)(g - 1)`` blurred."""
    from invsss.forward.light_terms import reflectance_law

    albedo = np.asarray(fit.light_terms["law"], np.float32)  # one w, or one per channel
    gain = np.asarray(reflectance_law(np.asarray(pair["buffers"].normal, np.float32),
                                      fill_light.astype(np.float32), albedo), np.float64)
    rest = np.asarray(pair["source"], np.float64) - np.asarray(pair["buffers"].key, np.float64)
    return [through_blur(rest * (gain - 1.0), pair, fit.params)]


def fresnel_transmittance(cosine, eta: float = 1.3):
    """Unpolarised Fresnel transmittance into a dielectric of relative index ``eta`` at
    the incidence ``cosine``, and the refracted ray's cosine."""
    cosine = np.clip(cosine, 1e-4, 1.0)
    refracted = np.sqrt(np.clip(1.0 - (1.0 - cosine**2) / eta**2, 0.0, 1.0))
    s = (cosine - eta * refracted) / (cosine + eta * refracted)
    p = (eta * cosine - refracted) / (eta * cosine + refracted)
    return 1.0 - 0.5 * (s**2 + p**2), refracted


def dielectric_laws(pair, fit) -> list[np.ndarray]:
    """The key light's part under a dielectric boundary's angular laws, ``K (g - 1)``
    blurred, faded as the law is: Fresnel transmission in and out,
    ``T(mu0) T(mu) / T(1)^2``, alone and times the law at the refracted cosines for
    ``w`` = 0.3, 0.9 and 0.99 (eta 1.3, the bundled rough dielectrics')."""
    from invsss.forward.light_terms import chandrasekhar_h

    normal, light = (np.asarray(b, np.float64) for b in (pair["buffers"].normal, pair["buffers"].light))
    key = np.asarray(pair["buffers"].key, np.float64) * np.asarray(pair["mask"], np.float64)[..., None]
    mu, mu0, fade = cosines(normal, light)
    into, inside0 = fresnel_transmittance(mu0)
    out, inside = fresnel_transmittance(mu)
    head_on, _ = fresnel_transmittance(np.ones(1))
    fresnel = into * out / head_on**2
    gains = [fresnel]
    for w in (0.3, 0.9, 0.99):
        h = lambda x: np.asarray(chandrasekhar_h(x, w), np.float64)  # noqa: E731
        gains.append(fresnel * h(inside) * h(inside0) / np.maximum(inside + inside0, 1e-6) / (h(1.0) ** 2 / 2.0))
    return [through_blur(key * fade * (g - 1.0), pair, fit.params) for g in gains]


def law_change(fit, pair) -> np.ndarray:
    """What the fit's law (and fill) add to the source, ``S' - S``, before any blur."""
    from invsss.forward.light_terms import lit_source

    terms, buffers = fit.light_terms, pair["buffers"]
    source = np.asarray(pair["source"], np.float32)
    fill = terms.get("fill")
    lit = lit_source(source, np.asarray(buffers.key, np.float32), np.asarray(pair["mask"], np.float32),
                     np.asarray(buffers.normal, np.float32), np.asarray(buffers.light, np.float32),
                     np.asarray(terms["law"], np.float32), float(terms.get("law_strength", 1.0)),
                     None if fill is None or buffers.fill_light is None else np.asarray(buffers.fill_light, np.float32),
                     None if fill is None else float(fill))
    return np.asarray(lit, np.float64) - source


def shifted(image, dy: int, dx: int):
    """``image`` at ``(y + dy, x + dx)``, 0 outside the frame."""
    h, w = image.shape[:2]
    out = np.zeros_like(image)
    out[max(-dy, 0):h + min(-dy, 0), max(-dx, 0):w + min(-dx, 0)] = image[max(dy, 0):h + min(dy, 0),
                                                                           max(dx, 0):w + min(dx, 0)]
    return out


def through_one_gaussian(image, pair, params, k: int):
    """``image`` through the fitted blur's ``k``-th Gaussian alone (weight 1)."""
    weights = np.zeros(len(params.weights), np.float32)
    weights[k] = 1.0
    one = invsss.SSSParams(params.sss_level, params.correction, params.maxdd, weights, params.variances)
    out = invsss.render(np.asarray(image, np.float32), pair["depth"], pair["mask"], one)
    return np.asarray(out, np.float64).reshape(np.shape(image))


def area_light_gains(pair, fit, keep, samples: int = 9) -> dict:
    """What giving the law an area light's whole extent, rather than the direction to
    its centre (``light.exr``, ``fill_light.exr``), gains (dB): the law's gain averaged
    over ``samples`` x ``samples`` points of the light, each weighted by the
    irradiance it sends (``n . l`` times the emitter's cosine over the squared
    distance; no shadowing). For an area key, the difference ``K (g_area - g_centre)``,
    blurred and mixed into the fit with a free weight; for an area second light (the
    fill's), ``(S - K)(g - 1)`` blurred, with the averaged gain and with the centre's,
    each mixed in alone (the fit's own fill strength may be near 0). Empty unless the
    fit has the law and a light is an area light."""
    from invsss.forward.light_terms import reflectance_law
    from invsss.scenes import parse_config
    from invsss.scenes.path_tracing import camera_points, camera_pose

    if not fit.light_terms or fit.light_terms.get("law") is None:
        return {}
    config = parse_config(pair["info"]["config"])
    origin, rotation = camera_pose(config)
    points = camera_points(config, np.asarray(pair["depth"], np.float64))
    normal = np.asarray(pair["buffers"].normal, np.float64)
    albedo = np.asarray(fit.light_terms["law"], np.float32)
    key = np.asarray(pair["buffers"].key, np.float64) * np.asarray(pair["mask"], np.float64)[..., None]
    rest = np.asarray(pair["source"], np.float64) * np.asarray(pair["mask"], np.float64)[..., None] - key
    target = np.asarray(pair["target"], np.float64)
    prediction = np.asarray(fit.fitted[0], np.float64).reshape(target.shape)
    base = mixed_psnr(target, keep, [prediction])

    def gain(*images):
        return mixed_psnr(target, keep, [prediction, *(through_blur(x, pair, fit.params) for x in images)]) - base

    def law_towards(place, facing):
        towards = rotation @ (place - origin) - points
        distance = np.linalg.norm(towards, axis=-1, keepdims=True)
        light = towards / distance
        sent = np.clip(-(light @ (rotation @ facing)), 0.0, None) * np.clip(np.sum(normal * light, -1), 0.0, None)
        law = np.asarray(reflectance_law(normal.astype(np.float32), light.astype(np.float32), albedo), np.float64)
        return law, (sent / distance[..., 0] ** 2)[..., None]

    out = {}
    for index, part in ((0, key), (1, rest)):
        if index >= len(config.lights) or config.lights[index].type != "area":
            continue
        light = config.lights[index]
        centre = np.asarray(light.center, np.float64)
        facing = np.asarray(light.look_at, np.float64) - centre
        facing /= np.linalg.norm(facing)
        across = np.cross(facing, [0.0, 1.0, 0.0])
        across /= np.linalg.norm(across)
        along = np.cross(facing, across)
        total = weight = 0.0
        for u in np.linspace(-0.5, 0.5, samples):
            for v in np.linspace(-0.5, 0.5, samples):
                law, sent = law_towards(centre + u * light.width * across + v * light.height * along, facing)
                total, weight = total + sent * law, weight + sent
        at_centre, _ = law_towards(centre, facing)
        spread = np.where(weight > 0, total / np.maximum(weight, 1e-30), at_centre)
        if index == 0:
            out["area key: the averaged law's difference"] = gain(part * (spread - at_centre))
        else:
            out["area fill: the law towards its centre"] = gain(part * (at_centre - 1.0))
            out["area fill: the law averaged over it"] = gain(part * (spread - 1.0))
    return out


def layer_gains(pair, fit, keep, fill_light=None) -> tuple[float, dict, float]:
    """The PSNR gain of each candidate layer mixed with the fit's prediction (dB).

    Returns ``(psnr, gains, near_edges)``: the prediction's own PSNR on ``keep``, the
    gain of each layer by name, and the share of ``keep`` within 7 px of a shadow edge.
    """
    source, target = (np.asarray(pair[k], np.float64) for k in ("source", "target"))
    key = np.asarray(pair["buffers"].key, np.float64)
    normal, light = (np.asarray(b, np.float64) for b in (pair["buffers"].normal, pair["buffers"].light))
    mu, mu0, fade = cosines(normal, light)
    prediction = np.asarray(fit.fitted[0], np.float64).reshape(target.shape)

    def psnr(columns) -> float:
        return mixed_psnr(target, keep, columns)

    single = fade * key / np.maximum(mu + mu0, 1e-3)
    curvature = surface_curvature(normal, np.asarray(pair["depth"], np.float64))
    edges = np.sqrt(sum(np.square(np.gradient(key[..., 0], axis=a)) for a in (0, 1)))[..., None]
    layers = {
        "single": [single], "single blurred": [through_blur(single, pair, fit.params)],
        "key": [key], "fill": [source - key], "single + key + fill": [single, key, source - key],
        "P x curvature": [prediction * curvature], "K x curvature": [key * curvature],
        "key edges": [edges], "P x (1 - n_z)": [prediction * (1.0 - mu)],
        "wider blur": [through_blur(source, pair, fit.params, 3.0)],
        "much wider blur": [through_blur(source, pair, fit.params, 10.0)],
        "any angular law": [through_blur(key * a * b, pair, fit.params)
                            for a in cosine_bins(mu, 8) for b in cosine_bins(mu0, 8) if np.any((a * b)[keep])]
                           + [through_blur((source - key) * a, pair, fit.params) for a in cosine_bins(mu, 8)],
        "along the light": along_the_light(prediction, light, mu0),
        "a dielectric's angular law": dielectric_laws(pair, fit),
        "shape at 1-8 px": shape_at_scales(prediction, normal, np.asarray(pair["depth"], np.float64), pair["mask"]),
    }
    edge_layers, near_edges = shadow_edge_profiles(key, mu0, np.asarray(pair["mask"], np.float64))
    layers["shadow-edge profiles"] = edge_layers
    if fill_light is not None:
        _, fill_mu0, _ = cosines(normal, fill_light)
        layers["other lights' angular law"] = [through_blur((source - key) * a * b, pair, fit.params)
                                               for a in cosine_bins(mu, 8) for b in cosine_bins(fill_mu0, 8)
                                               if np.any((a * b)[keep])]
        if fit.light_terms and fit.light_terms.get("law") is not None:
            layers["the law on the other lights"] = fill_law(fit, pair, fill_light)
    # Any translation-invariant filter of the source as the fit lit it: 225 free weights.
    lit = np.asarray(pair["source"], np.float64) * np.asarray(pair["mask"], np.float64)[..., None]
    change = law_change(fit, pair) if fit.light_terms and fit.light_terms.get("law") is not None else None
    layers["any 15 x 15 kernel"] = [shifted(lit if change is None else lit + change, dy, dx)
                                    for dy in range(-7, 8) for dx in range(-7, 8)]
    if change is not None:
        layers["the law's change, unblurred"] = [change]
        layers["the law's change, its own profile"] = [change] + [
            through_one_gaussian(change, pair, fit.params, k) for k in range(len(fit.params.weights))]
    base = psnr([prediction])
    gains = {name: psnr([prediction, *images]) - base for name, images in layers.items()}
    return base, gains, float(np.mean(near_edges[keep]))


def source_noise(folder, pair, fit, keep) -> dict:
    """The source's render noise through the fitted blur and gain, beside the target's
    noise and the fit's residual (rms on ``keep``, the target's units)."""
    from invsss.scenes import load_config, render_scene

    info = json.loads((folder / "scene.json").read_text())
    with scene_folder():
        config = load_config(scene_file(folder))
        again = render_scene(config.model_copy(update={"seed": config.seed + 1000}), target=False)
    source = np.asarray(pair["source"], np.float64)
    noise = (source - np.asarray(again.source, np.float64).reshape(source.shape)) / np.sqrt(2.0)
    # The fit's photometric gain, from the prediction against the blurred source.
    gain = photometric_gain(np.asarray(fit.fitted[0], np.float64).reshape(source.shape[:2] + (-1,)),
                            through_blur(source, pair, fit.params), keep)
    blurred_noise = gain * through_blur(noise, pair, fit.params)
    residual = fit_residual(fit, np.asarray(pair["target"], np.float64), keep)

    def rms(x):
        return float(np.sqrt(np.mean(np.square(x[keep]))))

    found = {"target noise": float(info["noise"]["noise_rms"]), "source noise, blurred": rms(blurred_noise),
             "residual": rms(residual)}
    left = found["residual"] ** 2 - found["target noise"] ** 2 - found["source noise, blurred"] ** 2
    found["model error"] = float(np.sqrt(max(left, 0.0)))
    found["ceiling"] = float(
        info["noise"]["noise_ceiling_db"]
        - 10.0 * np.log10(1.0 + (found["source noise, blurred"] / found["target noise"]) ** 2))
    return found


def averaged_buffers_gain(folder, pair, fit, terms: str, keep) -> dict:
    """PSNR (dB) on ``keep`` of ``fit`` (with the shipped buffers) and of the fit again
    with the source and the key light's part each the mean of the shipped render and
    one with another seed (half the render noise's variance): how much the buffers'
    Monte Carlo noise costs the fit (``S - K`` carries both renders' noise, since the
    key light is rendered from a scene of its own)."""
    from invsss.scenes import load_config, render_scene

    with scene_folder():
        config = load_config(scene_file(folder))
        again = render_scene(config.model_copy(update={"seed": config.seed + 1000}), target=False)
    buffers = pair["buffers"]
    source = np.asarray(pair["source"], np.float64)
    mean_source = 0.5 * (source + np.asarray(again.source, np.float64).reshape(source.shape))
    key = np.asarray(buffers.key, np.float64)
    mean_key = 0.5 * (key + np.asarray(again.key, np.float64).reshape(key.shape))
    target = np.asarray(pair["target"], np.float64)

    def psnr(result):
        return mixed_psnr(target, keep, [np.asarray(result.fitted[0], np.float64).reshape(target.shape)])

    averaged = invsss.fit_pair(mean_source, pair["target"], pair["depth"], pair["mask"], light_terms=terms,
                               light_buffers=invsss.LightBuffers(normal=buffers.normal, light=buffers.light,
                                                                 key=mean_key, fill_light=buffers.fill_light))
    return {"shipped buffers": psnr(fit), "buffers averaged over two renders": psnr(averaged)}


def key_through_thin_parts(folder) -> tuple[np.ndarray, np.ndarray]:
    """Ray-cast the scene file's object: for each pixel, the distance ``d`` (mm) from its
    surface point through the object towards the key light, and the key light's
    irradiance where that ray enters the object (cosine, visibility past the occluders,
    a point light's falloff; 0 on the lit side, where the ray leaves at once)."""
    import tempfile

    from invsss.scenes import load_config
    from invsss.scenes.mitsuba_scene import import_mitsuba, scene_dict
    from invsss.scenes.path_tracing import object_ply, render_aovs

    mi = import_mitsuba("scalar_rgb")
    with scene_folder(), tempfile.TemporaryDirectory(prefix="layers-probe-") as scratch:
        config = load_config(scene_file(folder))
        ply, _ = object_ply(config, scratch)
        coefficients = config.medium.coefficients()
        geometry = scene_dict(mi, config, "geometry", mesh_ply=ply, coefficients=coefficients)
        aovs = render_aovs(mi, geometry)
        skin = mi.load_dict(geometry)
        # The source's scene has the occluders too; it only answers "is the light blocked".
        blockers = mi.load_dict(scene_dict(mi, config, "source", mesh_ply=ply, albedo=0.5))
    coverage = aovs["cov"][..., 0]
    points = aovs["pos"] / np.maximum(coverage, 1e-6)[..., None]
    normals = aovs["nn"] / np.maximum(np.linalg.norm(aovs["nn"], axis=-1, keepdims=True), 1e-9)
    key = config.lights[0]
    place = None if key.type == "directional" else np.asarray(key.center if key.type == "area" else key.position)

    def towards_light(x):
        v = -np.asarray(key.direction, np.float64) if place is None else place - x
        return v / np.linalg.norm(v)

    def first_hit(scene, origin, direction):
        found = scene.ray_intersect(mi.Ray3f(mi.Point3f(*origin), mi.Vector3f(*direction)))
        return found if found.is_valid() else None

    distance = np.full(coverage.shape, np.inf)
    irradiance = np.zeros(coverage.shape)
    for i, j in zip(*np.nonzero(coverage >= 0.5)):
        p, n = points[i, j], normals[i, j]
        l = towards_light(p)
        entry = first_hit(skin, p - 0.05 * n, l)
        if entry is None or float(entry.t) < 1.0:  # lit side: the ray leaves the object at once
            continue
        distance[i, j] = float(entry.t)
        q = np.array(entry.p, np.float64)
        nq = np.array(entry.sh_frame.n, np.float64)
        lq = towards_light(q)
        cosine = float(nq @ lq)
        if cosine <= 0.0:
            continue
        block = first_hit(blockers, q + 0.05 * nq, lq)
        reach = np.inf if place is None else np.linalg.norm(place - q)
        if block is not None and float(block.t) < 0.98 * reach:
            continue
        irradiance[i, j] = cosine * (1.0 if place is None else 1.0 / reach ** 2)
    return distance, irradiance / max(irradiance.max(), 1e-30)


def thickness_gains(folder, pair, fit, keep, target) -> dict:
    """The gain of the key light carried through thin parts (see the module docstring)."""
    distance, irradiance = key_through_thin_parts(folder)
    prediction = np.asarray(fit.fitted[0], np.float64).reshape(target.shape)
    base = mixed_psnr(target, keep, [prediction])
    gains = {}
    for s in (0.1, 0.26, 0.6):
        carried = (np.where(np.isfinite(distance), np.exp(-s * distance), 0.0) * irradiance)[..., None]
        gains[f"s = {s}/mm"] = mixed_psnr(
            target, keep, [prediction, through_blur(np.broadcast_to(carried, target.shape), pair, fit.params)]) - base
    return gains


def fit_residual(fit, target, keep) -> np.ndarray:
    """The target minus the fit's prediction after the per-channel gain and offset on ``keep``
    (as ``experiments/fidelity.py`` scores)."""
    matched = photometric_match(np.asarray(fit.fitted[0], np.float32), target.astype(np.float32),
                                keep.astype(np.float32))
    return target - matched


def residual_scales(fit, target, keep) -> dict:
    """The residual's rms (first channel), and that of its part a 1.5 px Gaussian keeps
    and of the rest."""
    from scipy import ndimage

    inside = keep[..., 0] if keep.ndim == 3 else keep
    residual = np.where(inside, fit_residual(fit, target, inside)[..., 0], 0.0)
    weight = ndimage.gaussian_filter(inside.astype(np.float64), 1.5)
    smooth = ndimage.gaussian_filter(residual, 1.5) / np.maximum(weight, 1e-6)

    def rms(x):
        return float(np.sqrt(np.mean(np.square(x[inside]))))

    return {"residual": rms(residual), "over a few pixels": rms(smooth), "pixel scale": rms(residual - smooth)}


def facet_normal_gains(folder, pair, fit, terms, keep) -> dict:
    """Fit again with the source, the key light and the normal buffer rendered with each
    triangle's own normal instead of the smoothly interpolated shading normal, beside
    ``fit`` (the same terms on the pair as it is).

    The target's medium is bounded by the flat triangles themselves, while the source's
    Lambertian shading follows the interpolated normals; on meshes whose triangles are
    2-4 px wide the two differ at the pixel scale. A gain here is error that a smooth
    real face would not show.
    """
    from invsss.scenes import load_config, render_scene

    with scene_folder():
        config = load_config(scene_file(folder))
        flat = config.model_copy(update={"object": config.object.model_copy(update={"face_normals": True})})
        flat_render = render_scene(flat, target=False)
    target = np.asarray(pair["target"], np.float64)
    source = np.asarray(flat_render.source, np.float32).reshape(np.shape(pair["source"]))
    buffers = invsss.LightBuffers(np.asarray(flat_render.normal, np.float32), pair["buffers"].light,
                                  key=np.asarray(flat_render.key, np.float32).reshape(np.shape(pair["buffers"].key)))
    turned = np.degrees(np.arccos(np.clip(np.sum(np.asarray(flat_render.normal, np.float64)
                                                 * np.asarray(pair["buffers"].normal, np.float64), axis=-1), -1, 1)))
    flat_fit = invsss.fit_pair(source, pair["target"], pair["depth"], pair["mask"], light_terms=terms,
                               light_buffers=buffers)

    def psnr(result):
        return mixed_psnr(target, keep, [np.asarray(result.fitted[0], np.float64).reshape(target.shape)])

    return {"median angle to the shading normal (deg)": float(np.median(turned[keep])),
            "shading normals": psnr(fit), "facet normals": psnr(flat_fit)}


def photometric_gain(prediction, blurred, keep) -> float:
    """The least-squares gain from ``blurred`` to ``prediction`` on ``keep`` (with an offset)."""
    p, b = prediction[keep].ravel(), blurred[keep].ravel()
    design = np.stack([b, np.ones_like(b)], axis=1)
    (gain, _), *_ = np.linalg.lstsq(design, p, rcond=None)
    return float(gain)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--terms", default="shift,law", help="the light terms of the fit (default shift,law)")
    parser.add_argument("--source-noise", action="store_true",
                        help="render each source again with another seed and measure its noise (slow)")
    parser.add_argument("--thickness", action="store_true",
                        help="ray-cast the scene's mesh and try the key light carried through thin parts")
    parser.add_argument("--facet-normals", action="store_true",
                        help="render the source, key light and normals again with the triangles' own normals "
                        "and fit again (a few minutes)")
    parser.add_argument("--averaged-buffers", action="store_true",
                        help="render the source and key light again with another seed and fit with the means "
                        "(a few minutes)")
    parser.add_argument("pairs", nargs="+", type=pathlib.Path)
    args = parser.parse_args()
    for folder in args.pairs:
        pair = load_scene_pair(folder)
        keep = eroded(pair["mask"], 2) > 0
        fit = invsss.fit_pair(pair["source"], pair["target"], pair["depth"], pair["mask"],
                              light_terms=args.terms, light_buffers=pair["buffers"])
        base, gains, share = layer_gains(pair, fit, keep, other_lights(folder))
        cells = " | ".join(f"{name} {gain:+.2f}" for name, gain in gains.items())
        print(f"{folder.name}: fit + {args.terms} {base:.2f} dB (noise ceiling "
              f"{pair['info']['noise']['noise_ceiling_db']:.2f}); gain with a layer: {cells}; "
              f"{100 * share:.1f} % of the mask lies within 7 px of a shadow edge", flush=True)
        area = area_light_gains(pair, fit, keep)
        if area:
            print("  the law over an area light's extent: "
                  + ", ".join(f"{name} {value:+.3f}" for name, value in area.items()), flush=True)
        scales = residual_scales(fit, np.asarray(pair["target"], np.float64), keep)
        print("  residual rms: " + ", ".join(f"{name} {value:.4f}" for name, value in scales.items()), flush=True)
        if args.thickness:
            found = thickness_gains(folder, pair, fit, keep, np.asarray(pair["target"], np.float64))
            print("  gain with the key light through thin parts: "
                  + ", ".join(f"{name} {gain:+.2f}" for name, gain in found.items()), flush=True)
        if args.facet_normals:
            found = facet_normal_gains(folder, pair, fit, args.terms, keep)
            print("  " + ", ".join(f"{name} {value:.2f}" for name, value in found.items()), flush=True)
        if args.averaged_buffers:
            found = averaged_buffers_gain(folder, pair, fit, args.terms, keep)
            print("  the fit with " + ", ".join(f"{name} {value:.2f}" for name, value in found.items()), flush=True)
        if args.source_noise:
            found = source_noise(folder, pair, fit, keep)
            print("  rms: " + ", ".join(f"{name} {value:.4f}" for name, value in found.items()
                                        if name != "ceiling")
                  + f"; the noise ceiling with the source's noise {found['ceiling']:.2f} dB",
                  flush=True)


if __name__ == "__main__":
    main()
