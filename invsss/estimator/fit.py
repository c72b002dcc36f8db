"""``fit_pair`` / ``fit_pairs``: estimate the model's parameters from image pairs.

The fit, step by step (each step its own module):

1. check the options (:class:`FitOptions`) and the inputs (:mod:`.inputs`);
   decide each parameter's role and the unknowns (:mod:`.parametrisation`);
2. scan the loss along the blur scale and start from its ``n_starts`` lowest
   local minima, each with the best correction and maxdd of a small grid
   (:mod:`.initial`). Steps 1 and 2 are :func:`build_problem`, public;
3. from each start, run the solver (:mod:`.solve`) on the residual with the linear
   unknowns projected out (:mod:`.objective`, :mod:`.projection`), to a looser
   tolerance; keep the best;
4. refine from the best at the full tolerance: robust reweighting rounds
   (:mod:`.robust`) or, without them, one more solve; then an
   active-set pass that holds at 0 any ``sog`` weight the unconstrained least
   squares makes negative (the weights are ratios on the simplex: a negative one
   is not a profile), re-solving after each change;
5. standard errors and undetermined parameters (:mod:`.uncertainty`), PSNR, SSIM
   and a misalignment check (:mod:`.diagnostics`), all in a :class:`FitResult`.

Steps 1 and 2 are :func:`build_problem` (:mod:`.problem`), 3 and 4 :func:`.search.solve_problem`,
5 :func:`.summary.summarise`; :func:`.core.core` runs them in order. The options
that change *what* is fitted are stages around it (:mod:`.stages`), composed in
one place, :func:`fit_stages`: the targets' clipped pixels left out (``saturation``),
the source registered onto the target (``align``), a refit without highlights
(``highlights``), the light terms fitted after the plain model they extend
(``light_terms``).

A ``stop`` callable, polled between solver steps, ends the fit early: the best
point reached so far is reported as usual, flagged ``interrupted``.

Everything runs in float64 (``jax.enable_x64`` inside the call): the projection's
normal equations over strongly correlated layers need it.
"""

from __future__ import annotations

import dataclasses

from ..forward.light_terms import LightBuffers
from ..forward.pair import ImagePair
from ..validation import InvalidInputError, did_you_mean
from .core import Fit, FitCall, core
from .options import FitOptions
from .result import FitResult
from .stages import aligned, unsaturated, with_light_terms, without_highlights

__all__ = ["fit_pair", "fit_pairs", "fit_stages", "run_fit"]




def fit_pair(
    source,
    target,
    depth,
    mask,
    *,
    light_buffers=None,
    options: FitOptions | None = None,
    progress=None,
    stop=None,
    **keywords,
) -> FitResult:
    """Estimate the screen-space SSS parameters that turn ``source`` into ``target``.

    Minimises a robust masked residual between ``target`` and ``gain * out + offset``
    (``out`` the model applied to ``source``; docs/model.md, section 7) with the gains,
    offsets, RGB -> grey mix and, for ``sog``, the profile weights solved in closed
    form inside the residual (variable projection).

    Parameters
    ----------
    source : array, shape (H, W) or (H, W, C), C in {1, 3}
        Linear image without scattering.
    target : array, shape (H, W) or (H, W, C')
        The photograph to match: C' = C, or 1 for an RGB source (then a mix of the
        source channels is fitted too).
    depth : array, shape (H, W)
        Eye-space depth > 0 (mm recommended).
    mask : array, shape (H, W) or None
        Skin mask in [0, 1]; only masked pixels enter the fit (weighted by the mask).
        None uses every pixel.
    progress : callable, optional
        Called as ``progress(iteration, loss)`` after every solver step;
        ``iteration`` counts the steps of the whole fit (all starts and
        refinements) from 1, ``loss`` is in the units of :attr:`FitResult.loss`;
        the last ``iteration`` is :attr:`FitResult.iterations` and the losses are
        :attr:`FitResult.history`.
    light_buffers : LightBuffers, optional
        Camera-space ``light`` (unit vectors towards the key light) and ``normal``
        buffers of shape (H, W, 3), and ``key`` (the source lit by the key light
        alone, the source's shape), on the source's grid.
    options : FitOptions, optional
        How to fit, in one checked value; or give its fields as keywords
        (``model="thesis"``, ``fix={"maxdd": 0.01}``, ``align="similarity"``, ...):
        :class:`~invsss.estimator.FitOptions` lists and explains every one.
    stop : callable, optional
        ``stop() -> bool``, polled after every solver step (and once before the
        first): True ends the fit there, skipping the remaining starts and
        refinements, and the best point reached is reported with
        ``interrupted=True`` and ``converged=False``.

    Returns
    -------
    FitResult

    Raises
    ------
    InvalidInputError
        Bad shapes, NaN values, non-positive depth, empty mask, unknown model, solver,
        gauge or robust loss, a ``fix`` entry with an unknown name or a bad value,
        ``gauge="sss_level"`` without ``fix["sss_level"]``.
    FitInterrupted
        ``stop()`` returned True before any solver step finished.

    Examples
    --------
    >>> import numpy as np, invsss
    >>> rng = np.random.default_rng(0)
    >>> source = rng.uniform(0.2, 1.0, (24, 24))
    >>> depth = np.full((24, 24), 500.0); mask = np.ones((24, 24))
    >>> truth = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])
    >>> target = np.asarray(invsss.render(source, depth, mask, truth))
    >>> fit = invsss.fit_pair(source, target, depth, mask, profile={"weights": [0.5, 0.5],
    ...                       "variances": [0.5, 2.0]}, fix={"correction": 0.0, "maxdd": 1.0})
    >>> round(float(fit.params.sss_level))
    600
    """
    if light_buffers is None:
        pair: ImagePair | tuple = (source, target, depth, mask)
    elif isinstance(light_buffers, LightBuffers):
        pair = ImagePair(source, target, depth, mask, normal=light_buffers.normal, light=light_buffers.light,
                         key=light_buffers.key, fill_light=light_buffers.fill_light,
                         thickness=light_buffers.thickness, key_irradiance=light_buffers.key_irradiance)
    else:
        raise InvalidInputError(f"light_buffers: expected an invsss.LightBuffers, got {type(light_buffers).__name__}")
    return run_fit([pair], True, _options(options, keywords), progress, stop)


def fit_pairs(
    pairs,
    *,
    options: FitOptions | None = None,
    progress=None,
    stop=None,
    **keywords,
) -> FitResult:
    """Fit one set of parameters to several pairs (see :func:`fit_pair`).

    ``pairs`` is a sequence of ``(source, target, depth, mask)`` tuples or
    :class:`invsss.ImagePair` objects, all with the same channel layout (sizes may
    differ). The SSS parameters, weights and the RGB -> grey mix are shared; each
    pair has its own offset and gain (the exposure may differ), per target channel.
    ``FitResult.gain`` and ``offset`` then have shape (P, C'). ``options`` and
    ``stop`` as for :func:`fit_pair`.
    """
    return run_fit(pairs, False, _options(options, keywords), progress, stop)


def _check_callback(name, value):
    if value is not None and not callable(value):
        raise InvalidInputError(f"{name}: expected a callable or None, got {type(value).__name__}", field=name)


def _options(options, keywords) -> FitOptions:
    """``options`` if given (then no option keywords), else a FitOptions of the keywords."""
    known = [f.name for f in dataclasses.fields(FitOptions)]
    unknown = [name for name in keywords if name not in known]
    if unknown:
        raise InvalidInputError(
            f"{unknown[0]}: not an option of the fit{did_you_mean(unknown[0], known)}; expected one of "
            f"{', '.join(known)}"
        )
    if options is None:
        return FitOptions(**keywords)
    if not isinstance(options, FitOptions):
        raise InvalidInputError(f"options: expected a FitOptions, got {type(options).__name__}")
    if keywords:
        raise InvalidInputError(
            f"options: give either options= or keyword options, not both (got {', '.join(keywords)})"
        )
    return options


def fit_stages() -> Fit:
    """The fit as composed stages, outermost first.

    ``unsaturated(aligned(without_highlights(with_light_terms(core))))``: each
    stage takes the stage inside it, does nothing when its option is off, and
    otherwise calls the inner stage with the call it changed (fewer pixels, a
    resampled source, a start). The registration rounds of ``aligned`` use
    ``with_light_terms(core)``: a rough fit per round needs no highlights refit.
    """
    terms = with_light_terms(core)
    return unsaturated(aligned(without_highlights(terms), rounds=terms))


def run_fit(pairs, single: bool, options: FitOptions, progress=None, stop=None) -> FitResult:
    """The one entry point of every fit (:func:`fit_pair`, :func:`fit_pairs`, the
    command line and the sweeps): the callbacks checked, then :func:`fit_stages`."""
    _check_callback("progress", progress)
    _check_callback("stop", stop)
    if not isinstance(options, FitOptions):
        raise InvalidInputError(f"options: expected a FitOptions, got {type(options).__name__}")
    _require_light_buffers(pairs, single, options.light_terms)
    return fit_stages()(FitCall(pairs, single, options, progress, stop))


def _require_light_buffers(pairs, single: bool, terms) -> None:
    """Refuse a missing buffer of a requested light term before anything is fitted:
    the plain fit that comes first would otherwise run to the end before the error."""
    if not terms or not isinstance(pairs, (list, tuple)):
        return  # prepare_pairs names a malformed sequence
    for i, pair in enumerate(pairs):
        buffers = pair.light_buffers if isinstance(pair, ImagePair) else LightBuffers()
        buffers.require(terms, "light_buffers." if single else f"pairs[{i}].")
