"""The parameters of the screen-space model, as a pytree."""

from __future__ import annotations

import functools
import warnings

import equinox as eqx
import numpy as np
from jaxtyping import Array, Float

from ..validation import InputNotice, InvalidInputError, is_concrete, number_array
from .arrays import float_array
from .profiles import SumOfGaussians, check_profile_arrays

__all__ = [
    "PARAM_NAMES",
    "entry_name",
    "SSSParams",
    "check_parameter_values",
    "check_plausible",
    "parameter_arrays",
    "DEPTH_UNITS",
    "check_depth_unit",
    "convert_params",
]

#: The depth units a params file records (``depth_unit``), in millimetres each.
#: Millimetres are the recommended unit and the default wherever none is recorded.
DEPTH_UNITS = {"mm": 1.0, "cm": 10.0, "m": 1000.0}

#: The five parameters of the model, in the order of docs/model.md, section 6. Every
#: module that lists them (params files, the estimator, the report, the torch
#: twin) uses this tuple.
PARAM_NAMES = ("sss_level", "correction", "maxdd", "weights", "variances")


def entry_name(name: str, index) -> str:
    """``"weights[2]"`` or ``"weights[2,0]"`` for an entry of an array parameter: how
    a fit's ``undetermined`` list and a params file's filled entries name it."""
    return f"{name}[{','.join(str(int(i)) for i in index)}]"


class SSSParams(eqx.Module):
    """Stretch factors and sum-of-Gaussians profile (docs/model.md, sections 2, 4, 6).

    Parameters
    ----------
    sss_level : float
        ``L`` in ``s = L / (d + c min(|dd|, maxdd))``; pixels per scene unit at unit
        depth (the focal length in pixels for depth in mm and no correction).
    correction : float
        ``c`` >= 0, how strongly a depth slope narrows the blur.
    maxdd : float
        ``delta`` > 0, the slope above which the correction stops growing.
    weights : array, shape (K,) or (K, C)
        Gaussian weights, one per Gaussian or one per Gaussian and channel.
    variances : array, shape (K,)
        Gaussian variances in scene units squared (mm^2).

    Examples
    --------
    >>> import invsss
    >>> p = invsss.SSSParams(0.5, 2000.0, 0.001, [0.4, 0.6], [0.5, 2.0])
    >>> p.num_gaussians
    2
    >>> p
    SSSParams(sss_level=0.5, correction=2000.0, maxdd=0.001, weights=[0.4, 0.6], variances=[0.5, 2.0])
    """

    # Each converter names its field in an error ("sss_level: expected numbers, got the text '600'").
    sss_level: Float[Array, ""] = eqx.field(converter=functools.partial(float_array, name="sss_level"))
    correction: Float[Array, ""] = eqx.field(converter=functools.partial(float_array, name="correction"))
    maxdd: Float[Array, ""] = eqx.field(converter=functools.partial(float_array, name="maxdd"))
    weights: Float[Array, " K *C"] = eqx.field(converter=functools.partial(float_array, name="weights"))
    variances: Float[Array, " K"] = eqx.field(converter=functools.partial(float_array, name="variances"))

    def __repr__(self) -> str:
        # The values, as a user reads them (equinox's default shows only f32[5,3]);
        # under jit/vmap the fields are tracers and the default is all there is.
        from ..validation import is_concrete

        if not all(is_concrete(getattr(self, k)) for k in PARAM_NAMES):
            return super().__repr__()
        # Six significant digits: float32's own, without its binary tails (0.1478, not 0.14779999852).
        short = np.vectorize(lambda x: float(f"{x:.6g}"), otypes=[np.float64])
        values = ", ".join(f"{k}={short(np.asarray(getattr(self, k), np.float64)).tolist()}" for k in PARAM_NAMES)
        return f"SSSParams({values})"

    @property
    def num_gaussians(self) -> int:
        return int(self.variances.shape[-1])

    @property
    def profile(self) -> SumOfGaussians:
        """The weights and variances as a :class:`~invsss.forward.profiles.SumOfGaussians`."""
        return SumOfGaussians(self.weights, self.variances)

    @classmethod
    def from_dict(cls, d: dict, source: str = "params") -> SSSParams:
        """Build from a mapping with the keys of a params JSON file.

        Only the five parameter keys are read; other keys are ignored here.
        :func:`invsss.read_params` is the place that rejects unknown keys in a
        params file.
        """
        params = cls(**parameter_arrays(d, source))  # type: ignore[arg-type]  # the fields' converters take array-likes
        params.check(source)
        return params

    def to_dict(self) -> dict:
        """Plain-Python mapping (lists and floats) suitable for JSON."""
        return {k: np.asarray(getattr(self, k)).tolist() for k in PARAM_NAMES}

    def check(self, name: str = "params") -> None:
        """Raise :class:`InvalidInputError` if the values break the constraints.

        Shapes are static and are checked under ``jit``/``vmap`` too; values
        only when they are concrete.
        """
        from ..validation import is_concrete

        concrete = all(is_concrete(getattr(self, k)) for k in PARAM_NAMES)
        check_parameter_values({k: getattr(self, k) for k in PARAM_NAMES}, name, values=concrete)


def parameter_arrays(d, source: str = "params") -> dict[str, np.ndarray]:
    """The five parameters of mapping ``d`` as float64 NumPy arrays (shapes unchecked).

    Booleans, strings and ragged lists are refused with a message naming the key
    (:func:`invsss.validation.number_array`).
    """
    missing = [k for k in PARAM_NAMES if k not in d]
    if missing:
        raise InvalidInputError(f"{source}: missing key(s) {', '.join(missing)}", field=source)
    return {k: number_array(d[k], k, source) for k in PARAM_NAMES}


def check_parameter_values(params, name: str = "params", *, values: bool = True) -> None:
    """Check a mapping of the five parameters: shapes always, values if ``values``.

    Shared by :class:`SSSParams` and its PyTorch twin so both give the same
    messages; weights and variances go through the same check as a
    :class:`~invsss.forward.profiles.SumOfGaussians` (zero variances allowed here).
    Arrays may be anything ``numpy.asarray`` accepts (or, with
    ``values=False``, anything with a shape, tracers included).
    """
    for k in ("sss_level", "correction", "maxdd"):
        if np.ndim(params[k]) != 0:
            raise InvalidInputError(
                f"{name}: {k} must be a single number, got shape {np.shape(params[k])}",
                field=name,
            )
    if not values:
        check_profile_arrays(
            params["weights"], params["variances"], name, zero_variances=True, values=False
        )
        return
    vals = {k: np.asarray(params[k]) for k in PARAM_NAMES}
    for k in ("sss_level", "correction", "maxdd"):
        if not np.all(np.isfinite(vals[k])):
            raise InvalidInputError(f"{name}: {k} contains NaN or infinite values", field=name)
    check_profile_arrays(vals["weights"], vals["variances"], name, zero_variances=True)
    if vals["sss_level"] <= 0:
        raise InvalidInputError(f"{name}: sss_level must be > 0, got {float(vals['sss_level']):g}", field=name)
    if vals["correction"] < 0:
        raise InvalidInputError(f"{name}: correction must be >= 0, got {float(vals['correction']):g}", field=name)
    if vals["maxdd"] <= 0:
        raise InvalidInputError(f"{name}: maxdd must be > 0, got {float(vals['maxdd']):g}", field=name)


def check_depth_unit(unit, name: str = "depth_unit") -> str:
    """``unit`` if it is one of :data:`DEPTH_UNITS`, else a one-line error.

    Examples
    --------
    >>> check_depth_unit("cm")
    'cm'
    """
    if not isinstance(unit, str) or unit not in DEPTH_UNITS:
        raise InvalidInputError(f"{name}: expected one of {', '.join(DEPTH_UNITS)}, got {unit!r}", field=name)
    return unit


def convert_params(params: SSSParams, from_unit: str, to_unit: str) -> SSSParams:
    """The same blur for depth given in ``to_unit`` instead of ``from_unit``.

    With depth ``k`` times larger in the new unit (``k`` new units per old one),
    ``s = L / (d + c min(|dd|, delta))`` stays the same on the same surface when
    the variances (scene units squared) become ``k^2`` times larger and ``maxdd``
    (a depth step per pixel) ``k`` times: ``L`` and ``c`` do not change
    (docs/model.md, section 2). For ``burley`` the variances are ``d^2``.

    Examples
    --------
    >>> p = convert_params(SSSParams(600.0, 800.0, 0.5, [1.0], [4.0]), "mm", "cm")
    >>> float(p.sss_level), float(p.correction), round(float(p.maxdd), 6), [round(float(v), 6) for v in p.variances]
    (600.0, 800.0, 0.05, [0.04])
    """
    k = DEPTH_UNITS[check_depth_unit(from_unit, "from_unit")] / DEPTH_UNITS[check_depth_unit(to_unit, "to_unit")]
    if k == 1.0:
        return params
    maxdd, variances = np.asarray(params.maxdd, np.float64) * k, np.asarray(params.variances, np.float64) * k * k
    return SSSParams(params.sss_level, params.correction, maxdd, params.weights, variances)  # type: ignore[arg-type]  # the fields' converters take array-likes


#: The distances from a camera to a face that depth in mm is expected to show.
PLAUSIBLE_FACE_DEPTH_MM = (100.0, 5000.0)

#: Blur narrower than this (standard deviation, pixels) changes no pixel visibly.
NARROWEST_USEFUL_BLUR_PX = 0.01


def check_plausible(params: SSSParams, depth, name: str = "params") -> list[str]:
    """Warn (:class:`~invsss.validation.InputNotice`) about values whose blur is absurd here.

    Valid but absurd values (``sss_level: 1e30`` or ``1e-30``, a huge correction)
    render an image that is all one colour or unchanged, with no
    error to say why. At the image's median depth ``d`` (docs/model.md, section 2),
    the widest Gaussian blurs with a standard deviation of ``L sqrt(v_max) / d``
    pixels on a flat surface, and the narrowest with ``L sqrt(v_min) /
    (d + c min(g, delta))`` on the image's steepest depth slope ``g`` (``v_min``
    the smallest non-zero variance). A warning names the values when the first exceeds the image's
    larger side or the second is below ``NARROWEST_USEFUL_BLUR_PX``. Skipped for
    tracers. Returns the warning messages.

    Examples
    --------
    >>> import numpy as np, warnings
    >>> depth = np.full((32, 48), 500.0)
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     check_plausible(SSSParams(1e30, 0.0, 1.0, [1.0], [2.0]), depth, "p.json")
    ['p.json: sss_level 1e+30 blurs by up to 2.8e+27 px at the median depth 500, wider than the 32x48 image']
    >>> check_plausible(SSSParams(600.0, 0.0, 1.0, [1.0], [2.0]), depth)
    []
    """
    arrays = [getattr(params, k) for k in PARAM_NAMES] + [depth]
    if not all(is_concrete(a) for a in arrays):
        return []
    level, correction, maxdd = (float(getattr(params, k)) for k in ("sss_level", "correction", "maxdd"))
    variances = np.asarray(params.variances, dtype=np.float64)
    d = float(np.median(np.asarray(depth)))
    height, width = np.shape(depth)[:2]
    messages = []
    widest = level * np.sqrt(variances.max()) / d
    if widest > max(height, width):
        messages.append(
            f"{name}: sss_level {level:g} blurs by up to {widest:.2g} px at the median depth "
            f"{d:g}, wider than the {height}x{width} image"
        )
    low, high = PLAUSIBLE_FACE_DEPTH_MM
    if 0 < d < low:
        # Parameters fitted on mm and rendered on cm blur 10 times as wide, with no other sign.
        likely = "cm" if d * DEPTH_UNITS["cm"] >= low else "m"
        messages.append(
            f"{name}: the median depth {d:g} would put a face {d:g} mm from the camera (expected "
            f"{low:g}-{high:g} mm); if the depth is in {likely}, give it in the params' unit "
            f"(x{DEPTH_UNITS[likely]:g} for mm, or --depth-unit {likely})"
        )
    positive = variances[variances > 0]
    if positive.size:
        # The steepest slope in the image, capped at maxdd: the most the correction narrows.
        slope = max(float(np.abs(g).max()) for g in np.gradient(np.asarray(depth, np.float64)))
        narrowest = level * np.sqrt(positive.min()) / (d + correction * min(slope, maxdd))
        if narrowest < NARROWEST_USEFUL_BLUR_PX:
            messages.append(
                f"{name}: sss_level {level:g}, correction {correction:g}, maxdd {maxdd:g} give "
                f"passes as narrow as {narrowest:.2g} px at the median depth {d:g} "
                f"(below {NARROWEST_USEFUL_BLUR_PX} px: no visible blur)"
            )
    for message in messages:
        warnings.warn(message, InputNotice, stacklevel=2)
    return messages
