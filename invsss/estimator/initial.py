"""Reference scales from the data, and the starting points of a multi-start fit.

The blur scale is the hard part of the fit: with the wrong one by a factor of a
few, the loss is flat or has the wrong basin, and near the right one it is
bumpy. So before any solver runs, the compiled loss (a forward model plus the
small projection, about a millisecond at 64 x 64) is scanned along the blur
scale, and the starts are its lowest local minima, each with the best
correction and maxdd of a small grid (see :func:`choose_starts`).

The blur scale is ``L`` in the default gauge and a common factor on all variances
in the ``sss_level`` gauge; the grid spans a widest-Gaussian blur of 0.25 pixel
to a quarter of the image.
"""

from __future__ import annotations

import equinox as eqx
import numpy as np

from ..forward.stretch import depth_slopes, stretch_along
from .parametrisation import softplus_inverse

__all__ = ["DataScales", "data_scales", "blur_reference", "choose_starts"]

_BLUR_GRID = 40
_CORRECTION_GRID = (0.01, 0.1, 0.5, 2.0)  # in units of the reference correction
_MAXDD_PERCENTILES = (15.0, 50.0, 85.0)


class DataScales(eqx.Module):
    """What the estimator needs to know about the masked depth (NumPy, not traced).

    ``depths``, ``slopes_x`` and ``slopes_y`` hold every masked pixel of every pair.
    """

    depths: np.ndarray
    slopes_x: np.ndarray
    slopes_y: np.ndarray
    size: int  # smallest image side
    mask_diameter: float = np.inf  # the smallest pair's mask as a disc of equal area (px)

    @property
    def slopes(self) -> np.ndarray:
        """All masked slopes, x then y."""
        return np.concatenate([self.slopes_x, self.slopes_y])

    @property
    def depth(self) -> float:
        """Median masked depth."""
        return float(np.median(self.depths))

    @property
    def slope(self) -> float:
        """Median positive masked slope (depth units per pixel); on flat depth, where
        correction and maxdd have no effect, an arbitrary 1e-3 of the depth."""
        positive = self.slopes[self.slopes > 0]
        return float(np.median(positive)) if positive.size else 1e-3 * self.depth

    @property
    def correction(self) -> float:
        """The correction at which ``c * slope`` equals the depth."""
        return self.depth / self.slope

    def stretch_range(self, sss_level, correction, maxdd) -> tuple[float, float]:
        """The smallest and largest stretch factor over the masked pixels, both axes (px per mm)."""
        sx = stretch_along(self.depths, self.slopes_x, sss_level, correction, maxdd, xp=np)
        sy = stretch_along(self.depths, self.slopes_y, sss_level, correction, maxdd, xp=np)
        return float(min(sx.min(), sy.min())), float(max(sx.max(), sy.max()))

    def max_stretch(self, sss_level, correction, maxdd) -> float:
        """The largest stretch factor over the masked pixels (pixels per mm)."""
        return self.stretch_range(sss_level, correction, maxdd)[1]


def data_scales(pairs) -> DataScales:
    depths, slopes_x, slopes_y = [], [], []
    for p in pairs:
        keep = np.asarray(p.mask) > 0
        depths.append(np.asarray(p.depth)[keep])
        sx, sy = depth_slopes(np.asarray(p.depth, np.float64))  # type: ignore[arg-type]  # JAX takes NumPy arrays
        slopes_x.append(np.asarray(sx)[keep])
        slopes_y.append(np.asarray(sy)[keep])
    size = min(min(p.depth.shape) for p in pairs)
    area = min(float(np.sum(np.asarray(p.mask) > 0)) for p in pairs)
    return DataScales(np.concatenate(depths), np.concatenate(slopes_x), np.concatenate(slopes_y), int(size),
                      2.0 * float(np.sqrt(area / np.pi)))


def blur_reference(scales: DataScales, variances) -> float:
    """The ``L`` that blurs the widest Gaussian by 2 pixels at the median depth."""
    return 2.0 * scales.depth / float(np.sqrt(np.max(variances)))


def _with(param, z_base, **blocks):
    """``z_base`` with the named scalar (or uniformly filled) blocks replaced."""
    parts = param.split(np.asarray(z_base, np.float64))
    out = []
    for name, _shape in param.blocks:
        u = np.array(parts[name], dtype=np.float64)
        if name in blocks:
            u[...] = blocks[name]
        out.append(u.ravel())
    return np.concatenate(out) if out else np.zeros(0)


def choose_starts(losses, param, scales: DataScales, blur_at_zero: float | None, z_base, n_starts: int):
    """Starting unknown vectors, best first.

    Stage 1 scans the blur scale alone (correction at a tenth of its reference,
    maxdd at the median slope) on a fine log grid: the loss is bumpy in the blur
    scale (the 7 taps alias with the pixel grid, most on flat depth), so the starts
    are the ``n_starts`` lowest *local minima* of that profile, topped up with
    the best remaining points. Stage 2 picks, for each, the best correction (0.01
    to 2 times its reference) and maxdd (15th, 50th, 85th percentile of the masked
    slopes), one axis after the other.

    ``losses(points)`` evaluates the objective at a list of unknown vectors and
    returns their losses in order. The points of one call do not depend on each
    other's losses, so it may evaluate them concurrently: three calls in all
    (the blur grid, the corrections of every start, their maxdd values).
    """
    blocks = dict(param.blocks)
    c_mid = {"correction": float(softplus_inverse(0.1))} if "correction" in blocks else {}
    d_mid = {"maxdd": 0.0} if "maxdd" in blocks else {}
    if blur_at_zero is None:
        starts = [_with(param, z_base, **c_mid, **d_mid)]
    else:
        points = blur_grid(param, scales, blur_at_zero, _with(param, z_base, **c_mid, **d_mid))
        profile = _finite(losses(points))
        order = profile_minima(profile)
        order += [i for i in np.argsort(profile) if i not in order]
        starts = [points[i] for i in order[:n_starts]]
    if not c_mid and not d_mid:
        return starts
    c_axis = list(softplus_inverse(np.asarray(_CORRECTION_GRID))) if c_mid else [None]
    d_axis = [None]
    if d_mid:
        positive = scales.slopes[scales.slopes > 0]
        values = np.percentile(positive, _MAXDD_PERCENTILES) if positive.size else np.array([scales.slope])
        d_axis = list(np.log(np.unique(values) / scales.slope))

    # One axis at a time: correction at the middle maxdd, then maxdd at the best
    # correction (6 losses a start instead of 12). On the seven bundled pairs the
    # fits end at the same estimates as with the whole grid. Each axis is one
    # call of ``losses`` for all the starts together.
    middle = len(d_axis) // 2
    d_middle: dict = {} if d_axis[0] is None else {"maxdd": d_axis[middle]}
    by_correction = [
        [_with(param, z, **({} if c is None else {"correction": c}), **d_middle) for c in c_axis] for z in starts
    ]
    best = [_lowest(points, scores) for points, scores in zip(by_correction, _rows(losses, by_correction))]
    others = [d for i, d in enumerate(d_axis) if i != middle and d is not None]
    by_maxdd = [[_with(param, point, maxdd=d) for d in others] for point, _ in best]
    return [
        _lowest([point, *points], [score, *scores])[0]
        for (point, score), points, scores in zip(best, by_maxdd, _rows(losses, by_maxdd))
    ]


def blur_grid(param, scales: DataScales, blur_at_zero: float, z_base) -> list:
    """``z_base`` at each blur scale of the start scan's grid (a fine log grid of
    blur widths from a quarter pixel to a quarter of the image), every other
    unknown as ``z_base`` has it."""
    sigmas = np.geomspace(0.25, max(scales.size / 4.0, 1.0), _BLUR_GRID)
    blur = np.log(sigmas / blur_at_zero)
    name = "sss_level" if "sss_level" in dict(param.blocks) else "variances"
    return [_with(param, z_base, **{name: b if name == "sss_level" else 2.0 * b}) for b in blur]


def profile_minima(profile) -> list[int]:
    """The local minima of a loss profile along the blur grid, lowest first (an
    end of the grid counts when its one neighbour is not lower)."""
    padded = np.concatenate([[np.inf], profile, [np.inf]])
    minima = [i for i in range(len(profile)) if padded[i + 1] <= min(padded[i], padded[i + 2])]
    return sorted(minima, key=lambda i: profile[i])


def _finite(scores) -> np.ndarray:
    # A non-finite loss never wins.
    scores = np.asarray(scores, np.float64)
    return np.where(np.isfinite(scores), scores, np.inf)


def _lowest(points, scores):
    """The point with the lowest loss (the first of equals), and that loss."""
    scores = _finite(scores)
    k = int(np.argmin(scores))
    return points[k], scores[k]


def _rows(losses, table) -> list:
    """``losses`` of every point of a list of lists, in one call, as rows again."""
    flat = losses([point for row in table for point in row])
    out, first = [], 0
    for row in table:
        out.append(list(flat[first:first + len(row)]))
        first += len(row)
    return out
