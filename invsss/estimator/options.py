"""The settings of a fit, checked once: :class:`FitOptions`.

Everything that says *how* to fit (model, profile, gauge, solver, ...) lives in one
frozen value, validated when it is made, so that :func:`~invsss.estimator.build_problem`
and the fit itself never re-check a setting and a bad one fails before any image
is read. The callbacks (``progress``, ``stop``) are not options: they belong to
one run, not to the recipe.
"""

from __future__ import annotations

import dataclasses
import numbers
import os
import types

import jax
import numpy as np

from ..forward.light_terms import LIGHT_TERM_NAMES
from ..forward.models import get_model
from ..forward.passes import tap_weights as tap_weight_set
from ..validation import InvalidInputError
from .parametrisation import GAUGES, assign_roles, check_fix, resolve_profile
from .robust import check_robust
from .solve import SOLVERS

__all__ = ["FitOptions", "check_canvas"]


def check_canvas(canvas) -> tuple[int, int]:
    """``canvas`` as a (height, width) tuple of ints >= 1, or a one-line error.

    Examples
    --------
    >>> check_canvas([256, 320])
    (256, 320)
    >>> check_canvas((256,))
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: canvas: expected (height, width), two integers >= 1, got (256,)
    """
    ok = (
        isinstance(canvas, (tuple, list)) and len(canvas) == 2
        and all(isinstance(n, numbers.Integral) and not isinstance(n, bool) and n >= 1 for n in canvas)
    )
    if not ok:
        raise InvalidInputError(f"canvas: expected (height, width), two integers >= 1, got {canvas!r}")
    return int(canvas[0]), int(canvas[1])


# eq=False: ``fix`` holds arrays, whose == is elementwise, so value equality
# would raise for a fixed weight or variance list; options compare by identity.
@dataclasses.dataclass(frozen=True, eq=False)
class FitOptions:
    """How to fit: the keyword options of :func:`invsss.fit_pair`, checked once.

    Parameters
    ----------
    model : {"sog", "thesis", "separable"}
    profile : str, path, mapping or SumOfGaussians
        The sum-of-Gaussians profile (its variances are held in the default gauge;
        it gives the number of Gaussians and the starting weights).
    fix : mapping, optional
        Parameters held at given values, e.g. ``{"maxdd": 0.01}``. Stored as a
        read-only mapping of float64 arrays.
    gauge : {"variances", "sss_level"}
    solver : {"lm", "gauss-newton", "bfgs"}
    n_starts : int >= 1
    max_steps : int >= 1
        Solver steps per start and per refinement round.
    tap_weights : {"jimenez", "thesis"}, 7 numbers or None
        None picks the model's default set (:attr:`invsss.forward.models.ScreenSpaceModel.default_tap_weights`).
    robust : {"pseudo-huber", "cauchy"} or None
        ``"none"`` and False are stored as None.
    align : {"none", "translation", "similarity", "affine"}
        Register the target onto the source inside the fit (:mod:`invsss.estimator.registration`).
    vignetting : bool
        Fit the camera's radial fall-off as a gain field (:mod:`invsss.estimator.vignetting`).
    highlights : bool
        Refit with the first fit's specular highlights left out (see :func:`invsss.fit_pair`).
    saturation : float > 0 or None
        Target level at or above which a pixel is clipped and left out of the fit.
    light_terms : tuple of str
        Light-aware terms in the model (:data:`invsss.forward.light_terms.LIGHT_TERM_NAMES`:
        ``"shift"``, ``"grazing"``, ``"incidence"``, ``"law"``), stored as a tuple in
        that order. Given as names (a list, or a comma-separated string), each term
        is fitted; given as a mapping ``{name: value}`` (or ``"shift=1.3,grazing"``),
        a term with a number is held at it and one with None is fitted (``law``
        takes one albedo or one per source channel, ``"law=0.93/0.8/0.7"`` in a
        string). Each needs its buffers on every pair.
    light_fixed : mapping
        The held values (filled from ``light_terms``; read-only).
    canvas : (int, int) or None
        Pad every pair to this (height, width) before fitting, so that pairs of
        different sizes share one compilation (:mod:`invsss.estimator.canvas`):
        the estimate is the one at the pair's own size. A pair the padding
        would change is fitted at its own size, with a warning.

    Raises
    ------
    InvalidInputError
        Any field out of range, with the field's name in a one-line message.

    Examples
    --------
    >>> from invsss.estimator import FitOptions
    >>> options = FitOptions(n_starts=2, fix={"maxdd": 1.0})
    >>> options.n_starts, float(options.fix["maxdd"]), options.tap_label
    (2, 1.0, 'jimenez')
    >>> FitOptions(solver="adam")
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: solver: expected one of lm, gauss-newton, bfgs, got 'adam'
    """

    model: str = "sog"
    profile: object = "thesis-nir"
    fix: object = None
    gauge: str = "variances"
    solver: str = "lm"
    n_starts: int = 4
    max_steps: int = 200
    tap_weights: object = None
    robust: str | None = "pseudo-huber"
    align: str = "none"
    vignetting: bool = False
    highlights: bool = False
    saturation: float | None = None
    light_terms: tuple = ()
    light_fixed: object = None
    canvas: tuple | None = None

    def __post_init__(self):
        from .registration import ALIGN_KINDS

        if self.canvas is not None:
            object.__setattr__(self, "canvas", check_canvas(self.canvas))

        if self.align not in ("none", *ALIGN_KINDS):
            raise InvalidInputError(f"align: expected one of none, {', '.join(ALIGN_KINDS)}, got {self.align!r}")
        for name in ("vignetting", "highlights"):
            if not isinstance(getattr(self, name), bool):
                raise InvalidInputError(f"{name}: expected true or false, got {getattr(self, name)!r}")
        if self.saturation is not None:
            level = self.saturation
            if isinstance(level, bool) or not isinstance(level, numbers.Real) or not np.isfinite(level) or level <= 0:
                raise InvalidInputError(f"saturation: expected a number > 0 or None, got {level!r}")
            object.__setattr__(self, "saturation", float(level))
        terms, held = check_light_terms(self.light_terms)
        if self.light_fixed:
            held = {**held, **check_light_terms(dict(self.light_fixed))[1]}
        object.__setattr__(self, "light_terms", tuple(t for t in LIGHT_TERM_NAMES if t in terms or t in held))
        object.__setattr__(self, "light_fixed", types.MappingProxyType(held))
        get_model(self.model)  # one-line error naming the known models
        if self.gauge not in GAUGES:
            raise InvalidInputError(f"gauge: expected one of {', '.join(GAUGES)}, got {self.gauge!r}")
        if self.solver not in SOLVERS:
            raise InvalidInputError(f"solver: expected one of {', '.join(SOLVERS)}, got {self.solver!r}")
        for name in ("n_starts", "max_steps"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
                raise InvalidInputError(f"{name}: expected an integer >= 1, got {value!r}")
            object.__setattr__(self, name, int(value))
        object.__setattr__(self, "robust", check_robust(self.robust))
        fixed = check_fix(self.fix)
        object.__setattr__(self, "fix", types.MappingProxyType(fixed))
        assign_roles(self.model, self.gauge, fixed)  # gauge and fix= must agree
        self.taps()
        # The profile is read in float64 (a float32 copy would round the variances).
        with jax.enable_x64(True):
            resolve_profile(self.profile)

    def _tap_spec(self):
        # The model's own set by default; a model without 7-tap passes
        # (separable) ignores them, and "jimenez" stands in for the array.
        if self.tap_weights is not None:
            return self.tap_weights
        return get_model(self.model).default_tap_weights or "jimenez"

    def taps(self, dtype=None):
        """The 7 tap weights as a JAX array (``dtype`` default: JAX's default float)."""
        spec = self._tap_spec()
        try:
            return tap_weight_set(spec, dtype)
        except (ValueError, TypeError) as err:
            raise InvalidInputError(str(err)) from None

    @property
    def tap_label(self):
        """The tap weights as a params file writes them: a set's name or 7 numbers."""
        if isinstance(self._tap_spec(), str):
            return self._tap_spec()
        return np.asarray(self._tap_spec(), np.float64).tolist()  # checked in __post_init__

    @property
    def profile_label(self) -> str:
        """The profile's name or path ("" for a profile given as numbers)."""
        return os.fspath(self.profile) if isinstance(self.profile, (str, os.PathLike)) else ""


def _held_number(name, value) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InvalidInputError(f"light_terms[{name!r}]: expected a number or None (fitted), got {value!r}") from None
    if not np.isfinite(number) or (name in ("grazing", "incidence") and number <= -1.0):
        raise InvalidInputError(
            f"light_terms[{name!r}]: expected a finite number"
            f"{' > -1' if name in ('grazing', 'incidence') else ''}, got {value!r}"
        )
    return number


def _held_albedo(value) -> float | tuple[float, ...]:
    """A held ``law`` albedo: one number in (0, 1), or one per channel (a sequence,
    or a string such as ``"0.93/0.8/0.7"``)."""
    parts = value.split("/") if isinstance(value, str) else value
    try:
        w = np.asarray(parts, np.float64)
    except (TypeError, ValueError):
        w = None
    if w is None or w.ndim > 1 or w.size == 0 or not np.all(np.isfinite(w)) or np.any((w <= 0) | (w >= 1)):
        raise InvalidInputError(
            f"light_terms['law']: expected an albedo in (0, 1) or one per channel (e.g. 0.93/0.8/0.7), "
            f"or None (fitted), got {value!r}"
        )
    return float(w) if w.ndim == 0 else tuple(float(x) for x in w)


def check_light_terms(terms) -> tuple[tuple[str, ...], dict[str, float]]:
    """``(names, held)``: the terms in canonical order and the values of those held fixed.

    ``terms``: names (a sequence, or one comma-separated string; "none" or empty
    for none), a mapping ``{name: value or None}``, or a string mixing both
    (``"shift=1.3,grazing"``).

    Examples
    --------
    >>> check_light_terms("grazing, shift")
    (('shift', 'grazing'), {})
    >>> check_light_terms("shift=1.3,grazing")
    (('shift', 'grazing'), {'shift': 1.3})
    >>> check_light_terms("shift,law=0.93/0.8/0.7")
    (('shift', 'law'), {'law': (0.93, 0.8, 0.7)})
    """
    if terms is None:
        return (), {}
    if isinstance(terms, str):
        parts = [] if terms.strip() in ("", "none") else [t.strip() for t in terms.split(",")]
        entries = {}
        for part in parts:
            name, _, value = part.partition("=")
            entries[name.strip()] = value.strip() if value else None
    elif hasattr(terms, "items"):
        entries = dict(terms)
    else:
        try:
            entries = dict.fromkeys(terms)
        except TypeError:
            raise InvalidInputError(f"light_terms: expected names of terms, got {terms!r}") from None
    unknown = [t for t in entries if t not in LIGHT_TERM_NAMES]
    if unknown:
        raise InvalidInputError(
            f"light_terms: unknown term(s) {', '.join(map(repr, unknown))}; expected some of "
            + ", ".join(LIGHT_TERM_NAMES)
        )
    held = {}
    for name, value in entries.items():
        if value is None:
            continue
        held[name] = _held_albedo(value) if name == "law" else _held_number(name, value)
    return tuple(t for t in LIGHT_TERM_NAMES if t in entries), held
