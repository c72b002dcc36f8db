"""docs/model.md's formulas written out again for the model-table tests (the tap sets,
their spread, the pass plan), and a scene and parameters that every model renders."""

from __future__ import annotations

import math

import numpy as np

# docs/model.md, section 3, typed in again.
TAPS = {
    "jimenez": [0.006, 0.061, 0.242, 0.382, 0.242, 0.061, 0.006],
    "thesis": [0.1053, 0.1402, 0.1664, 0.1762, 0.1664, 0.1402, 0.1053],
}


def spread(name):
    return math.sqrt(sum(w * (k / 3.0) ** 2 for w, k in zip(TAPS[name], range(-3, 4))))


def scene(size=14, seed=3):
    """Texture on depth whose x-slope runs from 0 to above maxdd=3, so that
    correction and maxdd both change the stretch somewhere."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    depth = 400.0 + 0.25 * x**2 + 0.5 * y
    image = rng.random((size, size, 3))
    return image, depth, np.ones((size, size))


# Three Gaussians: the burley model reads the three variances as d^2 per channel.
BASE = dict(sss_level=600.0, correction=50.0, maxdd=3.0, weights=[0.3, 0.5, 0.2], variances=[1.0, 4.0, 0.5])
# One change per parameter; the weights change their ratio (only ratios matter in sog).
CHANGED = dict(sss_level=700.0, correction=80.0, maxdd=1.5, weights=[0.5, 0.3, 0.2], variances=[1.5, 3.0, 0.7])


def expected_plan(layout, variances, c_w):
    """docs/model.md, section 5 with loops: (axes, widths, order or None)."""
    k = len(variances)
    if layout == "layered":
        order = sorted(range(k), key=lambda i: variances[i])  # Python's sort is stable
        axes, widths, previous = [], [], 0.0
        for i in order:
            w = math.sqrt(variances[i] - previous) / c_w
            axes += [1, 0]
            widths += [w, w]
            previous = variances[i]
        return tuple(axes), widths, order
    widths = [math.sqrt(v) / c_w for v in variances]
    return (1,) * k + (0,) * k, widths + widths, None
