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
from ..forward.models import MODEL_NAMES, get_model
from ..forward.passes import tap_weights as tap_weight_set
from ..forward.profiles import PROFILE_NAMES
from ..validation import InvalidInputError
from .option_text import canvas_from_text, fix_from_text, saturation_from_text
from .parametrisation import GAUGES, assign_roles, check_fix, resolve_profile
from .pigment import DEGREES as PIGMENT_DEGREES
from .robust import check_robust
from .solve import JACOBIANS, SOLVERS

__all__ = ["TERM_STARTS", "FitOptions", "check_canvas"]

#: Where a fit with light terms may start (:attr:`FitOptions.term_starts`).
TERM_STARTS = ("auto", "plain", "scan")


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
        and all(isinstance(n, numbers.Integral) and not isinstance(n, bool) and int(n) >= 1 for n in canvas)
    )
    if not ok:
        raise InvalidInputError(f"canvas: expected (height, width), two integers >= 1, got {canvas!r}", field="canvas")
    return int(canvas[0]), int(canvas[1])


def _option(default, help: str, *, flag: str | None = "", parse=None, cli_default=dataclasses.MISSING,
            choices=None, **argparse_keywords):
    """A :class:`FitOptions` field: its default, and how the command line spells it.

    ``flag``: the command line's flag ("" for ``--`` and the field's name with
    dashes, None for a field the command line does not offer); ``parse``: text ->
    the field's value; ``cli_default``: the command line's default where its text
    differs from the field's; ``choices``: a callable giving the allowed values;
    the rest goes to :meth:`argparse.ArgumentParser.add_argument`.
    """
    metadata = {"help": help, "flag": flag, "parse": parse, "choices": choices,
                "cli_default": default if cli_default is dataclasses.MISSING else cli_default,
                "argparse": argparse_keywords}
    return dataclasses.field(default=default, metadata=metadata)


def _align_kinds() -> dict[str, int]:
    # Imported when first needed: registration pulls in scikit-image.
    from .registration import ALIGN_KINDS

    return ALIGN_KINDS


# eq=False: ``fix`` holds arrays, whose == is elementwise, so value equality
# would raise for a fixed weight or variance list; options compare by identity.
@dataclasses.dataclass(frozen=True, eq=False)
class FitOptions:
    """How to fit: the options of :func:`invsss.fit_pair`, checked once.

    :func:`~invsss.fit_pair` and :func:`~invsss.fit_pairs` take these fields as
    keywords or as one ``options=FitOptions(...)``; ``invsss fit`` as flags (each
    field's metadata) and an experiment file as its fit options.

    Parameters
    ----------
    model : {"sog", "thesis", "separable", "burley"}
    profile : str, path, mapping or SumOfGaussians
        Sum-of-Gaussians profile: in the default gauge its variances are fixed; it
        also gives the number of Gaussians and the starting values.
    fix : dict, optional
        Parameters to hold at given values, e.g. ``{"maxdd": 0.01}`` or
        ``{"sss_level": 1200.0}``.
    gauge : {"auto", "variances", "sss_level", "depth"}
        Which side of the ``L`` / variance-scale degeneracy is fixed: the profile's
        variances, or ``sss_level`` (must be given in ``fix``; the variances are
        then estimated); ``depth`` fixes neither, for a model whose depth weighting
        separates them (``burley``). ``auto`` (default): the model's own
        (``variances``, ``depth`` for ``burley``); the fit reports the one used.
    solver : {"lm", "gauss-newton", "bfgs"}
    n_starts : int
        Number of starting points (best grid points of a coarse search).
    max_steps : int
        Maximum solver steps per start and per refinement.
    solver_jacobian : {"differences", "forward-mode"}
        How the solvers differentiate the blur: by forward differences (the
        default, 0.64-0.77 of forward mode's time per step) or by forward mode.
        The standard errors use forward mode either way.
    stall_test : bool
        Stop a solve when its accepted losses stall within the noise (the
        default); False runs each solve to its own convergence test or
        ``max_steps`` (experiments/bench_fit.py --stopping compares the two).
    tap_weights : {"jimenez", "thesis"} or 7 numbers, optional
        Default "thesis" for the thesis model, else "jimenez".
    robust : {"pseudo-huber", "cauchy"} or None
        Robust loss by iterative reweighting (see :mod:`invsss.estimator.robust`).
    align : {"none", "translation", "similarity", "affine"}
        Register the pair as part of the fit, for photographs that are not
        pixel-aligned with their render. The warp (source pixels to target pixels)
        is estimated against the photometrically matched source; the source, depth
        and mask are resampled onto the target's grid (the noisy target never is:
        see :mod:`invsss.estimator.registration`) and fitted; the warp is refined against
        that fit's prediction (which carries the blur, so the blur does not bias
        the warp), alternating (at most 4 rounds, each a one-start fit of at most
        30 steps per solve from the previous round's estimate) until the warp
        moves less than 0.01 px, and the pair fitted again. The warp is in
        :attr:`FitResult.alignment` and the fitted images are on the target's grid.
        The standard errors count the warp as estimated too (its parameters join the
        covariance as nuisance unknowns; their own standard errors are in the
        alignment record). Target pixels that come from
        outside the source's frame leave the mask. Two to five times the time of a fit.
    vignetting : bool
        Fit the camera's fall-off toward the corners as a gain field
        ``1 + a_1 rho^2 + a_2 rho^4`` about the frame's centre
        (:mod:`invsss.estimator.vignetting`), for photographs; reported in
        :attr:`FitResult.vignetting`, and the standard errors account for it.
    highlights : bool
        Leave specular highlights out: after the fit, pixels where the target is
        brighter than the prediction by more than :data:`~invsss.estimator.stages.highlights.HIGHLIGHT_SIGMAS` robust
        standard deviations of the residual (smoothed over 1 px; dilated by 1 px)
        are excluded from the comparison and the pair is fitted again. Reported in
        :attr:`FitResult.highlights`.
    saturation : float, "auto" or None
        The target's clipping level (in the target's units, e.g. the decoded value
        of an 8-bit file's code 255): masked pixels with any channel at or above it
        are left out of the comparison, and their count is in
        :attr:`FitResult.warnings`. A clipped pixel reads darker than the light that
        reached it; about a hundred of them (0.4 % of a face) moved a photograph's
        fit to a basin with sss_level 50 % high. ``"auto"``: the targets' own level,
        which their files know (:func:`invsss.io.resolved_saturation` gives it; the
        command line and sweeps resolve it before the fit); None: no level.
    light_terms : sequence of {"shift", "grazing", "incidence", "law", "fill"}, a mapping, or a string
        Add the light-aware terms of docs/model.md, section 8, to the blur: a
        shift of the scattered light away from the light (``kappa``, mm), a
        gain towards grazing view (``gamma``), a gain towards grazing
        incidence of the key light (``beta``), and a multiple-scattering
        reflectance law for the key light's part of the source (``w``, an
        albedo in (0, 1) per source channel), and the same law for the other
        lights' part (``fill``, its strength; needs ``law``). Names are fitted; a mapping
        ``{"shift": 1.3, "grazing": None}`` holds a term at a value (a value
        measured on a registered pair, for an aligned fit of a photograph) and
        fits one given None; a comma-separated string (``"shift=1.3,grazing"``,
        ``"law=0.93/0.8/0.7"``) says the same. Stored as a tuple of names in
        canonical order, the held values in ``light_fixed``. Each needs its
        buffers on every pair (``light_buffers`` of :func:`~invsss.fit_pair`);
        reported in :attr:`FitResult.light_terms`.
    light_fixed : mapping
        The held values (filled from ``light_terms``; read-only).
    term_starts : {"auto", "plain", "scan"}
        Where the fit with ``light_terms`` starts. ``"plain"``: from the plain
        fit's estimate with every term at its identity; once that solve reaches
        the screening tolerance, the loss is scanned along the blur scale
        around where it ended, and the fit also solves from each local minimum
        already below it (another basin the terms lead to). ``"scan"``: from
        that estimate and from the start scan's points with the terms on,
        ranked by successive halving, with a second basin carried through the
        robust rounds (what every term fit did before; on the bundled pairs
        about 1.7 times the warm time of ``"plain"``). ``"auto"``
        (default): ``"scan"`` when ``transmission`` is fitted, ``"plain"``
        otherwise (docs/model.md, section 8, "Where a term fit starts").
    canvas : (int, int), optional
        Fit on a (height, width) canvas at least the pair's size: pairs of
        different sizes fitted on one canvas share one compilation (a sweep, a
        loop over photographs), and the estimate is the one at the pair's own
        size. The pair is padded outside its mask; where the mask reaches its
        last row or column, or with ``vignetting``, ``light_terms`` or ``align``,
        it is fitted at its own size and the result warns
        (:mod:`invsss.estimator.canvas`).

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

    # Each field is the one declaration of its option: its default, and in its
    # metadata the command line's flag, help and parser (invsss.cli.fit builds the
    # fit command's arguments from them), and the sweep schema's fit options
    # (invsss.sweeps.schema) take their names and defaults from here.
    model: str = _option("sog", "screen-space model", choices=lambda: MODEL_NAMES)
    profile: object = _option(
        "thesis-nir", f"sum-of-Gaussians profile ({', '.join(PROFILE_NAMES)}, or a JSON file); its variances "
        "are fixed in the default gauge; auto: thesis-nir, or single (one Gaussian, all a blur of a few pixels "
        "determines) with --distance", cli_default="auto", metavar="NAME|FILE.json")
    fix: object = _option(
        None, "hold parameters at given values: sss_level, correction, maxdd take one number, weights and "
        "variances a comma-separated list (e.g. --fix maxdd=0.05 variances=0.5,2,8)",
        action="extend", nargs="+", cli_default=[], metavar="NAME=VALUE", parse=fix_from_text)
    gauge: str = _option(
        "auto", "which side of the sss_level/variance-scale degeneracy is fixed: the profile's "
        "variances, or sss_level (then give --fix sss_level=VALUE); depth fixes neither (burley, whose "
        "depth weighting separates them); auto: the model's own (variances; depth for burley)",
        choices=lambda: ("auto", *GAUGES))
    solver: str = _option("lm", "nonlinear solver", choices=lambda: SOLVERS)
    n_starts: int = _option(4, "starting points of the multi-start search", flag="--starts", type=int,
                            metavar="N")
    max_steps: int = _option(200, "solver steps per start and per refinement", type=int, metavar="N")
    # The blur by forward differences took 0.64-0.77 of forward mode's time per
    # step (experiments/bench_fit.py --jacobian); the covariance uses forward mode.
    solver_jacobian: str = _option(
        "differences", "the solvers' Jacobian of the blur: 'differences' (forward differences) or "
        "'forward-mode' (exact, slower)", flag=None)
    stall_test: bool = _option(
        True, "stop a solve whose accepted losses stall within the noise (invsss.estimator.solve.stalled)",
        flag=None)
    tap_weights: object = _option(None, "the 7 tap weights: a set's name or 7 numbers", flag=None)
    robust: str | None = _option("pseudo-huber", "robust loss (pseudo-huber, cauchy or none)", flag=None)
    align: str = _option(
        "none", "register the target onto the source inside the fit, for photographs that are not "
        "pixel-aligned with their render (two to five times the time; the warp goes into params.json)",
        choices=lambda: ("none", *_align_kinds()))
    vignetting: bool = _option(
        False, "fit the camera's fall-off toward the corners as a gain field 1 + a1 rho^2 + a2 rho^4 "
        "(for photographs; the field goes into params.json)", action="store_true")
    highlights: bool = _option(
        False, "refit with the specular highlights of a first fit's residual left out (for photographs "
        "without cross-polarisation; their count goes into params.json)", action="store_true")
    saturation: float | str | None = _option(
        None, "the targets' clipping level in their decoded units: masked pixels at or above it are left "
        "out of the fit, and their count is a warning in params.json. 'auto': 1.0, the top code, when every "
        "target is an 8- or 16-bit file, and no level for float targets (EXR); 'none': keep every pixel",
        cli_default="auto", metavar="LEVEL", parse=saturation_from_text)
    light_terms: tuple = _option(
        (), "fit light-aware terms on top of the blur (docs/model.md, section 8): 'shift' (light exits "
        "displaced away from the light; needs --light), 'grazing' (brighter or darker at grazing view; needs "
        "--normal), 'incidence' (brighter or darker where the key light grazes the skin or misses it; needs "
        "--normal and --light), 'law' (the key light reflected by a scattering medium's law instead of "
        "Lambert's, an albedo per source channel; needs --key, --normal and --light), or a list such as "
        "'shift,law'; 'shift=1.3' holds kappa at a value measured on a registered pair (for --align), "
        "'law=0.93/0.8/0.7' the albedos", cli_default="none", metavar="TERMS")
    light_fixed: object = _option(None, "the held light-term values (filled from light_terms)", flag=None)
    term_starts: str = _option(
        "auto", "where the fit with light terms starts: 'plain', from the plain fit's estimate, then from any "
        "blur scale the loss along it shows to be better; 'scan', also from the start scan's points with the "
        "terms on, and a second basin carried to the end (about 1.7x the time warm); auto: scan with 'transmission', "
        "plain otherwise (docs/model.md, section 8)", choices=lambda: TERM_STARTS)
    canvas: tuple | None = _option(
        None, "fit on a canvas of HxW pixels at least every pair's size (e.g. 256x256): pairs of different "
        "sizes then share their compiled functions, in this process and in the compilation cache, with the "
        "estimate of a fit at the pair's own size (docs/model.md, section 7)", metavar="HxW",
        parse=canvas_from_text)
    pigment: int = _option(
        0, "fit the skin's pigment difference between source and target (a visible and a 940 nm photograph, "
        "or two colour channels) as a smooth gain field per target channel, a polynomial of this degree over "
        "the frame: 1 or 2 (0: none); it cannot take a blur's place (params.json's pigment)", type=int,
        metavar="DEGREE")
    focal_px: float | None = _option(
        None, "the camera's focal length in pixels: the fit's blur width (params.json's blur) is then also "
        "given in mm on the skin; the fit itself does not change", type=float, metavar="PX")

    def __post_init__(self):
        ALIGN_KINDS = _align_kinds()
        if self.canvas is not None:
            object.__setattr__(self, "canvas", check_canvas(self.canvas))

        if self.align not in ("none", *ALIGN_KINDS):
            raise InvalidInputError(f"align: expected one of none, {', '.join(ALIGN_KINDS)}, got {self.align!r}",
                                    field="align")
        for name in ("vignetting", "highlights", "stall_test"):
            if not isinstance(getattr(self, name), bool):
                raise InvalidInputError(f"{name}: expected true or false, got {getattr(self, name)!r}", field=name)
        if self.saturation is not None and self.saturation != "auto":
            level = self.saturation
            if isinstance(level, bool) or not isinstance(level, numbers.Real) or not np.isfinite(level) or level <= 0:
                raise InvalidInputError(f"saturation: expected a number > 0, 'auto' or None, got {level!r}",
                                        field="saturation")
            object.__setattr__(self, "saturation", float(level))
        terms, held = check_light_terms(self.light_terms)
        if self.light_fixed:
            held = {**held, **check_light_terms(dict(self.light_fixed))[1]}
        object.__setattr__(self, "light_terms", tuple(t for t in LIGHT_TERM_NAMES if t in terms or t in held))
        object.__setattr__(self, "light_fixed", types.MappingProxyType(held))
        entry = get_model(self.model)  # one-line error naming the known models
        if self.gauge not in ("auto", *GAUGES):
            raise InvalidInputError(f"gauge: expected one of auto, {', '.join(GAUGES)}, got {self.gauge!r}",
                                    field="gauge")
        if self.gauge == "auto":
            object.__setattr__(self, "gauge", entry.default_gauge)
        if isinstance(self.pigment, bool) or self.pigment not in PIGMENT_DEGREES:
            raise InvalidInputError(
                f"pigment: expected a degree among {', '.join(map(str, PIGMENT_DEGREES))}, got {self.pigment!r}",
                field="pigment")
        if self.focal_px is not None:
            focal = self.focal_px
            if isinstance(focal, bool) or not isinstance(focal, numbers.Real) or not np.isfinite(focal) or focal <= 0:
                raise InvalidInputError(f"focal_px: expected a number of pixels > 0 or None, got {focal!r}",
                                        field="focal_px")
            object.__setattr__(self, "focal_px", float(focal))
        if self.solver_jacobian not in JACOBIANS:
            raise InvalidInputError(
                f"solver_jacobian: expected one of {', '.join(JACOBIANS)}, got {self.solver_jacobian!r}",
                field="solver_jacobian")
        if self.term_starts not in TERM_STARTS:
            raise InvalidInputError(
                f"term_starts: expected one of {', '.join(TERM_STARTS)}, got {self.term_starts!r}",
                field="term_starts")
        if self.solver not in SOLVERS:
            raise InvalidInputError(f"solver: expected one of {', '.join(SOLVERS)}, got {self.solver!r}",
                                    field="solver")
        for name in ("n_starts", "max_steps"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
                raise InvalidInputError(f"{name}: expected an integer >= 1, got {value!r}", field=name)
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
        raise InvalidInputError(f"light_terms[{name!r}]: expected a number or None (fitted), got {value!r}",
                                field="light_terms") from None
    if not np.isfinite(number) or (name in ("grazing", "incidence") and number <= -1.0):
        raise InvalidInputError(
            f"light_terms[{name!r}]: expected a finite number"
            f"{' > -1' if name in ('grazing', 'incidence') else ''}, got {value!r}",
            field="light_terms",
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
            f"or None (fitted), got {value!r}",
            field="light_terms",
        )
    return float(w) if w.ndim == 0 else tuple(float(x) for x in w)


def check_light_terms(terms) -> tuple[tuple[str, ...], dict[str, float | tuple[float, ...]]]:
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
        entries: dict[str, str | None] = {}
        for part in parts:
            name, _, text = part.partition("=")
            entries[name.strip()] = text.strip() if text else None
    elif hasattr(terms, "items"):
        entries = dict(terms)
    else:
        try:
            entries = dict.fromkeys(terms)
        except TypeError:
            raise InvalidInputError(f"light_terms: expected names of terms, got {terms!r}",
                                    field="light_terms") from None
    unknown = [t for t in entries if t not in LIGHT_TERM_NAMES]
    if unknown:
        raise InvalidInputError(
            f"light_terms: unknown term(s) {', '.join(map(repr, unknown))}; expected some of "
            + ", ".join(LIGHT_TERM_NAMES)
        )
    held: dict[str, float | tuple[float, ...]] = {}
    for name, value in entries.items():
        if value is None:
            continue
        held[name] = _held_albedo(value) if name == "law" else _held_number(name, value)
    if "fill" in entries and "law" not in entries:
        raise InvalidInputError(
            "light_terms: 'fill' applies the law's albedo to the other lights; name 'law' too (e.g. \"law,fill\")",
            field="light_terms",
        )
    return tuple(t for t in LIGHT_TERM_NAMES if t in entries), held
