"""The problem a fit solves, built in the open: :func:`build_problem`.

From checked pairs and :class:`~invsss.estimator.FitOptions` it makes the
parametrisation (roles, free blocks, references), the projected residual
(:class:`~invsss.estimator.objective.Objective`) and the starting points of the
multi-start search. :func:`invsss.fit_pair` solves exactly this problem; tests and
benchmarks build it themselves to time or probe the solve without running a fit.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import jax
import jax.numpy as jnp
import numpy as np

try:
    from jax.extend.core import jaxpr_as_fun
except ImportError:  # a JAX from before jax.extend.core had it
    from jax.core import jaxpr_as_fun  # type: ignore[attr-defined,no-redef]  # only an older JAX has it here

from ..forward.models import get_model
from ..forward.params import PARAM_NAMES
from ..runtime.executable_cache import persistent_jit
from ..validation import InvalidInputError
from .canvas import on_canvas
from .initial import blur_grid, blur_reference, choose_starts, data_scales, profile_minima
from .inputs import prepare_pairs
from .objective import Objective
from .options import FitOptions
from .parametrisation import LIGHT_UNKNOWNS, Parametrisation, assign_roles, logit, resolve_profile
from .pigment import num_terms
from .uncertainty import linearise
from .vignetting import ORDER as VIGNETTING_ORDER

__all__ = ["FitProblem", "build_problem", "evaluate", "scan_losses"]


#: Where the law's albedo starts: between the 940 nm faces' fitted 0.93-0.95 and
#: the visible skin's 0.7-0.93 (docs/model.md, section 8).
LAW_START = 0.9


def _initial_weights(profile_weights, k, channels):
    """Starting (or carried) weights of shape (K,) or (K, C') from the profile."""
    w = np.asarray(profile_weights, np.float64)
    if w.shape[0] != k:
        w = np.ones(k)
    if w.ndim == 2 and (channels == 1 or w.shape[1] != channels):
        w = w.mean(axis=1)
    if w.ndim == 1 and channels > 1:
        w = np.repeat(w[:, None], channels, axis=1)
    w = np.maximum(w, 1e-6)
    return w / w.sum(axis=0)


# Over 80 lines, kept whole: one short block per parameter block in the order of
# the layout it builds, each reading the ones before it (fixed weights set the
# variances' start, the light terms follow the buffers).
def _build(pairs, roles, fixed, profile_w, profile_v, scales, vignetting=False, light_terms=(), light_fixed=None,
           pigment=0):
    """The parametrisation and the natural starting values of the free blocks."""
    c_src, c_tgt = pairs[0].channels
    variances = fixed.get("variances", profile_v)
    k = variances.shape[0]
    w0 = _initial_weights(profile_w, k, c_tgt)
    if "weights" in fixed:
        w = fixed["weights"]
        if w.ndim == 2 and w.shape[1] not in (1, c_tgt):
            raise InvalidInputError(
                f"fix['weights']: expected one column per target channel ({c_tgt}), got shape {w.shape}",
                field="fix",
            )
        if w.shape[0] != k:
            raise InvalidInputError(
                f"fix['weights']: expected {k} rows, one per Gaussian of the profile, got shape {w.shape}",
                field="fix",
            )
    carried = {"sss_level": 1.0, "correction": 0.0, "maxdd": scales.slope, "weights": w0, "variances": variances}
    values, reference, start, blocks = {}, {}, {}, []
    for name in PARAM_NAMES:
        role = roles[name]
        if role == "fixed":
            values[name] = _on_device(fixed.get(name, variances if name == "variances" else None))
        elif role in ("unused", "linear"):
            values[name] = _on_device(carried[name])
    if roles["sss_level"] == "free":
        reference["sss_level"] = blur_reference(scales, variances)
        blocks.append(("sss_level", ()))
    if roles["correction"] == "free":
        reference["correction"] = scales.correction
        start["correction"] = 0.1 * scales.correction
        blocks.append(("correction", ()))
    if roles["maxdd"] == "free":
        reference["maxdd"] = scales.slope
        blocks.append(("maxdd", ()))
    if roles["variances"] == "free":
        reference["variances"] = np.asarray(variances)
        blocks.append(("variances", (k,)))
    if roles["weights"] == "free":
        if k == 1:
            values["weights"] = jnp.ones((1,) if c_tgt == 1 else (1, c_tgt))
        else:
            blocks.append(("weights", (k - 1,) if c_tgt == 1 else (k - 1, c_tgt)))
            start["weights"] = w0
            reference["weights"] = 1.0
    if c_src == 3 and c_tgt == 1:
        blocks.append(("mix", (2,)))
        start["mix"] = np.full(3, 1.0 / 3.0)
        reference["mix"] = 1.0
    if len(pairs) > 1:
        blocks.append(("gain_ratio", (len(pairs) - 1, c_tgt)))
        start["gain_ratio"] = np.ones((len(pairs) - 1, c_tgt))
        reference["gain_ratio"] = 1.0
    if vignetting:
        blocks.append(("vignetting", (VIGNETTING_ORDER,)))
        start["vignetting"] = np.zeros(VIGNETTING_ORDER)
        reference["vignetting"] = 1.0
    if pigment:
        # One field per pair and target channel: each photograph has its own pigment.
        shape = (len(pairs), num_terms(pigment), c_tgt)
        blocks.append(("pigment", shape))
        start["pigment"] = np.zeros(shape)
        reference["pigment"] = 1.0
    for i, pair in enumerate(pairs):
        pair.light_buffers.require(light_terms, f"pairs[{i}]." if len(pairs) > 1 else "")
    light_fixed = dict(light_fixed or {})
    if "law" in light_fixed and np.size(light_fixed["law"]) not in (1, c_src):
        raise InvalidInputError(
            f"light_terms['law']: expected one albedo or one per source channel ({c_src}), "
            f"got {np.size(light_fixed['law'])}",
            field="light_terms",
        )
    # A held term is a value like a fixed parameter's; the objective applies a
    # term whenever its name is among the natural values.
    for term, name in LIGHT_UNKNOWNS.items():
        if term in light_fixed:
            values[name] = _on_device(light_fixed[term])
    if "shift" in light_terms and "shift" not in light_fixed:
        # One unit of z shifts by about a pixel at the start: kappa is in scene
        # units, and a pixel covers depth / L of them.
        level = reference["sss_level"] if "sss_level" in reference else float(values["sss_level"])
        blocks.append(("light_shift", ()))
        start["light_shift"] = 0.0
        reference["light_shift"] = scales.depth / float(level)
    for gain in ("grazing", "incidence"):
        if gain in light_terms and gain not in light_fixed:
            blocks.append((gain, ()))
            start[gain] = 0.0
            reference[gain] = 1.0
    if "law" in light_terms and "law" not in light_fixed:
        # One albedo per source channel: a chromatic medium's differ (skin's fall
        # from red to blue), and the law acts before a grey mix.
        blocks.append(("law", (c_src,)))
        start["law"] = np.full(c_src, LAW_START)
        reference["law"] = np.full(c_src, float(logit(LAW_START)))
    if "law" in light_terms:
        # The strength is free with a held albedo too: it is what lets the fit
        # fall back to Lambert (0) where the law does not describe the data. The
        # scan starts with the law on; the plain fit's start has it at 0.
        blocks.append(("law_strength", ()))
        start["law_strength"] = 1.0
        reference["law_strength"] = 1.0
    if "fill" in light_terms and "fill" not in light_fixed:
        # The law on the other lights: the same albedo, a strength of its own
        # (0 leaves them Lambertian), on from the scan's starts like the law's.
        blocks.append(("fill_strength", ()))
        start["fill_strength"] = 1.0
        reference["fill_strength"] = 1.0
    if "transmission" in light_terms and "transmission" not in light_fixed:
        # One tint per source channel (HDRP's transmission tint is a colour), 0 the
        # identity. The scan starts with it on, half the key light through; the
        # plain fit's start has it at 0.
        blocks.append(("transmission", (c_src,)))
        start["transmission"] = np.full(c_src, TRANSMISSION_START)
        reference["transmission"] = 1.0
    if "transmission" in light_terms and "thickness_scale" not in light_fixed:
        blocks.append(("thickness_scale", ()))
        reference["thickness_scale"] = thickness_reference(pairs)
        start["thickness_scale"] = reference["thickness_scale"]
    param = Parametrisation(
        tuple(blocks), {k_: _on_device(v) for k_, v in reference.items()}, values
    )
    natural0 = {name: start.get(name, reference[name]) for name, _ in blocks}
    return param, param.unknowns(natural0)


#: Where the transmission's tint starts in the scan (its identity, 0, is the plain fit's start).
TRANSMISSION_START = 0.5
#: Below this thickness (mm) the key light meets the surface itself: the scale's
#: reference is taken from the thicker part behind the terminator.
THIN_MM = 0.5


def median_thickness_behind(pairs) -> float | None:
    """The median thickness (mm) of the masked pixels that the key light reaches only
    through the skin (thicker than :data:`THIN_MM`), over all pairs; None without any."""
    behind = [np.asarray(p.thickness)[(np.asarray(p.mask) > 0) & (np.asarray(p.thickness) > THIN_MM)]
              for p in pairs if p.thickness is not None]
    values = np.concatenate(behind) if behind else np.zeros(0)
    return float(np.median(values)) if values.size else None


def thickness_reference(pairs) -> float:
    """The thickness scale's reference ``k``: one over :func:`median_thickness_behind`,
    so that ``k t`` is about 1 there at the start (1/mm when no pixel is behind the terminator)."""
    median = median_thickness_behind(pairs)
    return 1.0 if median is None else 1.0 / median


def _on_device(x) -> jax.Array:
    """A host value as a float64 device array. ``jnp.asarray`` would compile a
    small conversion for every new shape, a few hundredths of a second each."""
    return jax.device_put(np.asarray(x, np.float64))


_NO_JACOBIAN = np.asarray(False)  # evaluate's traced flag, for the cheap calls

#: Threads that evaluate the start scan's losses side by side. One evaluation
#: (a blur and the projection) keeps a 2-core CPU about 1.6 cores busy; on
#: data_synthetic/fran_front two threads took 0.6-0.87 of the time of one for
#: 32 losses, the losses bit for bit the same. More were not measured.
SCAN_THREADS = 2


def _blur_at_zero(roles, scales, fixed, variances):
    if roles["sss_level"] == "free":
        return 2.0  # by construction of the reference (initial.blur_reference)
    if roles["variances"] == "free":
        return float(fixed["sss_level"]) * float(np.sqrt(np.max(variances))) / scales.depth
    return None


@persistent_jit
def evaluate(objective, z, with_jacobian):
    """Everything needed after a solve, in one compiled function: the linear
    unknowns, predictions, loss and, if the traced flag ``with_jacobian`` is set,
    the linearisation for the covariance (a ``lax.cond``: one compilation serves
    the cheap calls of the start scan and the refinement loops, and the final
    one). The start scan reads only its loss: XLA computes the basis images once
    for all the outputs, so it costs what the loss alone does, and a fit
    compiles one function fewer."""
    _, _, ratios, coef, offset = objective.linear(z)
    return {
        "ratios": ratios,
        "coef": coef,
        "offset": offset,
        "predictions": objective.predictions(z),
        "loss": objective.loss(z),
        "linearisation": _when(with_jacobian, lambda: linearise(objective, z, coef, offset)),
    }


def _when(flag, compute):
    """``compute()`` where the traced ``flag`` is set, else zeros of its shapes (a ``lax.cond``).

    ``compute`` is traced once: its jaxpr gives both the shapes of the zeros and
    the branch that runs it. Tracing it a second time for the shapes
    (``jax.eval_shape``) cost a quarter of :func:`evaluate`'s tracing (0.7 of
    2.9-3.2 s on data_synthetic/fran_front, measured 2026-11-27).
    """
    closed, shapes = jax.make_jaxpr(compute, return_shape=True)()
    treedef = jax.tree_util.tree_structure(shapes)
    return jax.lax.cond(
        flag,
        lambda: jax.tree_util.tree_unflatten(treedef, jaxpr_as_fun(closed)()),
        lambda: jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shapes),
    )


def scan_losses(objective):
    """``losses(points)``: the loss at each unknown vector of a list, in order, in float64,
    evaluated by :data:`SCAN_THREADS` threads (the start scan's evaluator).

    ``objective`` is a :class:`FitProblem`'s; the first point is evaluated alone (it
    may compile or load :func:`evaluate`, which the threads then share), and float64
    mode is switched on in each thread, as it is a per-thread setting in JAX.
    """

    def one(z):
        # float64 mode is a per-thread setting.
        with jax.enable_x64(True):
            return float(evaluate(objective, _on_device(z), _NO_JACOBIAN)["loss"])

    def losses(points):
        if not points:
            return np.zeros(0)
        # The first point alone: it may compile (or load) evaluate, which the
        # threads then share.
        first = one(points[0])
        with ThreadPoolExecutor(SCAN_THREADS) as pool:
            return np.array([first, *pool.map(one, points[1:])])

    return losses


class FitProblem:
    """The checked inputs, parametrisation, objective and starts of one fit.

    Made by :func:`build_problem`; its arrays are float64, so use it under
    ``jax.enable_x64(True)``.

    Attributes
    ----------
    options : FitOptions
    data : tuple of ImagePair
        The checked float64 pairs the fit evaluates: on ``options.canvas``
        where that leaves the fit unchanged (:mod:`.canvas`).
    given : tuple of ImagePair
        The checked pairs at their own sizes.
    shapes : tuple of (int, int)
        Each pair's own (height, width): crop predictions on a canvas to it.
    notes : list of str
        Why pairs were left off the canvas (for the fit's warnings).
    roles : dict
        Each parameter's role: "free", "linear", "fixed" or "unused".
    fixed : dict
        The ``fix=`` values as float64 arrays.
    scales : DataScales
        Typical depth, slope and correction of the data (the references).
    param : Parametrisation
        Maps the unknowns ``z`` to parameter values.
    objective : Objective
        The projected residual: ``objective(z) -> (residual, None)``, with plain
        least-squares weights and every basis image active (the fit changes both
        in its refinement rounds).
    starts : tuple of arrays, shape (n,)
        Starting unknowns, best first (at most ``options.n_starts``; empty when
        nothing is free), after the nested start when there is one.
    nested : bool
        Whether ``starts[0]`` is a contained model's fit (``nested=``), which the
        solve never drops.
    scan_after : bool
        Whether the solve scans again around where its one start's solve ended
        (``scan_after=``).
    z_base : array, shape (n,)
        The natural starting values of the free blocks, before the start search.
    to_loss : float
        Factor from the solver's ``0.5 * sum(residual^2)`` to the reported loss.
    variances : numpy.ndarray
        The variances the fit starts from (fixed or the profile's).
    start_weights : numpy.ndarray, shape (K,) or (K, C')
        The profile's weights, normalised per channel: where the weights start.
    channels : int
        Target channels C'.
    linear_weights : bool
        Whether the weights are eliminated by least squares (``sog``).
    """

    def __init__(self, data, options, profile_w, profile_v, start=None, before_scan=None, nested=None,
                 scan_after=False):
        self.options, self.model = options, options.model
        self.given = tuple(data)
        self.shapes = tuple(tuple(np.shape(p.mask)) for p in self.given)
        self.fixed = dict(options.fix)
        self.roles = assign_roles(options.model, options.gauge, self.fixed)
        # The scales (the start grid's span among them) are the pairs' own, on a canvas too.
        self.scales = data_scales(self.given)
        self.data, self.notes = on_canvas(self.given, options)
        self.param, self.z_base = _build(
            self.data, self.roles, self.fixed, profile_w, profile_v, self.scales, options.vignetting,
            options.light_terms, options.light_fixed, options.pigment,
        )
        self.variances = np.asarray(self.fixed.get("variances", profile_v))
        self.channels = self.data[0].channels[1]
        self.start_weights = _initial_weights(profile_w, self.variances.shape[0], self.channels)
        self.linear_weights = self.roles["weights"] == "linear"
        nb = self.variances.shape[0] if self.linear_weights else 1
        on_mask = np.concatenate([np.asarray(p.target)[np.asarray(p.mask) > 0].ravel() for p in self.data])
        scale = float(np.std(on_mask)) or 1.0
        self.objective = Objective(
            self.param,
            self.data,
            options.taps(jnp.float64),
            tuple(_on_device(np.ones(p.target.shape)) for p in self.data),
            _on_device(np.ones((nb, self.channels))),
            _on_device(scale),
            options.model,
            self.linear_weights,
        )
        total = float(sum(np.sum(np.asarray(p.residual_weight)) for p in self.data)) * self.channels
        # 0.5 * sum(rho^2) -> the reported loss (see objective.py).
        self.to_loss = 2.0 * scale**2 / total
        self.starts = ()
        self.nested = False
        self.scan_after = bool(scan_after) and start is not None
        if self.param.size and start is not None:
            # A known neighbourhood (an earlier fit of nearly the same pair): start
            # there, without the scan.
            self.starts = (self._unknowns_at(start),)
        elif self.param.size:
            if before_scan is not None:
                before_scan(self)
            blur0 = _blur_at_zero(self.roles, self.scales, self.fixed, self.variances)
            self.starts = tuple(
                _on_device(z)
                for z in choose_starts(
                    scan_losses(self.objective), self.param, self.scales, blur0, self.z_base, options.n_starts
                )
            )
            if nested is not None:
                self.starts = (self._unknowns_at(nested), *self.starts)
                self.nested = True

    def blur_minima(self, z_base) -> list[tuple]:
        """``(z, loss)`` at each local minimum of the loss along the start scan's
        blur grid (:func:`~.initial.blur_grid`), lowest first, with every other
        unknown at ``z_base``; empty where the blur scale is not free."""
        blur0 = _blur_at_zero(self.roles, self.scales, self.fixed, self.variances)
        if blur0 is None or "sss_level" not in self.param.free:
            return []
        points = blur_grid(self.param, self.scales, blur0, z_base)
        losses = np.asarray(scan_losses(self.objective)(points), np.float64)
        profile = np.where(np.isfinite(losses), losses, np.inf)
        return [(_on_device(points[i]), float(profile[i])) for i in profile_minima(profile)]

    def _unknowns_at(self, natural_values: dict):
        """The unknowns at the given natural values of free blocks, the others at ``z_base``."""
        natural = {k: np.asarray(v) for k, v in self.param.natural(np.asarray(self.z_base, np.float64)).items()}
        natural.update({k: np.asarray(v, np.float64) for k, v in natural_values.items() if k in self.param.free})
        return jax.device_put(self.param.unknowns(natural))

    @property
    def z0(self):
        """The best start (``z_base`` when nothing is free)."""
        return self.starts[0] if self.starts else self.z_base

    def loss(self, z) -> float:
        """The reported loss at ``z`` (mask-weighted mean squared residual)."""
        return float(evaluate(self.objective, _on_device(z), _NO_JACOBIAN)["loss"])


def build_problem(
    pairs, options: FitOptions | None = None, start: dict | None = None, before_scan=None, nested: dict | None = None,
    scan_after: bool = False,
) -> FitProblem:
    """Check the pairs and build the problem :func:`invsss.fit_pairs` would solve.

    Parameters
    ----------
    pairs : sequence of (source, target, depth, mask) or ImagePair
        As for :func:`invsss.fit_pairs`.
    options : FitOptions, optional
        Default ``FitOptions()``.
    start : dict, optional
        Natural values (``sss_level``, ``correction``, ``maxdd``, ``mix``, ...) to
        start from instead of scanning for starts: one start, the free blocks
        named here at these values and the others where they would begin. Names
        that are not free are ignored.
    before_scan : callable, optional
        ``before_scan(problem)``, called once the objective is built and before
        the start scan (not at all when ``start`` replaces the scan or nothing is
        free). :func:`invsss.fit_pairs` starts compiling its solver there, on
        another thread, so that the compilation overlaps the scan.
    nested : dict, optional
        Natural values of a simpler model's fit that this model contains (the
        plain fit, with every light term at its identity): put first among the
        scan's starts, and :attr:`FitProblem.nested` set, so that the solve
        always carries it to the end and cannot finish above it.
    scan_after : bool
        With ``start``: set :attr:`FitProblem.scan_after`, so that the solve
        scans around where the start's solve ended and goes on from any scanned
        point already below it (:func:`~.search.solve_problem`).

    Returns
    -------
    FitProblem
        Its ``objective`` and ``starts`` are what the fit hands the solver first;
        evaluate them under ``jax.enable_x64(True)``.

    Raises
    ------
    InvalidInputError
        Bad pairs, or ``fix['weights']`` that does not match the profile.

    Examples
    --------
    >>> import numpy as np, jax, invsss
    >>> from invsss.estimator import FitOptions, build_problem
    >>> rng = np.random.default_rng(0)
    >>> source = rng.uniform(0.2, 1.0, (16, 16)); depth = np.full((16, 16), 500.0)
    >>> options = FitOptions(profile={"weights": [1.0], "variances": [1.0]}, n_starts=2,
    ...                      fix={"correction": 0.0, "maxdd": 1.0})
    >>> problem = build_problem([(source, source, depth, None)], options)
    >>> problem.param.free, len(problem.starts)
    (('sss_level',), 2)
    >>> with jax.enable_x64(True):
    ...     residual, _ = problem.objective(problem.z0)
    >>> residual.shape
    (256,)
    """
    options = FitOptions() if options is None else options
    if not isinstance(options, FitOptions):
        raise InvalidInputError(f"options: expected a FitOptions, got {type(options).__name__}")
    with jax.enable_x64(True):
        profile_w, profile_v = resolve_profile(options.profile)
        data = prepare_pairs(pairs)
        # --- issue 34: burley's variances are d_c^2, one per target channel, started
        # from the profile's per-axis variance (invsss.forward.burley_screen_space.start_variances).
        if get_model(options.model).layout == "disk":
            from ..forward.burley_screen_space import start_variances

            profile_v = start_variances(profile_w, profile_v, data[0].channels[1])
            profile_w = np.ones(profile_v.shape[0])
        # --- end issue 34
        return FitProblem(data, options, profile_w, profile_v, start, before_scan, nested, scan_after)
