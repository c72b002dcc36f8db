"""The experiment file's schema: strict pydantic models and one-line errors.

An experiment file is TOML with these top-level keys (only ``task`` and ``data``
are required)::

    name = "render-matrix"            # a label for reports (default: the file name)
    description = "..."
    task = "render"                   # "fit", "fit-joint" or "render"

    [data]                            # the pairs
    pairs = ["../data_synthetic/*/"]  # folders or globs, relative to this file
    depth_scale = 1.0                 # multiplies every depth map
    linear_codes = false              # 8-bit images hold linear codes
    [[data.files]]                    # and/or explicit file sets
    name = "card"
    source = "a.exr"; target = "b.exr"; depth = "d.exr"; mask = "m.png"

    [base]                            # the task's options, shared by every trial
    n_starts = 1
    light_terms = "shift,grazing"     # needs normal.exr / light.exr in each pair

    [grid]                            # Cartesian product of value lists
    profile = ["thesis-nir", "deon-skin"]
    fix.maxdd = [0.05, 0.5]           # dotted keys reach into a table option

    [zip]                             # value lists walked in step
    solver = ["lm", "bfgs"]
    max_steps = [50, 200]

    [sample]                          # quasi-random or random points in boxes
    method = "sobol"                  # or "random"
    n = 8
    seed = 0
    log = ["sss_level"]               # keys sampled uniformly in log space
    ranges.sss_level = [300.0, 1200.0]

Every table refuses keys it does not know; :func:`check_keys` names the
unknown key and the closest known one, on one line, before pydantic sees the
content (pydantic's own message for an extra key does not say what was meant).
"""

from __future__ import annotations

import dataclasses
import difflib
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, create_model, field_validator

from ..validation import InvalidInputError

__all__ = [
    "TASKS",
    "FileSet",
    "DataSpec",
    "SampleSpec",
    "ExperimentSpec",
    "FitTaskOptions",
    "fit_options",
    "RenderTaskOptions",
    "FIX_NAMES",
    "check_keys",
    "first_error",
    "nearest",
]

#: The tasks an experiment can run.
TASKS = ("fit", "fit-joint", "render")

#: Parameters ``fix`` accepts (:func:`invsss.fit_pair`).
FIX_NAMES = ("sss_level", "correction", "maxdd", "weights", "variances")

_STRICT = ConfigDict(extra="forbid", strict=True)

_Numbers = list[float]
# A profile: a name (thesis-nir, deon-skin, jensen-skin1), a JSON file, or numbers.
_Profile = str | dict[str, _Numbers | list[_Numbers]]
# Tap weights: a set's name or 7 numbers.
_Taps = str | _Numbers | None


class FileSet(BaseModel):
    """One pair given file by file (``[[data.files]]``); ``normal``, ``light``,
    ``key``, ``fill_light``, ``thickness`` and ``key_irradiance`` are the optional buffers
    of the light-aware terms."""

    model_config = _STRICT
    name: str | None = None
    source: str
    target: str
    depth: str
    mask: str
    normal: str | None = None
    light: str | None = None
    key: str | None = None
    fill_light: str | None = None
    thickness: str | None = None
    key_irradiance: str | None = None


class DataSpec(BaseModel):
    """The ``[data]`` table: pair folders or globs, and/or explicit file sets."""

    model_config = _STRICT
    pairs: list[str] = []
    files: list[FileSet] = []
    depth_scale: float = Field(1.0, gt=0)
    linear_codes: bool = False


class SampleSpec(BaseModel):
    """The ``[sample]`` table: ``n`` points in the box given by ``ranges``."""

    model_config = _STRICT
    method: Literal["sobol", "random"] = "sobol"
    n: int = Field(ge=1)
    seed: int = 0
    ranges: dict = {}
    log: list[str] = []


class ExperimentSpec(BaseModel):
    """The whole file; ``base``, ``grid``, ``zip`` are checked against the task's options."""

    model_config = _STRICT
    name: str | None = None
    description: str = ""
    task: Literal["fit", "fit-joint", "render"]
    data: DataSpec
    base: dict = {}
    grid: dict = {}
    zip: dict = {}
    sample: SampleSpec | None = None


class _FitTaskBase(BaseModel):
    """Options of a ``fit`` / ``fit-joint`` trial: the fields of :class:`invsss.estimator.FitOptions`.

    Each field's name and default come from ``FitOptions`` (its one declaration);
    those whose value has no TOML form are spelled as :data:`_TOML_FORMS` says.
    ``robust = "none"`` turns the robust loss off (TOML has no null).
    ``light_terms`` takes the names as one string (``"shift,grazing"``, or
    ``"shift=1.3,grazing"`` to hold the shift) or a list of names; it needs
    ``normal.exr`` and ``light.exr`` in each pair folder (or ``normal`` and
    ``light`` in a file set). ``saturation`` is a clipping level (a number > 0)
    or ``"auto"``: the level of integer-coded targets (1.0, their top code), as
    ``invsss fit --saturation auto``; by default no pixel is left out.
    ``canvas = [height, width]`` pads every pair to that size so that pairs of
    different sizes compile once per worker (:mod:`invsss.estimator.canvas`).
    """

    model_config = _STRICT

    @field_validator("light_terms", mode="before", check_fields=False)
    @classmethod
    def _one_string(cls, value):
        # One spelling per choice ("shift,grazing"), so that equal choices give
        # equal trial ids; FitOptions checks the names.
        if isinstance(value, list) and all(isinstance(v, str) for v in value):
            value = ",".join(value)
        if isinstance(value, str) and value.strip().lower() in ("", "none"):
            return ""
        return value


#: The TOML spelling (type, default) of the FitOptions fields whose Python value
#: has none (TOML has no null or tuple); None keeps the field's own default.
_TOML_FORMS: dict[str, tuple[Any, Any]] = {
    "profile": (_Profile, None),
    "fix": (dict[str, float | _Numbers | list[_Numbers]], {}),
    "tap_weights": (_Taps, None),
    "robust": (str, None),
    "light_terms": (str, ""),
    "saturation": (Literal["auto"] | float | None, None),
    "canvas": (list[int] | None, None),
}
#: FitOptions fields an experiment file does not set (filled from others).
_NOT_IN_FILES = ("light_fixed",)
#: The annotations of the plain fields, as options.py writes them.
_PLAIN_TYPES = {"bool": bool, "int": int, "float": float, "str": str,
                "float | None": float | None, "str | None": str | None, "int | None": int | None}


def _fit_task_fields() -> dict:
    from ..estimator.options import FitOptions

    out = {}
    for field in dataclasses.fields(FitOptions):
        if field.name in _NOT_IN_FILES:
            continue
        if field.name in _TOML_FORMS:
            annotation, default = _TOML_FORMS[field.name]
            out[field.name] = (annotation, field.default if default is None else default)
        elif field.type in _PLAIN_TYPES:
            out[field.name] = (_PLAIN_TYPES[field.type], field.default)
        else:
            # A new option whose type has no plain TOML form: say where to add it.
            raise TypeError(f"FitOptions.{field.name}: add its TOML form to invsss.sweeps.schema._TOML_FORMS")
    return out


FitTaskOptions = create_model("FitTaskOptions", __base__=_FitTaskBase, **_fit_task_fields())
FitTaskOptions.__doc__ = _FitTaskBase.__doc__


def fit_options(options: dict):
    """The :class:`~invsss.estimator.FitOptions` of a trial's validated fit options.

    ``saturation = "auto"`` gives None: the runner resolves it from the trial's
    files before the fit (checking the other options needs no files).
    """
    from ..estimator.options import FitOptions

    keywords = dict(options)
    keywords["fix"] = keywords["fix"] or None
    keywords["robust"] = None if keywords["robust"] == "none" else keywords["robust"]
    if keywords.get("saturation") == "auto":
        keywords["saturation"] = None
    return FitOptions(**keywords)


class RenderTaskOptions(BaseModel):
    """Options of a ``render`` trial: the parameters to render with.

    ``weights`` and ``variances`` default to the named ``profile``'s.
    """

    model_config = _STRICT
    model: str = "sog"
    tap_weights: _Taps = None
    profile: _Profile = "thesis-nir"
    sss_level: float
    correction: float
    maxdd: float
    weights: _Numbers | list[_Numbers] | None = None
    variances: _Numbers | None = None


def nearest(key: str, known) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``known``, or the list of them.

    Examples
    --------
    >>> nearest("sss_levle", ["sss_level", "maxdd"])
    " (did you mean 'sss_level'?)"
    """
    known = list(known)
    close = difflib.get_close_matches(key, known, n=1, cutoff=0.5)
    if close:
        return f" (did you mean {close[0]!r}?)"
    return f" (expected one of {', '.join(known)})"


def _submodel(annotation):
    """The pydantic model a field holds directly or as list items, else None."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation, False
    for arg in getattr(annotation, "__args__", ()) or ():
        if isinstance(arg, type) and issubclass(arg, BaseModel):
            return arg, getattr(annotation, "__origin__", None) is list
    return None, False


def check_keys(content, model: type[BaseModel], where: str, name: str) -> None:
    """Refuse the first key of ``content`` (a mapping) that ``model`` does not know.

    ``where`` is the dotted location of ``content`` in the file (``""`` at the
    top), ``name`` the file, for the message. Nested models are walked.

    Examples
    --------
    >>> check_keys({"task": "fit", "dta": {}}, ExperimentSpec, "", "e.toml")
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: e.toml: unknown key 'dta' (did you mean 'data'?)
    """
    if not isinstance(content, dict):
        return
    fields = model.model_fields
    for key, value in content.items():
        dotted = f"{where}{key}"
        if key not in fields:
            raise InvalidInputError(f"{name}: unknown key {dotted!r}{nearest(str(key), fields)}")
        sub, many = _submodel(fields[key].annotation)
        if sub is None:
            continue
        if many and isinstance(value, list):
            for i, item in enumerate(value):
                check_keys(item, sub, f"{dotted}[{i}].", name)
        else:
            check_keys(value, sub, f"{dotted}.", name)


def first_error(err: ValidationError, name: str, prefix: str = "") -> InvalidInputError:
    """One line for pydantic's first error: where, what was expected, what was given."""
    error = err.errors()[0]
    loc = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in error["loc"]).lstrip(".")
    where = f"{prefix}{loc}" if loc else prefix.rstrip(".") or "file"
    if error["type"] == "missing":
        return InvalidInputError(f"{name}: {where} is missing")
    message = error["msg"][0].lower() + error["msg"][1:]
    shown = repr(error.get("input"))
    if len(shown) > 60:
        shown = shown[:57] + "..."
    return InvalidInputError(f"{name}: {where}: {message}, got {shown}")
