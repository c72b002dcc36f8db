"""What one trial does, per task: ``fit``, ``fit-joint`` and ``render``.

Each task takes the loaded pairs and the trial's options and returns a
:class:`TaskOutput`: the numbers that go into the results database and the
files that go into the trial's folder (as writers for
:meth:`invsss.io.result_dir.ResultDir.commit`). Nothing is written here.

* ``fit``: :func:`invsss.fit_pair` on one pair; files ``params.json`` (the fit's
  params file) and ``fit.exr`` (the fitted prediction).
* ``fit-joint``: :func:`invsss.fit_pairs` on every pair; ``params.json`` and
  ``fit_0.exr``, ``fit_1.exr``, ... in the order of the pairs.
* ``render``: :func:`invsss.render` with the given parameters, scored against
  the target (:func:`.scoring.score_render`); ``params.json`` (the parameters
  and the score) and ``render.exr`` (the render itself, in the source's units:
  what a renderer would show).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from ..forward.params import PARAM_NAMES, SSSParams
from ..validation import InvalidInputError
from .schema import fit_options

__all__ = ["TaskOutput", "TrialInterrupted", "check_task_options", "run_task"]

#: The metrics every task reports (a fit adds ``sigma``, ``converged``, ``iterations``).
METRICS = ("loss", "psnr", "ssim")


class TrialInterrupted(Exception):
    """The sweep was asked to stop while this trial ran; it is not recorded."""


@dataclasses.dataclass
class TaskOutput:
    params: dict
    stderr: dict | None
    metrics: dict
    warnings: list
    files: dict  # name -> writer(path)


def _render_values(options: dict) -> dict:
    """The five parameters of a render trial as float64 lists and floats."""
    from ..estimator.parametrisation import resolve_profile

    weights, variances = options["weights"], options["variances"]
    if weights is None or variances is None:
        profile_weights, profile_variances = resolve_profile(options["profile"])
        weights = profile_weights if weights is None else weights
        variances = profile_variances if variances is None else variances
    values = {k: float(options[k]) for k in ("sss_level", "correction", "maxdd")}
    return {**values, "weights": np.asarray(weights, np.float64).tolist(),
            "variances": np.asarray(variances, np.float64).tolist()}


def _render_params(options: dict) -> SSSParams:
    return SSSParams.from_dict(_render_values(options), source="render options")


def check_task_options(task: str, options: dict) -> None:
    """Raise :class:`InvalidInputError` if ``task`` would refuse ``options``.

    Examples
    --------
    >>> from invsss.sweeps.schema import FitTaskOptions
    >>> check_task_options("fit", {**FitTaskOptions().model_dump(), "solver": "adam"})
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: solver: expected one of lm, gauss-newton, bfgs, got 'adam'
    """
    from ..forward.models import get_model

    if task == "render":
        get_model(options["model"])
        _render_params(options)
        if options["tap_weights"] is not None:
            from ..forward.passes import tap_weights

            try:
                tap_weights(options["tap_weights"])
            except (ValueError, TypeError) as err:
                raise InvalidInputError(f"tap_weights: {err}") from None
    else:
        fit_options(options)


def _image_writer(image) -> Callable[[str], None]:
    from ..io import write_image

    return lambda path: write_image(path, np.asarray(image, np.float32))


def _params_writer(content: dict) -> Callable[[str], None]:
    from ..io import write_params

    return lambda path: write_params(path, content)


def _fit_output(result, names: list[str]) -> TaskOutput:
    content = result.to_dict()
    files = {"params.json": _params_writer(content)}
    for name, image in zip(names, result.fitted):
        files[name] = _image_writer(image)
    metrics = {k: content[k] for k in (*METRICS, "sigma", "converged", "iterations")}
    from ..estimator.parametrisation import by_unknown

    params, stderr = {k: content[k] for k in PARAM_NAMES}, dict(content["stderr"] or {})
    # The light terms' values sit beside the five parameters, under the names the
    # estimator gives their unknowns (a held term is reported at its value).
    if content.get("light_terms"):
        params.update(by_unknown(content["light_terms"]))
        stderr.update(by_unknown(content["light_terms"]["stderr"]))
    return TaskOutput(
        params=params,
        stderr=stderr,
        metrics=metrics,
        warnings=list(result.warnings),
        files=files,
    )


def run_task(task: str, options: dict, pairs: list, stop=None) -> TaskOutput:
    """Run ``task`` on the loaded ``pairs`` (:class:`invsss.ImagePair`)."""
    if task == "render":
        return _render(options, pairs[0])
    from ..estimator import FitInterrupted
    from ..estimator.fit import run_fit

    try:
        # The command line's entry point too (invsss.cli.fit): "fit" is one pair,
        # "fit-joint" one set of parameters for every pair.
        result = run_fit(pairs, task == "fit", fit_options(options), stop=stop)
    except FitInterrupted:
        raise TrialInterrupted() from None
    if result.interrupted:
        raise TrialInterrupted()
    names = ["fit.exr"] if task == "fit" else [f"fit_{k}.exr" for k in range(len(pairs))]
    return _fit_output(result, names)


def _render(options: dict, pair) -> TaskOutput:
    from ..forward.screen_space import render
    from .scoring import score_render

    params = _render_params(options)
    rendered = np.asarray(render(pair.source, pair.depth, pair.mask, params, options["model"],
                                 tap_weights=options["tap_weights"]))
    score = score_render(rendered, pair.target, pair.mask)
    values = _render_values(options)
    content = {
        **values,
        "model": options["model"],
        **({"tap_weights": options["tap_weights"]} if options["tap_weights"] is not None else {}),
        # JSON has no infinity: a perfect match's PSNR is written as null.
        **{k: (score[k] if np.isfinite(score[k]) else None) for k in METRICS},
        "gain": score["gain"], "offset": score["offset"],
        **({"channels_mix": score["channels_mix"]} if score["channels_mix"] is not None else {}),
    }
    return TaskOutput(
        params={k: values[k] for k in PARAM_NAMES},
        stderr=None,
        metrics={k: score[k] for k in METRICS},
        warnings=[],
        files={"params.json": _params_writer(content), "render.exr": _image_writer(rendered)},
    )
