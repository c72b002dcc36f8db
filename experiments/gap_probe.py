"""What is left of the gap to the noise ceiling, and where does it come from? (issue 29, item 5)

On the path-traced *tuning* pairs (data_synthetic/SPLIT.toml) this replaces the
screen-space model's 7-tap separable passes by three dense references and scores
each against the target the way ``experiments/fidelity.py`` does (best gain and
offset per channel, PSNR on the mask eroded by 2 px):

``7-tap passes``
    the model as invsss renders it (docs/model.md, sections 2-5);
``dense, screen distance``
    the same sum of Gaussians with the same stretch, as a dense 2D convolution:
    every pixel of a window gathered with the weight
    ``exp(-((dx / s_x)^2 + (dy / s_y)^2) / (2 v))``, ``s_x``, ``s_y`` the output
    pixel's stretch factors, normalised over the window. It differs from the
    passes only by their sampling (7 taps a pass, linear interpolation between
    them, the second pass reading the first at its own stretch);
``dense, surface distance``
    the weight of the distance between the two pixels' points on the surface,
    back-projected from the depth buffer with the camera's focal length ``F``
    (``|P(y) - P(x)| F / L`` in the profile's units: equal to the screen distance
    on a surface that faces the camera, longer where it turns away). It needs no
    ``correction`` or ``maxdd``: the depth buffer's geometry replaces them.
``surface integral``
    the same distance, and each pixel's light weighted by the area of surface it
    covers (from the depth buffer, zero off the mask); not normalised by its own sum
    over the window but by the same sum on the output pixel's tangent plane (the depth
    continued with its slopes), over the window's pixels on the mask (past the mask's
    edge the surface goes on out of sight). It is the integral of the profile over the
    surface, which the normalised variants replace by an average: where the surface
    bends towards a pixel's neighbourhood (a crease, a fold) more light arrives than on
    its tangent plane, where it bends away less, and a neighbour that turns further
    from the camera than the pixel sends more of its light. Comparing with the tangent
    plane's sum, not with the integral of the profile, keeps a narrow Gaussian (under a
    pixel) from turning a tilted pixel's own area into a gain.

Each variant gets its own best ``sss_level`` (a golden-section search over its
logarithm) with the profile's weights and an offset solved by least squares on
the mask, as the fit solves them; the other parameters are the fit's. This is
done for the plain fit and for the fit with ``shift,law`` (the law applied to the
source, the shift to each blurred layer, both held at the fit's values).

    python experiments/gap_probe.py [PAIR_DIR ...] [--terms shift,law] [--variants 'NAME;...']

Without PAIR_DIR, the tuning pairs of data_synthetic/SPLIT.toml.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import invsss
from invsss.forward.light_terms import light_transport, propagation_offsets
from invsss.forward.stretch import stretch_factors

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from fidelity import eroded, load_scene_pair, score  # noqa: E402

#: The window's half-width: three standard deviations of the widest Gaussian, at most.
MAX_RADIUS_PX = 12
VARIANTS = ("7-tap passes", "dense, screen distance", "dense, surface distance", "surface integral")
#: The smallest cosine an area weight divides by (as the law's fade, docs/model.md section 8).
MIN_COSINE = 0.1


def _shifted(image: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """``image`` read at ``(y + dy, x + dx)``, clamped to the edge (the passes' addressing)."""
    h, w = image.shape[:2]
    rows = np.clip(np.arange(h) + dy, 0, h - 1)
    cols = np.clip(np.arange(w) + dx, 0, w - 1)
    return image[rows][:, cols]


def _back_projected(d: np.ndarray, focal_px: float, dy: int, dx: int) -> np.ndarray:
    """Camera-space points (H, W, 3) in mm of the pixels ``(y + dy, x + dx)`` at the
    depths ``d`` (H, W), pinhole at the image centre."""
    h, w = d.shape
    rows, cols = np.mgrid[0:h, 0:w].astype(np.float64)
    return np.stack([(cols + dx - (w - 1) / 2.0) * d / focal_px, (rows + dy - (h - 1) / 2.0) * d / focal_px, d],
                    axis=-1)


def _points(depth: np.ndarray, focal_px: float, dy: int = 0, dx: int = 0) -> np.ndarray:
    """The depth buffer's points of the pixels ``(y + dy, x + dx)``. Past the edge the
    depth is the edge's (as the image is) but the pixel keeps its own position, so a
    clamped sample is as far as its offset says."""
    return _back_projected(_shifted(depth, dy, dx), focal_px, dy, dx)


def _plane_points(depth: np.ndarray, slopes, focal_px: float, dy: int, dx: int) -> np.ndarray:
    """The points of the pixels ``(y + dy, x + dx)`` on each pixel's tangent plane, the
    depth continued from the pixel's own with ``slopes`` (per pixel, down and across)."""
    return _back_projected(depth + slopes[0] * dy + slopes[1] * dx, focal_px, dy, dx)


def _plane_area(depth: np.ndarray, slopes, focal_px: float) -> np.ndarray:
    """The area (H, W) in mm^2 a pixel covers on its tangent plane, bounded as in :func:`surface_areas`."""
    at = _plane_points(depth, slopes, focal_px, 0, 0)
    across = _plane_points(depth, slopes, focal_px, 0, 1) - at
    down = _plane_points(depth, slopes, focal_px, 1, 0) - at
    return np.minimum(np.linalg.norm(np.cross(across, down), axis=-1), (depth / focal_px) ** 2 / MIN_COSINE)


def surface_areas(depth: np.ndarray, mask: np.ndarray, focal_px: float) -> np.ndarray:
    """Area in mm^2 of surface each pixel covers, (H, W): zero off the mask.

    The depth buffer's own geometry, as the distances: each quarter of a pixel's
    footprint is the parallelogram spanned by the half-steps to its neighbours on
    that side (forward or backward in each axis), so a pixel on a crease gets half
    of each face. A quarter counts at most ``1 / MIN_COSINE`` times a quarter of the
    facing area ``(d / F)^2``, so that a step in depth (an occluding edge) does not
    stand for a wall of skin.
    """
    points = _points(depth, focal_px)
    facing = (depth / focal_px) ** 2
    total = np.zeros(depth.shape, np.float64)
    for dy in (-1, 1):
        for dx in (-1, 1):
            along_x = (_points(depth, focal_px, 0, dx) - points) * dx
            along_y = (_points(depth, focal_px, dy, 0) - points) * dy
            quarter = np.linalg.norm(np.cross(along_x, along_y), axis=-1)
            total += np.minimum(quarter, facing / MIN_COSINE) / 4.0
    return np.where(mask > 0.5, total, 0.0)


def dense_layers(image, depth, mask, params, distance: str, focal_px: float) -> np.ndarray:
    """One dense blurred image per Gaussian of ``params``, (K, H, W, C).

    ``distance`` is ``"screen"``, ``"surface"`` or ``"integral"`` (surface distance,
    area-weighted and normalised on the tangent plane).
    """
    s_x, s_y = (np.asarray(s, np.float64) for s in stretch_factors(
        depth, float(params.sss_level), float(params.correction), float(params.maxdd)))
    variances = np.asarray(params.variances, np.float64)
    widest = float(np.sqrt(variances.max()) * max(s_x.max(), s_y.max()))
    radius = int(min(MAX_RADIUS_PX, np.ceil(3.0 * widest)))
    points = _points(depth, focal_px) if distance != "screen" else None
    to_model = focal_px / float(params.sss_level)  # scene mm -> the profile's units at this L
    if distance == "integral":
        areas = surface_areas(depth, mask, focal_px)
        slopes = np.gradient(depth)  # the tangent plane's depth per pixel down and across
        plane_area = _plane_area(depth, slopes, focal_px)
    totals = np.zeros((len(variances),) + image.shape, np.float64)
    norms = np.zeros((len(variances),) + depth.shape, np.float64)
    # Offsets outside, Gaussians inside: each offset's distances and shifted images are
    # made once for all the Gaussians (each sum still runs over the offsets in order).
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            if distance == "screen":
                d2 = (dx / s_x) ** 2 + (dy / s_y) ** 2
            else:
                d2 = np.sum((_points(depth, focal_px, dy, dx) - points) ** 2, axis=-1) * to_model**2
            neighbour = _shifted(image, dy, dx)
            if distance == "integral":
                sent = _shifted(areas, dy, dx)
                # The same sum on the tangent plane, and only where the window has skin:
                # past the mask's edge the surface goes on out of sight.
                on_plane = _plane_points(depth, slopes, focal_px, dy, dx) - points
                plane_d2 = np.sum(on_plane**2, axis=-1) * to_model**2
                plane_weight = plane_area * (_shifted(mask, dy, dx) > 0.5)
            for k, v in enumerate(variances):
                weight = np.exp(-d2 / (2.0 * v))
                if distance == "integral":
                    totals[k] += (weight * sent)[..., None] * neighbour
                    norms[k] += plane_weight * np.exp(-plane_d2 / (2.0 * v))
                else:
                    totals[k] += weight[..., None] * neighbour
                    norms[k] += weight
    layers = []
    for total, norm in zip(totals, norms):
        # Off the mask the pixel stays as it is (the integral's sum there may have no skin).
        blurred = np.divide(total, norm[..., None], out=image.astype(np.float64),
                            where=(norm > 0)[..., None] & (mask > 0)[..., None])
        layers.append(image + mask[..., None] * (blurred - image))
    return np.stack(layers)


def pass_layers(image, depth, mask, params) -> np.ndarray:
    """The model's own layers: each Gaussian rendered alone (a one-hot weight)."""
    k = len(np.atleast_1d(params.variances))
    out = []
    for i in range(k):
        one = invsss.SSSParams(params.sss_level, params.correction, params.maxdd, np.eye(k)[i], params.variances)
        out.append(np.asarray(invsss.render(image, depth, mask, one, model="sog"), np.float64))
    return np.stack(out)


def predict(layers: np.ndarray, target: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``sum_i c_i layer_i + b`` per channel, least squares on the mask (weights and gain, as the fit)."""
    on = mask > 0
    out = np.empty(target.shape, np.float64)
    for c in range(target.shape[-1]):
        design = np.concatenate([layers[..., min(c, layers.shape[-1] - 1)][:, on].T, np.ones((int(on.sum()), 1))],
                                axis=1)
        coef, *_ = np.linalg.lstsq(design, target[..., c][on], rcond=None)
        full = np.concatenate([layers[..., min(c, layers.shape[-1] - 1)].reshape(len(layers), -1).T,
                               np.ones((target[..., 0].size, 1))], axis=1)
        out[..., c] = (full @ coef).reshape(target.shape[:2])
    return out


def variant_psnr(pair, fit, variant: str, level: float, scored: np.ndarray) -> float:
    """PSNR of one variant at ``sss_level = level``, the rest of the fit held."""
    params = invsss.SSSParams(level, float(fit.values["correction"]),
                              float(fit.values["maxdd"]), np.asarray(fit.values["weights"]),
                              np.asarray(fit.values["variances"]))
    source, depth, mask = pair["source"].astype(np.float64), pair["depth"].astype(np.float64), pair["mask"]
    terms = fit.light_terms_params()
    buffers = pair["buffers"]
    if terms is not None and "law" in terms.used:
        source = np.asarray(invsss.apply_law(source, mask, np.asarray(terms.law), buffers,
                                             float(terms.law_strength)), np.float64)
    if variant == VARIANTS[0]:
        layers = pass_layers(source, depth, mask, params)
    else:
        distance = {VARIANTS[1]: "screen", VARIANTS[2]: "surface", VARIANTS[3]: "integral"}[variant]
        layers = dense_layers(source, depth, mask, params, distance, pair["info"]["focal_px"])
    if terms is not None and float(terms.shift) != 0.0:
        stretch = stretch_factors(depth, level, params.correction, params.maxdd)
        offsets = propagation_offsets(np.asarray(buffers.light, np.float64))
        layers = np.stack([np.asarray(light_transport(jnp.asarray(x), jnp.asarray(mask), stretch, terms, offsets))
                           for x in layers])
    prediction = predict(layers, pair["target"].astype(np.float64), pair["mask"])
    return score(prediction, pair, scored)["psnr"]


def best_level(pair, fit, variant: str, scored: np.ndarray, evaluations: int = 14) -> tuple[float, float]:
    """Golden-section search of log sss_level within a factor 3 of the fit's; ``(level, psnr)``."""
    centre = float(fit.values["sss_level"])
    a, b = np.log(centre / 3.0), np.log(centre * 3.0)
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    c, d = b - ratio * (b - a), a + ratio * (b - a)
    fc, fd = (variant_psnr(pair, fit, variant, float(np.exp(x)), scored) for x in (c, d))
    for _ in range(evaluations):
        if fc > fd:
            b, d, fd = d, c, fc
            c = b - ratio * (b - a)
            fc = variant_psnr(pair, fit, variant, float(np.exp(c)), scored)
        else:
            a, c, fc = c, d, fd
            d = a + ratio * (b - a)
            fd = variant_psnr(pair, fit, variant, float(np.exp(d)), scored)
    x, f = (c, fc) if fc > fd else (d, fd)
    return float(np.exp(x)), float(f)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pairs", nargs="*", type=pathlib.Path)
    parser.add_argument("--terms", default="shift,law", help="the term set probed beside the plain fit")
    parser.add_argument("--erode", type=int, default=2)
    parser.add_argument("--variants", default=";".join(VARIANTS),
                        help="which of the variants to score, separated by ';' (default: all)")
    args = parser.parse_args()
    variants = [name.strip() for name in args.variants.split(";")]
    unknown = sorted(set(variants) - set(VARIANTS))
    if unknown:
        parser.error(f"--variants: unknown {unknown}; expected some of {list(VARIANTS)}")
    folders = args.pairs
    if not folders:
        from invsss.scenes.split import read_split  # the tuning pairs only: this probe chooses what to build

        split = read_split(pathlib.Path("data_synthetic/SPLIT.toml"))
        folders = sorted(pathlib.Path("data_synthetic") / name for name, part in split.items() if part == "tuning")
    print("| pair | fit | ceiling | " + " | ".join(variants) + " | sss_level (each) |")
    print("|---|---|---|" + "---|" * len(variants) + "---|")
    for folder in folders:
        pair = load_scene_pair(folder)
        scored = eroded(pair["mask"], args.erode)
        ceiling = pair["info"]["noise"]["noise_ceiling_db"]
        for terms in ((), tuple(args.terms.split(","))):
            started = time.perf_counter()
            fit = invsss.fit_pair(pair["source"], pair["target"], pair["depth"], pair["mask"],
                                  light_terms=terms, light_buffers=pair["buffers"] if terms else None)
            found = [best_level(pair, fit, variant, scored) for variant in variants]
            label = "plain" if not terms else "+ " + " + ".join(terms)
            print(f"| {folder.name} | {label} | {ceiling:.2f} | " + " | ".join(f"{p:.2f}" for _, p in found)
                  + " | " + ", ".join(f"{lv:.0f}" for lv, _ in found)
                  + f" |  ({time.perf_counter() - started:.0f} s)", flush=True)


if __name__ == "__main__":
    with jax.enable_x64(True):
        main()
