"""What a fit returns: the estimate, its uncertainty and how it was obtained."""

from __future__ import annotations

import copy
import math

import equinox as eqx
import numpy as np

from ..forward.params import PARAM_NAMES, SSSParams

__all__ = ["FitResult", "masked_list"]


def _number(x):
    """A JSON-ready float (None for NaN or infinity)."""
    x = float(x)
    return x if math.isfinite(x) else None


def masked_list(values, undetermined):
    """``values.tolist()`` with undetermined entries replaced by None."""
    values, undetermined = np.asarray(values, np.float64), np.asarray(undetermined, bool)
    if values.ndim == 0:
        return None if undetermined else _number(values)
    return [masked_list(v, u) for v, u in zip(values, np.broadcast_to(undetermined, values.shape))]


class FitResult(eqx.Module):
    """The result of :func:`invsss.fit_pair` / :func:`invsss.fit_pairs`.

    Attributes
    ----------
    params : SSSParams
        The estimate, as numbers (ready for :func:`invsss.render`, in JAX's default
        precision). Entries listed in ``undetermined`` carry no information (they
        are where the solver stopped, or the profile's value for a parameter the
        model ignores); use :meth:`to_dict`, which writes them as null.
    values : dict
        The same estimate as float64 NumPy arrays (what :meth:`to_dict` writes).
    stderr : dict
        Standard error of each parameter (float, or a list for weights and
        variances); None where the parameter is fixed (see ``fixed``) or
        undetermined (see ``undetermined``). They are conditional on the model
        and on the profile held fixed (its variances, in the default gauge): they
        measure the noise, not the choice of profile. Another profile can move
        the estimate by many standard errors at the same PSNR (14 for
        ``sss_level`` in one measured case), so compare profiles before trusting
        an error bar.
    undetermined : tuple of str
        Parameters the data cannot determine: ``"maxdd"``, ``"weights[2]"``,
        ``"weights[1,0]"`` (Gaussian 1, channel 0), ``"variances[3]"``...
    fixed : dict
        Parameters not estimated, with the values used (given by ``fix=`` or by the gauge).
    gauge : str
        ``"variances"`` or ``"sss_level"``: which side of the ``L``-variance
        degeneracy was fixed.
    loss : float
        Final objective: the mask-weighted mean of ``u (T - pred)^2`` over pixels and
        channels (``u`` the robust weights; about ``sigma^2`` for Gaussian noise).
    sigma : float
        Residual standard deviation (target units) used for the standard errors.
    psnr, ssim : float
        PSNR (dB) and SSIM of the prediction against the target on the mask
        (where the residual counted: an aligned fit leaves out the mask's rim).
    converged : bool
        Whether the last solve met its tolerances within ``max_steps`` (False
        when ``interrupted``).
    iterations : int
        Every solver step the fit took: all starts and all refinement rounds,
        the count the ``progress`` callback reached.
    history : numpy.ndarray, shape (iterations,)
        The loss after each of those steps, in the order taken (same units as
        ``loss``; the value ``progress`` was given). Each solve starts afresh, so
        the curve jumps between stages; split it with ``stages``.
    stages : tuple of (str, int, int)
        ``(label, first, stop)``: ``history[first:stop]`` are the steps of one
        solve, labelled ``"start 1"`` ... ``"start n"`` (the multi-start, to a
        looser tolerance; the lowest final loss wins), then ``"robust 1"``,
        ``"robust 2"`` (reweighting rounds) or, without robust weights,
        ``"refine"`` (the winner solved to the full tolerance), and
        ``"active set 1"``... (weights held at 0), all warm-started from the
        winner. See :meth:`history_by_stage`.
    interrupted : bool
        Whether the ``stop`` callable ended the fit early; the estimate is then
        the best point reached, with its standard errors at that point.
    start_profile : dict or None
        ``{"weights", "variances"}``: the profile the fit started from (weights
        normalised per channel, shaped like the fitted ones), for comparing the
        fitted profile with it (:func:`invsss.cli.report.plot_fit_report` does).
    alignment : tuple of dict
        With ``align``: per pair, the warp from source pixels to target pixels
        (:meth:`invsss.estimator.registration.Warp.to_dict`); the fitted images are on the
        target's grid. Empty without ``align``.
        Not written by :meth:`to_dict`.
    vignetting : dict or None
        With ``vignetting=True``: the fitted fall-off field
        (:mod:`invsss.estimator.vignetting`) as ``{"model", "coefficients",
        "stderr", "corner_gain"}``; ``stderr`` entries are None where the data do
        not determine them. None without it.
    highlights : dict or None
        With ``highlights=True``: ``{"method", "excluded_pixels", "fraction"}``,
        per pair the pixels left out as specular highlights. None without it.
    light_terms : dict or None
        With ``light_terms``: the terms of docs/model.md, section 8, as
        ``{"shift": kappa, "grazing": gamma, "stderr": {...}, "fixed": [...]}``
        with only the terms in use present; a held term is listed in ``fixed``
        and has a None standard error (:meth:`light_terms_params` gives the
        values as an :class:`invsss.LightTerms`). None without them.
    pigment : dict or None
        With ``pigment=n``: the fitted pigment field (:mod:`invsss.estimator.pigment`)
        as ``{"model", "degree", "terms", "coefficients", "stderr", "estimate",
        "psnr_without"}``: coefficients per term and target channel (per pair
        first in a joint fit), ``psnr_without`` the PSNR with the field set to 1
        and the gains solved again (what the field bought at this blur). None
        without it.
    blur : dict or None
        The fitted blur's RMS width per axis, in pixels at the skin's median depth
        and slope, per channel, with standard errors and whether the pixels
        resolve it (:func:`invsss.estimator.blur_width.blur_record`): what the
        pair measured, whatever the gauge.
    gain, offset : numpy.ndarray
        Photometric fit ``pred = gain * out + offset`` per target channel: shape
        (C',) for one pair, (P, C') for :func:`fit_pairs`.
    mix : numpy.ndarray or None
        Weights (3,) of the RGB -> grey mix (an RGB source and a grey target).
    fitted : list of numpy.ndarray
        The prediction ``gain * out + offset`` of each pair, shaped like its target.
    warnings : tuple of str
        Everything the user should know: undetermined parameters and why,
        misalignment, non-convergence.
    model : str
    tap_weights : str or list
    solver : str
    """

    params: SSSParams
    values: dict
    stderr: dict
    undetermined: tuple
    fixed: dict
    gauge: str
    loss: float
    sigma: float
    psnr: float
    ssim: float
    converged: bool
    iterations: int
    history: np.ndarray
    gain: np.ndarray
    offset: np.ndarray
    mix: np.ndarray | None
    fitted: list
    warnings: tuple
    model: str
    tap_weights: object
    solver: str = "lm"
    profile: str = ""
    interrupted: bool = False
    stages: tuple = ()
    start_profile: dict | None = None
    alignment: tuple = ()
    vignetting: dict | None = None
    highlights: dict | None = None
    light_terms: dict | None = None
    blur: dict | None = None
    pigment: dict | None = None

    def light_terms_params(self):
        """The fitted light-aware terms as an :class:`invsss.LightTerms` (None without them)."""
        if self.light_terms is None:
            return None
        from ..forward.light_terms import LIGHT_TERM_FIELDS, LightTerms

        return LightTerms(**{k: v for k, v in self.light_terms.items() if k in LIGHT_TERM_FIELDS})

    def history_by_stage(self) -> dict:
        """``{label: losses}`` for each solve of the fit (see ``stages``).

        Examples
        --------
        >>> import numpy as np, invsss
        >>> y, x = np.mgrid[0:16, 0:16]
        >>> source = 0.5 + 0.3 * np.sin(x / 2.0); depth = np.full((16, 16), 500.0)
        >>> fit = invsss.fit_pair(source, source, depth, None, n_starts=2, robust=None,
        ...                       profile={"weights": [1.0], "variances": [1.0]})
        >>> list(fit.history_by_stage())
        ['start 1', 'start 2', 'refine']
        >>> sum(map(len, fit.history_by_stage().values())) == fit.iterations
        True
        """
        history = np.asarray(self.history)
        return {label: history[first:stop] for label, first, stop in self.stages}

    def is_undetermined(self, name: str) -> np.ndarray:
        """Boolean array of parameter ``name``'s shape: True where undetermined."""
        shape = np.shape(self.values[name])
        flags = np.zeros(shape, bool)
        for entry in self.undetermined:
            if entry == name:
                flags[...] = True
            elif entry.startswith(name + "["):
                idx = tuple(int(i) for i in entry[len(name) + 1 : -1].split(","))
                flags[idx] = True
        return flags

    def to_dict(self) -> dict:
        """JSON-ready mapping with the keys of a params file plus the fit report.

        Undetermined parameters (and their standard errors) are None, never numbers.
        The keys are always the same (``channels_mix`` only with an RGB -> grey
        mix, ``profile`` only for a named profile): the five parameters,
        ``model``, ``tap_weights``, ``stderr``, ``undetermined``, ``loss``,
        ``psnr``, ``ssim``, ``converged``, ``interrupted``, ``iterations``,
        ``fixed``, ``gauge``, ``gain``, ``offset``, ``sigma``, ``solver``,
        ``warnings``, ``alignment``, ``vignetting``, ``highlights``, ``light_terms``,
        ``blur``, ``pigment`` and ``estimate`` (every parameter as a number, undetermined
        ones included: what produced the fitted image). The loss history is not
        written.
        """
        out = {}
        for name in PARAM_NAMES:
            out[name] = masked_list(self.values[name], self.is_undetermined(name))
        out["model"] = self.model
        out["tap_weights"] = self.tap_weights
        out["stderr"] = copy.deepcopy(dict(self.stderr))
        out["undetermined"] = list(self.undetermined)
        out["loss"] = _number(self.loss)
        out["psnr"] = _number(self.psnr)
        out["ssim"] = _number(self.ssim)
        out["converged"] = bool(self.converged)
        out["interrupted"] = bool(self.interrupted)
        out["iterations"] = int(self.iterations)
        out["fixed"] = {k: np.asarray(v).tolist() for k, v in self.fixed.items()}
        out["gauge"] = self.gauge
        out["gain"] = np.asarray(self.gain).tolist()
        out["offset"] = np.asarray(self.offset).tolist()
        if self.mix is not None:
            out["channels_mix"] = np.asarray(self.mix).tolist()
        if self.profile:
            out["profile"] = self.profile
        out["sigma"] = _number(self.sigma)
        out["solver"] = self.solver
        out["warnings"] = list(self.warnings)
        # One warp per pair (invsss.estimator.registration.Warp.to_dict) when the fit registered
        # the target, else null.
        out["alignment"] = [dict(a) for a in self.alignment] or None
        # The camera's fitted fall-off (fit --vignetting), else null.
        out["vignetting"] = copy.deepcopy(self.vignetting)
        # The pixels left out as specular highlights (fit --highlights), else null.
        out["highlights"] = copy.deepcopy(self.highlights)
        # The fitted light-aware terms (fit --light-terms), else null.
        out["light_terms"] = copy.deepcopy(self.light_terms)
        # The blur's width in pixels, with its standard error: what the pixels measured.
        out["blur"] = copy.deepcopy(self.blur)
        # The fitted pigment field (fit --pigment), else null.
        out["pigment"] = copy.deepcopy(self.pigment)
        # The numbers that produced the fitted image, undetermined ones included:
        # what a renderer uses when it needs a value anyway. Always written, so a
        # params file has one shape whatever the data determined.
        out["estimate"] = {name: np.asarray(self.values[name]).tolist() for name in PARAM_NAMES}
        return out
