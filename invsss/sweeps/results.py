"""Reading a sweep's results back: :func:`results`.

One flat row per trial, the shape a table or a plot wants: ``id``,
``status`` (``pending``, ``running``, ``done``, ``failed``, or ``interrupted``: marked
running by a sweep that no longer runs, which runs it again when resumed), ``task`` (a
folder may hold the trials of several experiments), one column per varied key
(``sss_level``, ``fix.maxdd``, ``pair``),
the metrics (``loss``, ``psnr``, ``ssim``, and for fits ``sigma``,
``converged``, ``iterations``), the parameters (``param.sss_level``,
``param.weights``...; ``param.light_shift``, ``param.grazing``, ``param.incidence`` and
``param.law``, a list of albedos per source channel, where a trial fitted light terms),
their standard errors (``stderr.sss_level``...),
``seconds`` (the trial's total time), ``compute_seconds`` (the fit or render
alone), ``host``, ``pid``, ``attempts``, ``warnings`` and ``error``. A pandas
``DataFrame`` when pandas is installed (``pip install 'invsss[report]'``),
else a list of dicts with the same keys.
"""

from __future__ import annotations

import os

from ..forward.params import PARAM_NAMES
from ..validation import InvalidInputError
from .store import DATABASE_NAME, ResultsStore, sweep_running

#: The light terms' unknowns a fit trial may report beside the five parameters
#: (the values of invsss.estimator.parametrisation.LIGHT_UNKNOWNS, written out so
#: that reading results does not import JAX).
LIGHT_PARAMS = ("light_shift", "grazing", "incidence", "law")

__all__ = ["results", "flat_rows"]


def flat_rows(out) -> tuple[list[dict], dict]:
    """The trials of the sweep in ``out`` as flat dicts, and the sweep's metadata.

    The metadata is that of the last experiment run into ``out``, plus
    ``"row_axes"``: the varied keys of every trial, in the order of the columns.
    """
    out = os.fspath(out)
    if not os.path.isfile(os.path.join(out, DATABASE_NAME)):
        raise InvalidInputError(f"{out}: no sweep results here (no {DATABASE_NAME}); run invsss sweep first")
    with ResultsStore(out, readonly=True) as store:
        stored, meta = store.rows(), store.meta()
    alive = sweep_running(out)
    # The file's order (grid keys first, then zip, sample, pair), then any key of older trials.
    axes = list(dict.fromkeys([*meta.get("axes", []), "pair", *(k for row in stored for k in row["axes"])]))
    axes = [key for key in axes if any(key in row["axes"] for row in stored)]
    # The light terms' columns, only in a sweep where some trial fitted them.
    light = [name for name in LIGHT_PARAMS if any(name in (row["params"] or {}) for row in stored)]
    rows = []
    for row in stored:
        status = "interrupted" if row["status"] == "running" and not alive else row["status"]
        flat = {"id": row["id"], "status": status, "task": row["task"]}
        flat.update({key: row["axes"].get(key) for key in axes})
        metrics = row["metrics"] or {}
        fit_only = () if row["task"] == "render" else ("sigma", "converged", "iterations")
        for key in ("loss", "psnr", "ssim", *fit_only):
            flat[key] = metrics.get(key)
        for name in PARAM_NAMES:
            flat[f"param.{name}"] = (row["params"] or {}).get(name)
        if row["task"] != "render":
            for name in PARAM_NAMES:
                flat[f"stderr.{name}"] = (row["stderr"] or {}).get(name)
            for name in light:
                flat[f"param.{name}"] = (row["params"] or {}).get(name)
                flat[f"stderr.{name}"] = (row["stderr"] or {}).get(name)
        timings = row["timings"] or {}
        flat["seconds"] = timings.get("total")
        flat["compute_seconds"] = timings.get("compute")
        flat["host"] = row["host"]
        flat["pid"] = row["pid"]
        flat["attempts"] = row["attempts"]
        flat["warnings"] = row["warnings"] or []
        flat["error"] = row["error"]
        rows.append(flat)
    return rows, {**meta, "row_axes": axes}


def results(out, *, frame: bool | None = None):
    """The results of the sweep in ``out``, one row per trial (see the module docstring).

    Parameters
    ----------
    out : str or os.PathLike
        A sweep's output folder.
    frame : bool, optional
        True: a pandas DataFrame (pandas must be installed); False: a list of
        dicts; None (default): a DataFrame if pandas is installed.

    Raises
    ------
    InvalidInputError
        ``out`` holds no sweep, or ``frame=True`` without pandas.

    Examples
    --------
    >>> import os, tempfile, numpy as np, invsss, invsss.sweeps as ex
    >>> root = tempfile.mkdtemp(); pair = os.path.join(root, "face"); os.mkdir(pair)
    >>> for name, image in [("source.exr", np.ones((8, 8, 3))), ("target.exr", np.ones((8, 8))),
    ...         ("depth.exr", np.full((8, 8), 500.0)), ("mask.png", np.ones((8, 8)))]:
    ...     invsss.write_image(os.path.join(pair, name), image.astype(np.float32))
    >>> with open(os.path.join(root, "e.toml"), "w") as f:
    ...     _ = f.write('task = "render"\\n[data]\\npairs = ["face/"]\\n[base]\\ncorrection = 0.0\\n'
    ...                 'maxdd = 0.5\\n[grid]\\nsss_level = [300.0, 600.0]\\n')
    >>> _ = ex.run(os.path.join(root, "e.toml"), os.path.join(root, "out"), log=None)
    >>> rows = results(os.path.join(root, "out"), frame=False)
    >>> [(row["sss_level"], row["pair"], row["status"]) for row in rows]
    [(300.0, 'face', 'done'), (600.0, 'face', 'done')]
    """
    rows, _ = flat_rows(out)
    if frame is False:
        return rows
    try:
        import pandas
    except ImportError:
        if frame:
            raise InvalidInputError(
                "results(frame=True): pandas is not installed; pip install 'invsss[report]'"
            ) from None
        return rows
    return pandas.DataFrame(rows)
