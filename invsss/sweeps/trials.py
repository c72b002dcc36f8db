"""Trials: the resolved configurations of a sweep, each with a stable id.

A trial is everything one run needs: the task, its options with every default
filled in, the pair(s) it uses (paths relative to the experiment file), the
depth scale and whether 8-bit codes are linear. Its id is the first 12 hex
digits of the SHA-256 of that configuration as canonical JSON (sorted keys, no
spaces), so the same configuration gets the same id in every run, on every
machine, whatever order the file lists its axes in; that is what lets a sweep
resume, and what keeps a result from being attributed to a changed
configuration.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import json

from pydantic import ValidationError

from ..forward.models import MODEL_NAMES, get_model
from ..validation import InvalidInputError
from .axes import set_path
from .data import BUFFER_FILES
from .schema import FIX_NAMES, FitTaskOptions, RenderTaskOptions, first_error, nearest

__all__ = ["Trial", "trial_id", "task_options_model", "check_option_key", "resolve_options"]


def task_options_model(task: str):
    """The pydantic model of a task's options."""
    return RenderTaskOptions if task == "render" else FitTaskOptions


def trial_id(config: dict) -> str:
    """First 12 hex digits of the SHA-256 of ``config`` as canonical JSON.

    Examples
    --------
    >>> trial_id({"b": 1, "a": [1.0, "x"]}) == trial_id({"a": [1.0, "x"], "b": 1})
    True
    >>> len(trial_id({}))
    12
    """
    text = json.dumps(config, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


#: The fit options of the first release; every later one (align, vignetting,
#: highlights, light_terms, saturation, canvas, and any added to FitOptions
#: since) leaves a trial's id unchanged while it holds its default.
FIRST_OPTIONS = ("model", "profile", "fix", "gauge", "solver", "n_starts", "max_steps", "tap_weights", "robust")
#: The later fit options with their defaults (an experiment file's, :class:`~.schema.FitTaskOptions`).
LATER_OPTIONS = {name: field.default for name, field in FitTaskOptions.model_fields.items()
                 if name not in FIRST_OPTIONS}


@dataclasses.dataclass(frozen=True)
class Trial:
    """One run of a sweep.

    Attributes
    ----------
    id : str
        :func:`trial_id` of :attr:`config`.
    index : int
        Position in the expansion (the order trials are started in).
    task : str
        ``"fit"``, ``"fit-joint"`` or ``"render"``.
    options : dict
        The task's options, every default filled in.
    pairs : tuple of dict
        ``{"name", "source", "target", "depth", "mask"}`` and, where present,
        ``"normal"`` and ``"light"``; paths relative to ``root``.
    axes : dict
        The values this trial varies (``{"fix.maxdd": 0.05, "pair": "fran_front"}``):
        what reports plot against.
    root : str
        The experiment file's folder (absolute); not part of the id.
    depth_scale : float
    linear_codes : bool
    """

    id: str
    index: int
    task: str
    options: dict
    pairs: tuple
    axes: dict
    root: str
    depth_scale: float = 1.0
    linear_codes: bool = False

    @property
    def config(self) -> dict:
        """What the id hashes: the trial without its position, axes and root.

        Options added after the first release are left out while they hold
        their default (:data:`LATER_OPTIONS`), so a sweep started before they
        existed keeps its trial ids and resumes instead of starting over.
        """
        options = {k: v for k, v in self.options.items()
                   if not (k in LATER_OPTIONS and v == LATER_OPTIONS[k])}
        if options.get("gauge") == "auto":
            # The gauge a fit resolves "auto" to: the ids of sweeps from before
            # "auto" existed (when "variances" was the default) stay the same.
            options["gauge"] = get_model(options.get("model", MODEL_NAMES[0])).default_gauge
        # The buffers count only for a trial that reads them: a folder that
        # gained light.exr keeps the ids of its trials without light terms, one
        # that gained key.exr those without the law, one that gained
        # fill_light.exr those without the fill, and one that gained thickness.exr
        # and key_irradiance.exr those without the transmission.
        buffers = [role for role in BUFFER_FILES if role not in self.buffer_roles]
        return {
            "task": self.task,
            "options": options,
            "pairs": [{k: v for k, v in p.items() if k not in buffers} for p in self.pairs],
            "depth_scale": self.depth_scale,
            "linear_codes": self.linear_codes,
        }

    @property
    def buffer_roles(self) -> tuple[str, ...]:
        """The buffers this trial reads: none without light terms, the key light's
        image only with the law, the other lights' direction only with the fill, the
        thickness and the key light's irradiance only with the transmission."""
        from ..estimator.options import check_light_terms

        if not self.options.get("light_terms"):
            return ()
        terms, held = check_light_terms(self.options["light_terms"])
        named = (*terms, *held)
        return ("normal", "light", *(("key",) if "law" in named else ()),
                *(("fill_light",) if "fill" in named else ()),
                *(("thickness", "key_irradiance") if "transmission" in named else ()))

    def to_dict(self) -> dict:
        """A plain mapping (for another process, or JSON); :meth:`from_dict` reverses it."""
        return {**dataclasses.asdict(self), "pairs": [dict(p) for p in self.pairs]}

    @classmethod
    def from_dict(cls, content: dict) -> Trial:
        return cls(**{**content, "pairs": tuple(content["pairs"])})


def check_option_key(path: str, task: str, where: str, name: str) -> None:
    """Refuse an axis key that names no option of ``task`` (nearest valid key in the message)."""
    fields = task_options_model(task).model_fields
    head, _, rest = path.partition(".")
    known = [*fields] + ([] if task == "fit-joint" else ["pair"])
    if head not in known:
        # A parameter's name is an axis of fix, not an option of its own (grid.sss_level).
        hint = (f" (did you mean '{where}.fix.{path}'?)" if "fix" in known and path in FIX_NAMES
                else nearest(head, known))
        raise InvalidInputError(f"{name}: unknown key '{where}.{path}'{hint}")
    if head == "fix":
        if not rest or rest not in FIX_NAMES:
            raise InvalidInputError(
                f"{name}: unknown key '{where}.{path}'{nearest(rest, ['fix.' + n for n in FIX_NAMES]) if rest else ''}"
                + ("" if rest else f": fix takes one of {', '.join(FIX_NAMES)}")
            )
    elif rest and head != "profile":
        raise InvalidInputError(f"{name}: '{where}.{path}': {head} is a single option, not a table")


def resolve_options(task: str, base: dict, row: dict, name: str, label: str, sampled=()) -> dict:
    """``base`` with the row's axis values set, validated, every default filled in.

    Keys in ``sampled`` come from ``[sample]``: a sampled count (``n_starts``) is
    rounded to the nearest integer.
    """
    options = copy.deepcopy(base)
    integers = {k for k, f in task_options_model(task).model_fields.items() if f.annotation is int}
    for path, value in row.items():
        if path == "pair":
            continue
        if path in integers and path in sampled:
            value = int(round(value))
        try:
            set_path(options, path, value)
        except InvalidInputError as err:
            raise InvalidInputError(f"{name}: {label}: {err}") from None
    for key in options.get("fix", {}) if isinstance(options.get("fix"), dict) else ():
        if key not in FIX_NAMES:
            raise InvalidInputError(f"{name}: {label}: unknown key 'fix.{key}'{nearest(key, FIX_NAMES)}")
    try:
        validated = task_options_model(task).model_validate(options)
    except ValidationError as err:
        raise first_error(err, name, f"{label}: ") from None
    return validated.model_dump()
