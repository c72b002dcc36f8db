"""How wide the fitted blur is on the image, with its standard error: what the pixels measured.

Every model blurs by a profile whose per-axis second moment, in scene units squared, is

* ``sog``: ``sum_k w_kc v_k / sum_k w_kc`` (a mixture of Gaussians);
* ``separable``: that of its N-tap kernel, ``sum_n k_nc o_n^2`` (the kernel spans a
  fixed range of scene units, so a wide profile is cut off);
* ``thesis``: ``sum_k v_k`` (its passes are chained, so their variances add);
* ``burley``: ``7 d_c^2`` (Burley's profile, docs/model.md, section 5),

and the stretch ``s = L / (d + c min(|dd|, delta))`` turns scene units into
pixels. At the skin's median depth and median slope the blur's RMS width per axis
is ``sigma_px = s sqrt(m2)``, per channel. It is what a pair can measure whatever
the gauge: the split between ``L`` and the profile's scale is a convention, its
product is not. Its standard error comes from the fit's covariance by the delta
method (:func:`invsss.estimator.uncertainty.derived_stderr`).

A blur under about a pixel is below what the pixels resolve: demosaicking, the
lens and the pixel's own area blur by that much, so its shape and, on a photograph,
its size are not a measurement (issue 47: a 0.3-0.7 px blur fitted at full and half
resolution disagreed by 40 %). :data:`RESOLVED_PX` is that limit.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..forward.models import get_model
from ..forward.screen_space import separable_kernel
from .uncertainty import derived_stderr

__all__ = ["RESOLVED_PX", "second_moment", "blur_width_px", "blur_record", "under_a_pixel_warning", "blur_line"]

#: The narrowest RMS width (px per axis) taken as measured rather than unresolved.
RESOLVED_PX = 1.0


def second_moment(model: str, weights, variances, xp=jnp):
    """Per-axis second moment of the model's profile per channel (scene units^2), shape (C,).

    Examples
    --------
    >>> import numpy as np
    >>> second_moment("sog", np.array([1.0, 3.0]), np.array([2.0, 6.0]), np).tolist()
    [5.0]
    >>> second_moment("thesis", np.array([1.0, 3.0]), np.array([2.0, 6.0]), np).tolist()
    [8.0]
    >>> second_moment("burley", np.ones(3), np.array([1.0, 0.25, 0.04]), np).tolist()
    [7.0, 1.75, 0.28]
    """
    layout = get_model(model).layout
    v = xp.asarray(variances)
    if layout == "disk":
        return 7.0 * v
    if layout == "chained":
        return xp.sum(v)[None]
    if layout == "kernel":
        # The kernel the model renders with (its default 17 taps), not the untruncated profile.
        offsets, kernel = separable_kernel(jnp.asarray(weights), jnp.asarray(variances))
        return xp.asarray(jnp.sum(kernel * offsets[:, None] ** 2, axis=0))
    w = xp.asarray(weights)
    w = w[:, None] if w.ndim == 1 else w
    return xp.sum(w * v[:, None], axis=0) / xp.sum(w, axis=0)


def blur_width_px(model: str, values: dict, depth: float, slope: float, xp=jnp):
    """``sigma_px`` per channel: the RMS width per axis at ``depth`` and depth ``slope`` (per pixel).

    Examples
    --------
    >>> import numpy as np
    >>> values = {"sss_level": 600.0, "correction": 0.0, "maxdd": 1.0,
    ...           "weights": np.array([1.0]), "variances": np.array([4.0])}
    >>> blur_width_px("sog", values, 600.0, 0.5, np).tolist()
    [2.0]
    """
    stretch = values["sss_level"] / (depth + values["correction"] * xp.minimum(slope, values["maxdd"]))
    return stretch * xp.sqrt(second_moment(model, values["weights"], values["variances"], xp))


def blur_record(model: str, natural: dict, depth: float, slope: float, unc, focal_px=None) -> dict:
    """The fit's blur width per channel, its standard error and whether the pixels resolve it.

    With the camera's focal length ``focal_px`` (pixels) the widths are also given
    in mm on the skin: a pixel covers ``depth / focal_px`` of it at that depth
    (depth in mm).

    Returns
    -------
    dict
        ``sigma_px`` (list, one per channel), ``stderr_px`` (list; None where
        undetermined), ``depth`` and ``slope`` (where it is evaluated: the
        skin's median depth and median slope), ``resolved`` (every channel at
        least :data:`RESOLVED_PX`); with ``focal_px`` also ``mm_per_px``,
        ``sigma_mm`` and ``stderr_mm``.
    """
    names = ("sss_level", "correction", "maxdd", "weights", "variances")
    with jax.enable_x64(True):
        values = {k: jnp.asarray(np.asarray(natural[k], np.float64)) for k in names}
        widths = np.asarray(blur_width_px(model, values, depth, slope), np.float64)
        jac = jax.jacfwd(lambda v: blur_width_px(model, v, depth, slope))(values)
    stderr = []
    for c in range(widths.size):
        std, undetermined = derived_stderr(unc, {k: np.asarray(jac[k])[c] for k in names})
        stderr.append(None if undetermined or not np.isfinite(std) or std > widths[c] else std)
    record = {"sigma_px": widths.tolist(), "stderr_px": stderr, "depth": float(depth), "slope": float(slope),
              "resolved": bool(np.all(widths >= RESOLVED_PX))}
    if focal_px is not None:
        mm = float(depth) / float(focal_px)
        record.update(mm_per_px=mm, sigma_mm=(widths * mm).tolist(),
                      stderr_mm=[None if e is None else e * mm for e in stderr])
    return record


def under_a_pixel_warning(record: dict) -> str | None:
    """The warning for a blur the pixels do not resolve, or None.

    Examples
    --------
    >>> print(under_a_pixel_warning({"sigma_px": [0.32], "resolved": False, "depth": 600.0}))
    blur: 0.32 px (RMS per axis at the skin's median depth 600) is under a pixel: the pixels do not resolve it, so its size and shape are not a measurement; photograph more pixels per mm of skin (a closer or longer lens)
    """  # noqa: E501
    if record["resolved"]:
        return None
    widths = "/".join(f"{w:.2g}" for w in record["sigma_px"])
    return (
        f"blur: {widths} px (RMS per axis at the skin's median depth {record['depth']:g}) is under a pixel: "
        "the pixels do not resolve it, so its size and shape are not a measurement; photograph more "
        "pixels per mm of skin (a closer or longer lens)"
    )


def _with_error(values, errors, unit: str) -> str:
    parts = [f"{v:.3g}" + ("" if e is None else f" \u00b1 {e:.2g}") for v, e in zip(values, errors)]
    return " / ".join(parts) + f" {unit}"


def blur_line(record: dict | None, depth_unit: str | None = None) -> str | None:
    """One line for people: the blur's width in pixels (and mm), with errors, and the
    depth it is measured at (in ``depth_unit`` when the caller knows it).

    Examples
    --------
    >>> blur_line({"sigma_px": [2.5], "stderr_px": [0.1], "depth": 600.0, "resolved": True,
    ...            "mm_per_px": 0.5, "sigma_mm": [1.25], "stderr_mm": [0.05]}, "mm")
    'blur 2.5 \u00b1 0.1 px (1.25 \u00b1 0.05 mm) RMS per axis at depth 600 mm'
    """
    if not record:
        return None
    text = "blur " + _with_error(record["sigma_px"], record["stderr_px"], "px")
    if record.get("sigma_mm") is not None:
        text += " (" + _with_error(record["sigma_mm"], record["stderr_mm"], "mm") + ")"
    text += f" RMS per axis at depth {record['depth']:g}" + (f" {depth_unit}" if depth_unit else "")
    return text + ("" if record["resolved"] else ": under a pixel, not resolved")
