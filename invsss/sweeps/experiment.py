"""Reading an experiment file: :func:`load` and the :class:`Experiment` it returns.

:func:`load` parses the TOML with :mod:`tomllib`, checks every key and value
(:mod:`.schema`), locates the pairs (:mod:`.data`) and expands the trials
(:mod:`.axes`, :mod:`.trials`), so a mistake anywhere in the file is reported
before anything runs: one line naming the file, the key and what was expected.
Each trial's options are also checked the way the task will use them
(:class:`invsss.estimator.FitOptions` for a fit, the parameter constraints for a
render), so a bad value in one corner of a grid fails at once, not hours in.
"""

from __future__ import annotations

import dataclasses
import os
import tomllib

from pydantic import ValidationError

from ..validation import InvalidInputError
from .axes import combine, flatten, grid_rows, row_count, sample_rows, zip_rows
from .data import resolve_pairs
from .schema import ExperimentSpec, check_keys, first_error
from .trials import Trial, check_option_key, resolve_options, task_options_model, trial_id

__all__ = ["Experiment", "load", "MAX_TRIALS"]

#: The most trials :func:`load` expands unless told otherwise (``max_trials``,
#: ``invsss sweep --max-trials``): a sweep this large runs for days, and
#: expanding 10**6 trials alone took about 15 minutes without a word.
MAX_TRIALS = 100_000


@dataclasses.dataclass(frozen=True)
class Experiment:
    """A checked experiment file and its trials (see :func:`load`).

    Attributes
    ----------
    path : str
        The file, absolute.
    name : str
        ``name`` from the file, else the file name without extension.
    task : str
    description : str
    pairs : tuple of dict
        The pairs (``name`` and the four paths relative to the file's folder).
    trials : tuple of Trial
        In the order they are started.
    axes : tuple of str
        The keys the sweep varies, ``"pair"`` included when there is more than one pair.
    text : str
        The file's content, kept with the results.
    """

    path: str
    name: str
    task: str
    description: str
    pairs: tuple
    trials: tuple
    axes: tuple
    text: str


def _read_toml(path: str) -> tuple[str, dict]:
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except FileNotFoundError:
        raise InvalidInputError(f"{path}: experiment file not found") from None
    except OSError as err:
        raise InvalidInputError(f"{path}: cannot read the experiment file ({err.strerror})") from None
    try:
        text = raw.decode("utf-8")
        return text, tomllib.loads(text)
    except UnicodeDecodeError:
        raise InvalidInputError(f"{path}: expected a UTF-8 TOML file") from None
    except tomllib.TOMLDecodeError as err:
        raise InvalidInputError(f"{path}: invalid TOML ({err})") from None


def _check_axis_keys(spec: ExperimentSpec, name: str) -> None:
    from .axes import flatten

    model = task_options_model(spec.task)
    check_keys(spec.base, model, "base.", name)
    for where, table in (("grid", spec.grid), ("zip", spec.zip)):
        for path in flatten(table):
            check_option_key(path, spec.task, where, name)
    if spec.sample is not None:
        for path in flatten(spec.sample.ranges):
            check_option_key(path, spec.task, "sample.ranges", name)
    # An axis sets its key in every trial, so a [base] value of the same key would
    # be silently dropped: refuse the pair instead.
    axes = [(where, path) for where, table in (("grid", spec.grid), ("zip", spec.zip),
                                               ("sample.ranges", spec.sample.ranges if spec.sample else {}))
            for path in flatten(table)]
    for base in flatten(spec.base):
        for where, path in axes:
            if base == path or base.startswith(path + ".") or path.startswith(base + "."):
                raise InvalidInputError(
                    f"{name}: {where}.{path}: also set in [base] (base.{base}); the axis sets it in "
                    "every trial, so remove one of them"
                )


def _pair_rows(spec: ExperimentSpec, rows: list[dict], pairs: list[dict], name: str) -> list[dict]:
    """Add the pair axis: every pair in turn, unless the file varies ``pair`` itself."""
    names = [p["name"] for p in pairs]
    if spec.task == "fit-joint":
        return rows
    if rows and "pair" in rows[0]:
        for row in rows:
            if row["pair"] not in names:
                raise InvalidInputError(
                    f"{name}: pair {row['pair']!r} is not one of the data's pairs ({', '.join(names)})"
                )
        return rows
    return [{**row, "pair": n} for row in rows for n in names]


def _check_trial(trial: Trial, name: str, label: str) -> None:
    """Check the options as the task will use them, and that every pair has the
    buffers its light terms read."""
    from ..estimator.options import check_light_terms
    from ..forward.light_terms import NEEDED_BUFFERS
    from .data import BUFFER_FILES
    from .tasks import check_task_options

    try:
        check_task_options(trial.task, trial.options)
    except InvalidInputError as err:
        raise InvalidInputError(f"{name}: {label}: {err}") from None
    terms, held = check_light_terms(trial.options.get("light_terms") or None)
    for term, role in ((t, r) for t in (*terms, *held) for r in NEEDED_BUFFERS[t]):
        for pair in trial.pairs:
            if role not in pair:
                raise InvalidInputError(
                    f"{name}: {label}: light term {term!r} needs {BUFFER_FILES[role]} in pair "
                    f"{pair['name']!r} (or {role} = ... in its data.files entry)"
                )


def _check_trial_count(spec: ExperimentSpec, pairs: list[dict], name: str, max_trials: int) -> None:
    """Refuse an experiment of more than ``max_trials`` trials, counted before expanding it."""
    count, factors = row_count(spec.grid, spec.zip, spec.sample)
    varies_pair = "pair" in flatten(spec.grid) or "pair" in flatten(spec.zip)
    if spec.task != "fit-joint" and not varies_pair:
        count *= len(pairs)
        factors.append(f"{len(pairs)} pair(s)")
    if count > max_trials:
        raise InvalidInputError(
            f"{name}: {count:,} trials ({' x '.join(factors)}), more than the limit of {max_trials:,}; "
            f"vary fewer values, or raise the limit with --max-trials {count} (max_trials= in load)"
        )


def _label(index: int, row: dict) -> str:
    shown = ", ".join(f"{k}={v!r}" for k, v in row.items())
    return f"trial {index + 1}" + (f" ({shown})" if shown else "")


def load(path, *, max_trials: int = MAX_TRIALS) -> Experiment:
    """Read, check and expand an experiment file.

    Parameters
    ----------
    path : str or os.PathLike
        A TOML experiment file (format: :mod:`invsss.sweeps.schema`). Data
        paths in it are relative to its folder.
    max_trials : int
        Refuse a file of more trials than this (default :data:`MAX_TRIALS`),
        counted before they are expanded.

    Returns
    -------
    Experiment

    Raises
    ------
    InvalidInputError
        Unreadable or invalid TOML, an unknown key (the message names the
        nearest valid one), a value of the wrong type, pairs that cannot be
        found, a trial whose options the task refuses, or more than
        ``max_trials`` trials; one line each.

    Examples
    --------
    >>> import os, tempfile
    >>> from invsss.sweeps.data import PAIR_FILES
    >>> root = tempfile.mkdtemp(); os.mkdir(os.path.join(root, "face"))
    >>> for f in PAIR_FILES.values(): open(os.path.join(root, "face", f), "w").close()
    >>> path = os.path.join(root, "matrix.toml")
    >>> with open(path, "w") as f:
    ...     _ = f.write('task = "render"\\n[data]\\npairs = ["*/"]\\n[base]\\nmaxdd = 0.5\\n'
    ...                 '[grid]\\nsss_level = [300, 600]\\ncorrection = [800, 1500]\\n')
    >>> experiment = load(path)
    >>> len(experiment.trials), experiment.axes
    (4, ('sss_level', 'correction'))
    >>> experiment.trials[0].axes
    {'sss_level': 300, 'correction': 800, 'pair': 'face'}
    """
    if isinstance(max_trials, bool) or not isinstance(max_trials, int) or max_trials < 1:
        raise InvalidInputError(f"max_trials: expected a whole number >= 1, got {max_trials!r}")
    path = os.path.abspath(os.fspath(path))
    name = os.fspath(path)
    text, content = _read_toml(path)
    check_keys(content, ExperimentSpec, "", name)
    try:
        spec = ExperimentSpec.model_validate(content)
    except ValidationError as err:
        raise first_error(err, name) from None
    _check_axis_keys(spec, name)
    root = os.path.dirname(path)
    pairs = resolve_pairs(spec.data, root, name)
    _check_trial_count(spec, pairs, name, max_trials)
    sampled = frozenset(sample_rows(spec.sample, name)[0])
    rows = combine([grid_rows(spec.grid, name), zip_rows(spec.zip, name), sample_rows(spec.sample, name)], name)
    rows = _pair_rows(spec, rows, pairs, name)
    by_name = {p["name"]: p for p in pairs}
    trials: list[Trial] = []
    seen: dict[str, int] = {}  # trial id -> index of the row that made it
    for index, row in enumerate(rows):
        label = _label(index, {k: v for k, v in row.items() if k != "pair"})
        options = resolve_options(spec.task, spec.base, row, name, label, sampled)
        used = pairs if spec.task == "fit-joint" else [by_name[row["pair"]]]
        draft = Trial("", index, spec.task, options, tuple(used), dict(row), root,
                      spec.data.depth_scale, spec.data.linear_codes)
        trial = dataclasses.replace(draft, id=trial_id(draft.config))
        if trial.id in seen:
            raise InvalidInputError(
                f"{name}: {_label(index, row)} is the same configuration as trial {seen[trial.id] + 1}; "
                "remove the repeated value"
            )
        seen[trial.id] = index
        _check_trial(trial, name, _label(index, row))
        trials.append(trial)
    axes = tuple(k for k in (rows[0] if rows else {}) if k != "pair" or len(pairs) > 1)
    return Experiment(
        path=path,
        name=spec.name or os.path.splitext(os.path.basename(path))[0],
        task=spec.task,
        description=spec.description,
        pairs=tuple(pairs),
        trials=tuple(trials),
        axes=axes,
        text=text,
    )
