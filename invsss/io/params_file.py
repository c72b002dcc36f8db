"""The params JSON file: the five parameters, the model choice and a fit's report."""

from __future__ import annotations

import difflib
import json
import os
import warnings
from collections.abc import Mapping
from pathlib import Path

from ..params import PARAM_NAMES, SSSParams
from ..passes import TAP_WEIGHTS
from ..screen_space import MODELS
from ..validation import InvalidInputError
from .images import _one_line, write_text_atomic

__all__ = ["PARAMS_KEYS", "PARAMS_OPTIONAL_KEYS", "read_params", "write_params"]

#: The keys every params JSON file must have (the fields of :class:`SSSParams`).
PARAMS_KEYS = PARAM_NAMES

#: Keys a params JSON file may have besides :data:`PARAMS_KEYS`: the model
#: choice, and the report the estimator writes next to the fitted values.
PARAMS_OPTIONAL_KEYS = (
    "model",
    "tap_weights",
    "stderr",
    "undetermined",
    "loss",
    "psnr",
    "ssim",
    "converged",
    "iterations",
    "fixed",
    "gauge",
    "channels_mix",
    "gain",
    "offset",
    "profile",
    "estimate",
    "sigma",
    "solver",
    "warnings",
)


def _check_keys(keys, name: str) -> None:
    allowed = PARAMS_KEYS + PARAMS_OPTIONAL_KEYS
    for key in keys:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), allowed, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise InvalidInputError(
                f"{name}: unknown key {key!r}{hint}; expected {', '.join(PARAMS_KEYS)} "
                f"and optionally {', '.join(PARAMS_OPTIONAL_KEYS)}"
            )


def _check_model_choice(extras: Mapping, name: str) -> None:
    if "model" in extras and extras["model"] not in MODELS:
        raise InvalidInputError(
            f"{name}: model must be one of {', '.join(MODELS)}, got {extras['model']!r}"
        )
    if "tap_weights" in extras:
        taps = extras["tap_weights"]
        named = isinstance(taps, str) and taps in TAP_WEIGHTS
        numbers = (
            isinstance(taps, list)
            and len(taps) == 7
            and all(isinstance(t, (int, float)) and not isinstance(t, bool) for t in taps)
        )
        if not (named or numbers):
            raise InvalidInputError(
                f"{name}: tap_weights must be one of {', '.join(TAP_WEIGHTS)} or a list of "
                f"7 numbers, got {taps!r}"
            )


def read_params(path) -> tuple[SSSParams, dict]:
    """Read a params JSON file.

    The file is one JSON object with the keys :data:`PARAMS_KEYS`
    (``weights`` a list, or a list of per-channel lists; ``variances`` a list)
    and optionally any of :data:`PARAMS_OPTIONAL_KEYS`. Any other key is an
    error, so a misspelt key never silently falls back to a default.

    A fit's params file holds ``null`` where the data did not determine a
    value, and its point estimate under ``estimate``; such nulls are filled
    from ``estimate`` and listed in ``extras["filled_from_estimate"]``.

    Returns
    -------
    params : SSSParams
    extras : dict
        The optional keys present in the file (``model``, ``tap_weights``, the
        estimator's report), as parsed.

    Raises
    ------
    InvalidInputError
        Missing file, invalid JSON, missing or unknown keys, values that break
        the constraints of :meth:`SSSParams.check`, an unknown ``model`` or
        ``tap_weights``.

    Examples
    --------
    >>> import tempfile, os, invsss
    >>> path = os.path.join(tempfile.mkdtemp(), "params.json")
    >>> invsss.write_params(path, {"sss_level": 900.0, "correction": 0.0, "maxdd": 1.0,
    ...                            "weights": [1.0], "variances": [2.0], "model": "sog"})
    >>> params, extras = invsss.read_params(path)
    >>> float(params.sss_level), extras
    (900.0, {'model': 'sog'})
    """
    name = os.fspath(path)
    try:
        text = Path(name).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InvalidInputError(f"{name}: params file not found") from None
    except (OSError, UnicodeDecodeError) as err:
        raise InvalidInputError(f"{name}: cannot read params file ({_one_line(err)})") from None
    try:
        content = json.loads(text)
    except json.JSONDecodeError as err:
        raise InvalidInputError(
            f"{name}: invalid JSON at line {err.lineno} column {err.colno} ({err.msg})"
        ) from None
    if not isinstance(content, dict):
        raise InvalidInputError(f"{name}: expected a JSON object with the parameter keys")
    _check_keys(content, name)
    extras = {k: v for k, v in content.items() if k not in PARAMS_KEYS}
    _check_model_choice(extras, name)
    values = {k: content[k] for k in PARAMS_KEYS if k in content}
    nulls = [k for k, v in values.items() if _has_null(v)]
    if nulls:
        # A fit writes undetermined values as null, and beside them the point
        # estimate that produced its fit.exr; a renderer needs numbers, so use
        # those and say which ones the data did not determine.
        estimate = extras.get("estimate")
        if not isinstance(estimate, dict) or any(_has_null(estimate.get(k)) for k in nulls):
            raise InvalidInputError(
                f"{name}: {', '.join(nulls)} is null (undetermined by the fit); "
                "give a number, or re-fit with --fix"
            )
        values.update({k: estimate[k] for k in nulls})
        extras["filled_from_estimate"] = nulls
        warnings.warn(
            f"{name}: {', '.join(nulls)} not determined by the fit; using its point estimate",
            stacklevel=2,
        )
    params = SSSParams.from_dict(values, source=name)
    return params, extras


def _has_null(value) -> bool:
    if isinstance(value, list):
        return any(_has_null(v) for v in value)
    return value is None


def _to_json(value):
    # NumPy/JAX scalars and arrays, as found in an estimator's report.
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def write_params(path, mapping) -> None:
    """Write parameters (and optional report keys) as JSON, atomically.

    Parameters
    ----------
    path : str or os.PathLike
    mapping : Mapping or SSSParams
        The keys :func:`read_params` accepts; arrays become lists. Keys that
        :func:`read_params` would reject are rejected here, so every file this
        writes can be read back.

    Raises
    ------
    InvalidInputError
        Unknown keys, values that are not JSON-serialisable, a missing directory.
    """
    name = os.fspath(path)
    if isinstance(mapping, SSSParams):
        mapping = mapping.to_dict()
    if not isinstance(mapping, Mapping):
        raise InvalidInputError(
            f"{name}: expected a mapping or SSSParams to write, got {type(mapping).__name__}"
        )
    _check_keys(mapping, name)
    try:
        text = json.dumps(dict(mapping), indent=2, default=_to_json) + "\n"
    except (TypeError, ValueError) as err:
        raise InvalidInputError(f"{name}: cannot write params ({_one_line(err)})") from None
    write_text_atomic(name, text)
