"""The sequence of 7-tap passes a model runs, and each pass's width (docs/model.md, section 5).

Written once against an array namespace (``jax.numpy``, ``numpy`` or ``torch``)
so that the JAX renderer, the PyTorch twin and the shader export derive the
same widths from the same formulas, and each keeps its own sampling. Only
operations the three namespaces share are used: ``argsort(stable=True)``,
``diff(prepend=)``, ``where``, ``sqrt``, ``stack``, ``concatenate``.

A pass along ``axis`` (1 horizontal, 0 vertical) with width ``w`` has footprint
``s * w`` pixels, ``s`` the stretch factor along that axis, so ``w`` is in
scene units (mm) per unit of stretch.
"""

from __future__ import annotations

from typing import Any, NamedTuple

__all__ = ["PassPlan", "pass_plan", "LAYOUTS_WITH_PASSES"]

#: The layouts :func:`pass_plan` builds (see :class:`invsss.forward.models.ScreenSpaceModel`).
LAYOUTS_WITH_PASSES = ("layered", "chained")


class PassPlan(NamedTuple):
    """The passes of one model, in the order they run.

    Attributes
    ----------
    axes : tuple of int
        ``1`` (horizontal) or ``0`` (vertical) per pass; static, it depends on
        the number of Gaussians only.
    widths : array, shape (P,)
        Width per unit stretch of each pass, in the namespace and dtype of the
        variances.
    order : array of int, shape (K,), or None
        ``layered``: the Gaussian each pass pair belongs to (variances sorted,
        stable); ``None`` when the passes follow the given order.
    """

    axes: tuple
    widths: Any
    order: Any


def _safe_sqrt(xp, x):
    # sqrt with derivative 0 at 0: a zero-width pass is the identity and its
    # derivative with respect to the footprint vanishes there, so the true
    # derivative is 0 * inf; its limit 0 is taken instead of a NaN, and sqrt
    # never sees the 0 (where both branches are differentiated).
    positive = x > 0
    return xp.where(positive, xp.sqrt(xp.where(positive, x, 1.0)), 0.0)


def pass_plan(layout: str, variances, spread, xp) -> PassPlan:
    """The passes of a model with pass layout ``layout``, widths per unit stretch.

    ``layered`` (model ``sog``): sort the variances, ``v_0 = 0``; pass pair ``i``
    (horizontal then vertical) has width ``sqrt(v_i - v_{i-1}) / c_W``, so the
    vertical pass of pair ``i`` completes the image blurred by variance ``v_i``.
    ``chained`` (model ``thesis``): K horizontal then K vertical passes, pass
    ``i`` of each run with width ``sqrt(v_i) / c_W``, in the given order.

    Parameters
    ----------
    layout : {"layered", "chained"}
    variances : array, shape (K,)
        Gaussian variances (scene units squared), >= 0, of namespace ``xp``.
    spread : scalar or 0-d array
        The tap weight set's ``c_W`` (:func:`invsss.forward.passes.tap_spread`).
    xp : module
        ``jax.numpy``, ``numpy`` or ``torch``.

    Examples
    --------
    >>> import numpy as np
    >>> plan = pass_plan("layered", np.array([4.0, 1.0]), 0.5, np)
    >>> plan.axes, plan.widths.tolist(), plan.order.tolist()
    ((1, 0, 1, 0), [2.0, 2.0, 3.4641016151377544, 3.4641016151377544], [1, 0])
    >>> plan = pass_plan("chained", np.array([4.0, 1.0]), 0.5, np)
    >>> plan.axes, plan.widths.tolist(), plan.order
    ((1, 1, 0, 0), [4.0, 2.0, 4.0, 2.0], None)
    """
    k = variances.shape[0]
    if layout == "layered":
        order = xp.argsort(variances, stable=True)
        v = variances[order]
        # prepend v[:1] * 0 rather than a literal 0: torch wants a tensor there.
        steps = _safe_sqrt(xp, xp.diff(v, prepend=v[:1] * 0)) / spread
        return PassPlan((1, 0) * k, xp.stack([steps, steps], 1).reshape(-1), order)
    if layout == "chained":
        steps = _safe_sqrt(xp, variances) / spread
        return PassPlan((1,) * k + (0,) * k, xp.concatenate([steps, steps]), None)
    raise ValueError(f"layout: expected one of {', '.join(LAYOUTS_WITH_PASSES)}, got {layout!r}")
