"""The points of a sweep: grid, zipped lists and quasi-random samples.

Each way of varying options gives a list of rows (``{key: value}``):

* ``grid``: the Cartesian product of the value lists, first key outermost;
* ``zip``: the lists walked in step (all of one length);
* ``sample``: ``n`` points in a box, from a scrambled Sobol' sequence
  (:class:`scipy.stats.qmc.Sobol`) or uniform random numbers, both seeded, so
  the same file always gives the same points. Keys listed in ``log`` are
  sampled uniformly in their logarithm (scales such as ``sss_level``).

The sweep is the product of the three lists of rows (an absent one counts as a
single empty row). Keys are dotted paths into the options (``fix.maxdd``);
TOML's dotted keys and sub-tables give the same paths.
"""

from __future__ import annotations

import itertools
import math
import warnings

import numpy as np

from ..validation import InvalidInputError
from .schema import SampleSpec

__all__ = ["flatten", "grid_rows", "zip_rows", "sample_rows", "combine", "set_path", "row_count"]


def flatten(table: dict, prefix: str = "") -> dict:
    """``{"fix": {"maxdd": [..]}}`` -> ``{"fix.maxdd": [..]}`` (lists are leaves).

    Examples
    --------
    >>> flatten({"fix": {"maxdd": [1, 2]}, "solver": ["lm"]})
    {'fix.maxdd': [1, 2], 'solver': ['lm']}
    """
    flat = {}
    for key, value in table.items():
        path = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten(value, f"{path}."))
        else:
            flat[path] = value
    return flat


def _value_lists(table: dict, where: str, name: str) -> dict:
    flat = flatten(table)
    for key, values in flat.items():
        if not isinstance(values, list) or not values:
            raise InvalidInputError(
                f"{name}: {where}.{key}: expected a non-empty list of values, got {values!r}"
            )
    return flat


def grid_rows(table: dict, name: str) -> list[dict]:
    """Every combination of the ``grid`` table's value lists.

    Examples
    --------
    >>> grid_rows({"a": [1, 2], "b": ["x", "y"]}, "e.toml")
    [{'a': 1, 'b': 'x'}, {'a': 1, 'b': 'y'}, {'a': 2, 'b': 'x'}, {'a': 2, 'b': 'y'}]
    """
    flat = _value_lists(table, "grid", name)
    keys = list(flat)
    return [dict(zip(keys, combo)) for combo in itertools.product(*(flat[k] for k in keys))]


def zip_rows(table: dict, name: str) -> list[dict]:
    """The ``zip`` table's value lists taken in step.

    Examples
    --------
    >>> zip_rows({"solver": ["lm", "bfgs"], "max_steps": [50, 200]}, "e.toml")
    [{'solver': 'lm', 'max_steps': 50}, {'solver': 'bfgs', 'max_steps': 200}]
    """
    flat = _value_lists(table, "zip", name)
    if not flat:
        return [{}]
    lengths = {key: len(values) for key, values in flat.items()}
    if len(set(lengths.values())) > 1:
        shown = ", ".join(f"{k} has {n}" for k, n in lengths.items())
        raise InvalidInputError(f"{name}: zip: the lists must have one length, but {shown}")
    keys = list(flat)
    return [dict(zip(keys, values)) for values in zip(*(flat[k] for k in keys))]


def sample_rows(sample: SampleSpec | None, name: str) -> list[dict]:
    """``sample.n`` points in the box ``sample.ranges`` (seeded; see the module docstring).

    Examples
    --------
    >>> rows = sample_rows(SampleSpec(n=4, ranges={"maxdd": [0.0, 1.0]}, seed=1), "e.toml")
    >>> len(rows), all(0.0 <= r["maxdd"] <= 1.0 for r in rows)
    (4, True)
    """
    if sample is None:
        return [{}]
    ranges = flatten(sample.ranges)
    if not ranges:
        raise InvalidInputError(f"{name}: sample.ranges: expected at least one KEY = [low, high]")
    lows, highs = [], []
    for key, bounds in ranges.items():
        ok = (
            isinstance(bounds, list) and len(bounds) == 2
            and all(isinstance(b, (int, float)) and not isinstance(b, bool) for b in bounds)
            and bounds[0] < bounds[1]
        )
        if not ok:
            raise InvalidInputError(
                f"{name}: sample.ranges.{key}: expected [low, high] with low < high, got {bounds!r}"
            )
        if key in sample.log and bounds[0] <= 0:
            raise InvalidInputError(f"{name}: sample.ranges.{key}: a log-scale range needs low > 0, got {bounds!r}")
        lows.append(math.log(bounds[0]) if key in sample.log else float(bounds[0]))
        highs.append(math.log(bounds[1]) if key in sample.log else float(bounds[1]))
    for key in sample.log:
        if key not in ranges:
            raise InvalidInputError(f"{name}: sample.log: {key!r} has no range in sample.ranges")
    dimension = len(ranges)
    if sample.method == "sobol":
        from scipy.stats import qmc

        engine = qmc.Sobol(d=dimension, scramble=True, seed=sample.seed)
        with warnings.catch_warnings():
            # A point count that is not a power of two loses Sobol's balance
            # properties, which is the user's choice here, not a mistake.
            warnings.simplefilter("ignore", UserWarning)
            unit = engine.random(sample.n)
    else:
        unit = np.random.default_rng(sample.seed).random((sample.n, dimension))
    points = np.asarray(lows) + unit * (np.asarray(highs) - np.asarray(lows))
    rows = []
    for point in points:
        row = {}
        for key, value in zip(ranges, point):
            value = math.exp(value) if key in sample.log else float(value)
            row[key] = float(np.float64(value).round(12))  # stable text in the trial id
        rows.append(row)
    return rows


def combine(parts: list[list[dict]], name: str) -> list[dict]:
    """The product of several lists of rows; a key may come from one part only."""
    owner: dict = {}
    for index, rows in enumerate(parts):
        for key in rows[0] if rows else ():
            if key in owner and owner[key] != index:
                raise InvalidInputError(f"{name}: {key!r} is varied twice (in two of grid, zip, sample)")
            owner[key] = index
    return [dict(itertools.chain.from_iterable(r.items() for r in combo)) for combo in itertools.product(*parts)]


def row_count(grid: dict, zipped: dict, sample: SampleSpec | None) -> tuple[int, list[str]]:
    """How many rows :func:`combine` would make of the three tables, without making them.

    Returns the count and its factors as text (``["grid 1000 x 1000", "sample 8"]``),
    so that a sweep too large to run is refused before its rows take minutes to
    build (about 1 ms a trial). A value that is not a list counts as one: the
    expansion reports it.

    Examples
    --------
    >>> row_count({"a": [1, 2], "b": [1, 2, 3]}, {"c": [1, 2]}, SampleSpec(n=5, ranges={"d": [0, 1]}))
    (60, ['grid 2 x 3', 'zip 2', 'sample 5'])
    """
    sizes = [len(v) if isinstance(v, list) else 1 for v in flatten(grid).values()]
    zipped_sizes = [len(v) if isinstance(v, list) else 1 for v in flatten(zipped).values()]
    factors, count = [], 1
    if sizes:
        count *= math.prod(sizes)
        factors.append("grid " + " x ".join(str(n) for n in sizes))
    if zipped_sizes:
        count *= max(zipped_sizes)
        factors.append(f"zip {max(zipped_sizes)}")
    if sample is not None:
        count *= sample.n
        factors.append(f"sample {sample.n}")
    return count, factors


def set_path(options: dict, path: str, value) -> None:
    """Set ``options["fix"]["maxdd"]`` for ``path = "fix.maxdd"`` (creating tables)."""
    *parents, leaf = path.split(".")
    table = options
    for part in parents:
        table = table.setdefault(part, {})
        if not isinstance(table, dict):
            raise InvalidInputError(f"{path}: the base value of {part} is {table!r}, not a table to set {leaf} in")
    table[leaf] = value
