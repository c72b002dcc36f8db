"""The params JSON file: the five parameters, the model choice and a fit's report.

The schema is defined once, as the strict pydantic model :class:`ParamsFile`:
numbers must be JSON numbers (``true`` or ``"600"`` are refused, never read as
1 or 600), unknown keys are refused (a misspelt key never falls back to a
default), and every file carries a ``schema_version``. ``docs/params-schema.json``
is generated from the model (:func:`params_json_schema`) and
``docs/params-json.md`` describes each key.

Compatibility: a file without ``schema_version`` was written by an invsss older
than the versioned schema and is read as version 1; a file with a newer version
than :data:`SCHEMA_VERSION` is refused with a message saying to upgrade. Version
2 added ``depth_unit``: a file without it is read as mm, with a notice when a
fit wrote it before the unit was recorded.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from ..forward.models import MODEL_NAMES, get_model
from ..forward.params import DEPTH_UNITS, PARAM_NAMES, SSSParams, entry_name
from ..forward.passes import TAP_WEIGHTS
from ..forward.screen_space import MODELS
from ..validation import InputNotice, InvalidInputError, did_you_mean, number_array, one_line
from .result_dir import MANIFEST_NAME, result_state
from .writing import write_text_atomic

if TYPE_CHECKING:
    from pydantic_core import ErrorDetails

__all__ = [
    "SCHEMA_VERSION",
    "MANIFEST_NAME",
    "PARAMS_KEYS",
    "PARAMS_OPTIONAL_KEYS",
    "ParamsFile",
    "params_json_schema",
    "read_params",
    "warn_filled_for_model",
    "write_params",
]

#: The version :func:`write_params` writes and the newest :func:`read_params` reads.
SCHEMA_VERSION = 2

#: The keys every params JSON file must have (the fields of :class:`SSSParams`).
PARAMS_KEYS = PARAM_NAMES

_Number = float  # strict: a JSON number; booleans and strings are refused
_MaybeNumber = _Number | None  # null: a value the fit did not determine


class Estimate(BaseModel):
    """The fit's point estimate: every parameter as a number, undetermined ones included."""

    model_config = ConfigDict(strict=True, extra="forbid")

    sss_level: _Number
    correction: _Number
    maxdd: _Number
    weights: list[_Number] | list[list[_Number]]
    variances: list[_Number]


class ParamsFile(BaseModel):
    """The params JSON file (``invsss fit`` writes it, ``invsss render``/``export`` read it)."""

    model_config = ConfigDict(
        strict=True, extra="forbid", title="invsss params file", use_attribute_docstrings=True
    )

    schema_version: Annotated[int, Field(ge=1)] = SCHEMA_VERSION
    """Version of this schema; files without it were written before versioning (read as 1)."""
    sss_level: _MaybeNumber
    """L > 0: pixels per scene unit at unit depth (the focal length in pixels for depth in mm)."""
    correction: _MaybeNumber
    """c >= 0: how strongly a depth slope narrows the blur."""
    maxdd: _MaybeNumber
    """delta > 0: the depth slope above which the correction stops growing."""
    weights: list[_MaybeNumber] | list[list[_MaybeNumber]]
    """Gaussian weights, one per Gaussian (K) or one per Gaussian and channel (K x C)."""
    variances: list[_MaybeNumber]
    """Gaussian variances in scene units squared, one per Gaussian (K)."""
    depth_unit: Literal[tuple(DEPTH_UNITS)] | None = None  # type: ignore[valid-type]
    """Unit of the depth the parameters refer to: mm, cm or m (schema 2; absent: mm)."""
    model: Literal[MODELS] | None = None  # type: ignore[valid-type]
    """Screen-space model to render with (default sog)."""
    tap_weights: (
        Literal[tuple(TAP_WEIGHTS)]  # type: ignore[valid-type]
        | Annotated[list[_Number], Field(min_length=7, max_length=7)]
        | None
    ) = None
    """7-tap weight set: a name or 7 numbers (default: the model's own)."""
    estimate: Estimate | None = None
    """A fit's point estimate; fills the null entries above when rendering."""
    stderr: Any = None
    """Fit report: standard errors of the parameters (null where undetermined)."""
    undetermined: list[str] | None = None
    """Fit report: the entries the data did not determine (``weights[2]``, ...)."""
    loss: _Number | None = None
    """Fit report: final value of the objective."""
    psnr: _Number | None = None
    """Fit report: PSNR of the fitted prediction against the target, dB."""
    ssim: _Number | None = None
    """Fit report: SSIM of the fitted prediction against the target."""
    converged: bool | None = None
    """Fit report: whether the solver met its tolerance."""
    interrupted: bool | None = None
    """Fit report: true when the fit was stopped before it finished (e.g. Ctrl-C)."""
    iterations: int | None = None
    """Fit report: solver iterations used."""
    fixed: Any = None
    """Fit report: the parameters held fixed and their values."""
    gauge: str | None = None
    """Fit report: which side of the sss_level/variance-scale degeneracy was fixed."""
    channels_mix: Any = None
    """Fit report: RGB -> grey mix fitted for a grey target of an RGB source."""
    gain: Any = None
    """Fit report: per-channel gain fitted between prediction and target."""
    offset: Any = None
    """Fit report: per-channel offset fitted between prediction and target."""
    profile: Any = None
    """Fit report: the profile the fit started from (a name or a file)."""
    sigma: _Number | None = None
    """Fit report: estimated noise level of the target."""
    solver: str | None = None
    """Fit report: the nonlinear solver used."""
    alignment: Any = None
    """Fit report: per pair, the warp that registered the target onto the source (fit --align), or null."""
    vignetting: Any = None
    """Fit report: the camera's fitted radial fall-off (fit --vignetting): model, coefficients, stderr, corner_gain; or null."""  # noqa: E501
    highlights: Any = None
    """Fit report: pixels left out as specular highlights (fit --highlights): method, excluded_pixels, fraction; or null."""  # noqa: E501
    light_terms: Any = None
    """Fit report: the fitted light-aware terms (fit --light-terms; docs/model.md, section 8): shift (mm), grazing, incidence, law (an albedo per source channel), law_strength (0 Lambert, 1 the law; absent means 1), fill (the law's strength on the other lights; absent means 0), stderr, fixed, psnr_plain and psnr_without (dB, measured), fallback; or null."""  # noqa: E501
    pigment: Any = None
    """Fit report: the fitted pigment field (fit --pigment): model, degree, terms, coefficients (per term and target channel; per pair first in a joint fit), stderr, estimate, psnr_without (dB, the field set to 1); or null."""  # noqa: E501
    blur: Any = None
    """Fit report: the fitted blur's RMS width per axis in pixels at the skin's median depth and slope, per channel: sigma_px, stderr_px (null where undetermined), depth, slope, resolved (every channel at least a pixel); with fit --focal-px also mm_per_px and sigma_mm; or null."""  # noqa: E501
    warnings: list[str] | None = None
    """Fit report: warnings the fit raised."""
    inputs: Any = None
    """Fit report: how each pair's depth and mask were obtained when not both given as files (fit --distance, a mask made from the pair), and held: the parameters the inputs cannot determine, each with its value and why; or null."""  # noqa: E501


#: Keys a params JSON file may have besides :data:`PARAMS_KEYS`: the schema
#: version, the model choice and the report the estimator writes. Defined by
#: :class:`ParamsFile`; add a key there, not here.
PARAMS_OPTIONAL_KEYS = tuple(k for k in ParamsFile.model_fields if k not in PARAMS_KEYS)


def params_json_schema() -> dict:
    """The JSON Schema of a params file, generated from :class:`ParamsFile`.

    ``docs/params-schema.json`` is this, written with ``json.dumps(..., indent=2)``.

    Examples
    --------
    >>> schema = params_json_schema()
    >>> schema["additionalProperties"], schema["required"][:2]
    (False, ['sss_level', 'correction'])
    """
    schema = ParamsFile.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    return schema


# ------------------------------------------------------------------- errors


def _shown(value) -> str:
    try:
        return json.dumps(value)
    except (TypeError, ValueError):
        return repr(value)


def _check_keys(keys, name: str) -> None:
    allowed = PARAMS_KEYS + PARAMS_OPTIONAL_KEYS
    for key in keys:
        if key not in allowed:
            raise InvalidInputError(
                f"{name}: unknown key {key!r}{did_you_mean(key, allowed)}; expected {', '.join(PARAMS_KEYS)} "
                f"and optionally {', '.join(PARAMS_OPTIONAL_KEYS)}",
                field=name,
            )
    missing = [k for k in PARAMS_KEYS if k not in keys]
    if missing:
        raise InvalidInputError(f"{name}: missing key(s) {', '.join(missing)}", field=name)


def _check_version(content: Mapping, name: str) -> None:
    version = content.get("schema_version", 1)
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise InvalidInputError(
            f"{name}: schema_version: expected an integer >= 1, got {_shown(version)}",
            field=name,
        )
    if version > SCHEMA_VERSION:
        raise InvalidInputError(
            f"{name}: written by a newer invsss (schema_version {version}; this one reads up "
            f"to {SCHEMA_VERSION}); upgrade invsss to read it",
            field=name,
        )


def _without_nulls(value):
    """``value`` with every null replaced by 0.0, so only the non-null entries get checked."""
    if isinstance(value, list):
        return [_without_nulls(v) for v in value]
    return 0.0 if value is None else value


def _message(error: ErrorDetails, content: Mapping, name: str) -> str:
    """One line for pydantic's first error, naming the key and the value as written."""
    key = str(error["loc"][0])  # a field's name
    value = content.get(key)
    if key == "model":
        return f"{name}: model must be one of {', '.join(MODELS)}, got {_shown(value)}"
    if key == "tap_weights":
        return (
            f"{name}: tap_weights must be one of {', '.join(TAP_WEIGHTS)} or a list of "
            f"7 numbers, got {_shown(value)}"
        )
    where = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in error["loc"][1:])
    if error["type"] == "missing":
        return f"{name}: {key}{where} is missing"
    # For numbers, our own walk names the first bad entry as the user wrote it
    # (pydantic's location inside a union names the union's members instead).
    entries, label = None, key
    if key in PARAMS_KEYS:
        entries = value
    elif key == "estimate" and isinstance(value, Mapping) and len(error["loc"]) > 1:
        inner = error["loc"][1]
        entries = value.get(inner) if inner in PARAMS_KEYS else None
        label = f"estimate.{inner}"
    if label.split(".")[-1] in ("weights", "variances") and not isinstance(entries, list):
        return f"{name}: {label}: expected a list of numbers, got {_shown(entries)}"
    if entries is not None:
        try:
            number_array(_without_nulls(entries), label, name)
        except InvalidInputError as err:
            return str(err)
    expected = error["msg"][0].lower() + error["msg"][1:]
    if error["type"] in ("float_type", "int_type"):
        expected = "expected a number" if error["type"] == "float_type" else "expected an integer"
    elif error["type"] == "bool_type":
        expected = "expected true or false"
    elif error["type"] == "extra_forbidden":
        expected = "unknown key"
    shown = _shown(error.get("input"))
    return f"{name}: {key}{where}: {expected}, got {shown}"


def _validated(content: Mapping, name: str) -> ParamsFile:
    _check_version(content, name)
    _check_keys(content, name)
    try:
        return ParamsFile.model_validate(dict(content))
    except ValidationError as err:
        raise InvalidInputError(_message(err.errors()[0], content, name)) from None


# ---------------------------------------------------------------- reading


def _check_result_complete(path: str) -> None:
    """Refuse a params file whose result directory says its run did not finish."""
    # A hand-written file, or a result written before manifests, has no state to check.
    directory = os.path.dirname(os.path.abspath(path))
    state = result_state(directory)
    if state == "incomplete":
        raise InvalidInputError(
            f"{path}: belongs to an incomplete result (the run that wrote it was "
            "interrupted); re-run it",
            path=path,
        )
    if state == "damaged":
        # Not an interruption (manifests are written atomically): the file was changed.
        raise InvalidInputError(
            f"{path}: its result's manifest {os.path.join(directory, MANIFEST_NAME)} is damaged "
            "(not a JSON object), so whether the result is whole is unknown; re-run it",
            path=path,
        )


def _null_entries(value, where: str) -> list[str]:
    """Names of the null entries of a number or nested list, spelt as a fit's
    ``undetermined`` spells them: ``["sss_level"]``, ``["weights[2]", ...]`` or
    ``["weights[2,0]", ...]``."""
    def indices(v, index):
        if isinstance(v, list):
            return [found for i, item in enumerate(v) for found in indices(item, (*index, i))]
        return [index] if v is None else []

    return [entry_name(where, i) if i else where for i in indices(value, ())]


def _filled(value, estimate):
    """``value`` with each null entry taken from ``estimate`` (same nesting), the rest kept."""
    if isinstance(value, list):
        return [_filled(v, e) for v, e in zip(value, estimate)]
    return estimate if value is None else value


def _fill_from_estimate(values: dict, estimate: Estimate | None, name: str) -> list[str]:
    """Fill the null entries of ``values`` in place from ``estimate``; return their names."""
    nulls = {k: _null_entries(v, k) for k, v in values.items()}
    nulls = {k: entries for k, entries in nulls.items() if entries}
    if not nulls:
        return []
    if estimate is None:
        raise InvalidInputError(
            f"{name}: {', '.join(nulls)} is null (undetermined by the fit); "
            "give a number, or re-fit with --fix",
            field=name,
        )
    for key in nulls:
        point = getattr(estimate, key)
        if np.shape(point) != np.shape(_without_nulls(values[key])):
            raise InvalidInputError(
                f"{name}: estimate.{key} has shape {np.shape(point)}, but {key} has shape "
                f"{np.shape(_without_nulls(values[key]))}; cannot fill its null entries",
                field=name,
            )
        values[key] = _filled(values[key], point)
    return [entry for entries in nulls.values() for entry in entries]


def read_params(path) -> tuple[SSSParams, dict]:
    """Read a params JSON file.

    The file is one JSON object with the keys :data:`PARAMS_KEYS`
    (``weights`` a list, or a list of per-channel lists; ``variances`` a list)
    and optionally any of :data:`PARAMS_OPTIONAL_KEYS` (schema:
    :class:`ParamsFile`). Any other key is an error, so a misspelt key never
    silently falls back to a default; numbers must be JSON numbers.

    A fit's params file holds ``null`` where the data did not determine a
    value, and its point estimate under ``estimate``. Only those null entries
    are filled from ``estimate`` (an edited entry beside them is kept); a
    warning names them and ``extras["filled_from_estimate"]`` lists them
    (``["weights[2]", "weights[3]"]``).

    Returns
    -------
    params : SSSParams
    extras : dict
        The optional keys present in the file (``model``, ``tap_weights``, the
        estimator's report) as written, without ``schema_version``.

    Raises
    ------
    InvalidInputError
        Missing file, invalid JSON, missing or unknown keys, a value that is
        not a JSON number where one is expected, values that break the
        constraints of :meth:`SSSParams.check`, an unknown ``model`` or
        ``tap_weights``, a newer ``schema_version``, a null without an
        ``estimate``, or a file in a result directory whose
        ``invsss-manifest.json`` says the run did not complete.

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
        raise InvalidInputError(f"{name}: params file not found", field=name) from None
    except (OSError, UnicodeDecodeError) as err:
        raise InvalidInputError(f"{name}: cannot read params file ({one_line(err)})", field=name) from None
    try:
        content = json.loads(text)
    except json.JSONDecodeError as err:
        raise InvalidInputError(
            f"{name}: invalid JSON at line {err.lineno} column {err.colno} ({err.msg})",
            field=name,
        ) from None
    if not isinstance(content, dict):
        raise InvalidInputError(f"{name}: expected a JSON object with the parameter keys", field=name)
    _check_result_complete(name)
    params, filled = _params_of(content, _validated(content, name), name)
    extras = {k: content[k] for k in content if k not in PARAMS_KEYS and k != "schema_version"}
    fit_report = any(key in content for key in ("gauge", "converged", "iterations"))
    if "depth_unit" not in extras and content.get("schema_version", 1) < 2 and fit_report:
        # A fit's file from before the unit was recorded; a file written by hand
        # without one has always meant mm and is read so silently.
        warnings.warn(
            f"{name}: written before params files recorded the depth unit (schema_version "
            f"{content.get('schema_version', 1)}); reading its parameters as for depth in mm",
            InputNotice, stacklevel=2,
        )
    if filled:
        # A renderer needs numbers: use the estimate that produced the fit's
        # image for exactly the entries the data did not determine, and say so,
        # except for entries the file's model does not use (a burley fit's weights):
        # they change nothing it renders.
        extras["filled_from_estimate"] = filled
        model = content.get("model")
        used = get_model(model).parameters if model in MODEL_NAMES else frozenset(PARAM_NAMES)
        mattering = _entries_of(filled, used)
        if mattering:
            warnings.warn(
                f"{name}: {', '.join(mattering)} not determined by the fit; using its point estimate",
                stacklevel=2,
            )
    return params, extras


def warn_filled_for_model(name, extras: Mapping, model: str) -> None:
    """Warn about the entries :func:`read_params` filled from the fit's estimate that
    ``model`` uses and the file's own model does not.

    :func:`read_params` warns only about filled entries the file's model uses (a
    ``burley`` fit's weights change nothing it renders); a caller that renders or
    exports the file with another model (``--model``) calls this with that model.

    Examples
    --------
    >>> import warnings
    >>> extras = {"model": "burley", "filled_from_estimate": ["weights[0]", "weights[1]"]}
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     warn_filled_for_model("p.json", extras, "sog")
    >>> print(caught[0].message)
    p.json: weights[0], weights[1] not determined by the burley fit; model sog uses them, with their point estimate
    """
    own = extras.get("model")
    if model == own or own not in MODEL_NAMES or model not in MODEL_NAMES:
        return
    only_there = get_model(model).parameters - get_model(own).parameters
    newly = _entries_of(extras.get("filled_from_estimate") or (), only_there)
    if newly:
        warnings.warn(f"{os.fspath(name)}: {', '.join(newly)} not determined by the {own} fit; model {model} uses "
                      "them, with their point estimate", stacklevel=2)


def _entries_of(entries, parameters) -> list[str]:
    """Those of ``entries`` (``"maxdd"``, ``"weights[2]"``: :func:`entry_name`'s) that belong to ``parameters``."""
    return [entry for entry in entries if entry.split("[")[0] in parameters]


def _params_of(content: Mapping, parsed: ParamsFile, name: str) -> tuple[SSSParams, list[str]]:
    """The parameters of a validated file's content, null entries filled from its
    estimate, checked as :meth:`SSSParams.check` checks them; and the filled entries."""
    values = {k: content[k] for k in PARAMS_KEYS}
    filled = _fill_from_estimate(values, parsed.estimate, name)
    return SSSParams.from_dict(values, source=name), filled


# ---------------------------------------------------------------- writing


def _to_json(value):
    # NumPy/JAX scalars and arrays, as found in an estimator's report.
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def write_params(path, mapping) -> None:
    """Write parameters (and optional report keys) as JSON, atomically.

    ``schema_version`` (:data:`SCHEMA_VERSION`) is written first unless the
    mapping has it.

    Parameters
    ----------
    path : str or os.PathLike
    mapping : Mapping or SSSParams
        The keys :func:`read_params` accepts; arrays become lists. Content that
        :func:`read_params` would reject (unknown keys, a string for a number,
        values outside the parameters' domain, a null without an ``estimate``)
        is rejected here, so every file this writes can be read back.

    Raises
    ------
    InvalidInputError
        Unknown keys, values the schema or :meth:`SSSParams.check` refuses or
        that are not JSON-serialisable, a missing directory.

    Examples
    --------
    >>> import json, tempfile, os, invsss
    >>> path = os.path.join(tempfile.mkdtemp(), "params.json")
    >>> invsss.write_params(path, invsss.SSSParams(900.0, 0.0, 1.0, [1.0], [2.0]))
    >>> list(json.load(open(path)))[:2]
    ['schema_version', 'sss_level']
    """
    name = os.fspath(path)
    if isinstance(mapping, SSSParams):
        mapping = mapping.to_dict()
    if not isinstance(mapping, Mapping):
        raise InvalidInputError(
            f"{name}: expected a mapping or SSSParams to write, got {type(mapping).__name__}",
            field=name,
        )
    try:
        # Through JSON and back: what gets checked is exactly what gets written.
        content = json.loads(json.dumps(dict(mapping), default=_to_json))
    except (TypeError, ValueError) as err:
        raise InvalidInputError(f"{name}: cannot write params ({one_line(err)})", field=name) from None
    content = {"schema_version": SCHEMA_VERSION, **content}
    # The values too (NaN, sss_level <= 0, shapes that disagree): read_params
    # would refuse them.
    _params_of(content, _validated(content, name), name)
    write_text_atomic(name, json.dumps(content, indent=2) + "\n")
