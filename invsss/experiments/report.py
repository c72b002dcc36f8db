"""A finished (or running) sweep as a table, a CSV file and plots: :func:`write_report`.

Written into ``OUT/report/``:

* ``results.csv`` -- every column of :func:`invsss.experiments.results`
  (lists as JSON text);
* ``results.parquet`` with ``parquet=True`` -- the same table through
  pandas (needs ``pip install 'invsss[report]'``: pandas and pyarrow), lists
  kept as lists;
* ``<metric>_vs_<axis>.png`` -- loss, PSNR and SSIM against each numeric axis,
  one line per pair;
* for fits, ``params_vs_<axis>.png`` -- the fitted ``sss_level``,
  ``correction``, ``maxdd`` against each numeric axis with their standard
  errors as error bars, and ``params_by_pair.png`` -- their spread across the
  pairs;
* for a render sweep with two numeric axes, ``contact_<pair>.png`` -- the
  rendered images laid out on those axes with the PSNR under each (the
  thesis's sssLevel x correction matrix, made from the results).

The table :func:`write_report` returns is plain text, one line per trial. A
folder that holds the trials of experiments with different tasks (a render
matrix and a fit written into one ``--out``) gets one table per task, each
under a ``task <name>: N trial(s)`` line, and each task's plots in
``OUT/report/<task>/``: their columns and metrics differ.
"""

from __future__ import annotations

import csv
import json
import math
import os

from ..validation import InvalidInputError
from .results import flat_rows

__all__ = ["write_report", "format_table"]

_METRICS = ("loss", "psnr", "ssim")
_SCALARS = ("sss_level", "correction", "maxdd")


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _cell(value) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}" if math.isfinite(value) else str(value)
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return str(value)


def format_table(rows: list[dict], axes: list[str]) -> str:
    """Plain-text table: id, status, the axes, loss/PSNR/SSIM, seconds, error.

    Examples
    --------
    >>> print(format_table([{"id": "abc", "status": "done", "x": 1.5, "loss": 0.25,
    ...                      "psnr": 30.0, "ssim": 0.9, "seconds": 2.0, "error": None}], ["x"]))
    id   status  x    loss  psnr  ssim  seconds  error
    abc  done    1.5  0.25  30    0.9   2        -
    """
    columns = ["id", "status", *axes, *_METRICS, "seconds", "error"]
    cells = [columns] + [[_cell(row.get(c)) for c in columns] for row in rows]
    widths = [max(len(line[i]) for line in cells) for i in range(len(columns))]
    return "\n".join(
        "  ".join(text.ljust(width) for text, width in zip(line, widths)).rstrip() for line in cells
    )


def _write_csv(rows: list[dict], path: str) -> None:
    columns = list(dict.fromkeys(key for row in rows for key in row))
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(columns)
        for row in rows:
            writer.writerow(["" if row.get(c) is None else
                             json.dumps(row[c]) if isinstance(row.get(c), (list, dict)) else row[c]
                             for c in columns])


def _numeric_axes(rows: list[dict], axes: list[str]) -> list[str]:
    return [a for a in axes if a != "pair" and all(_is_number(r.get(a)) for r in rows)
            and len({r.get(a) for r in rows}) > 1]


def _groups(rows: list[dict]) -> dict:
    groups: dict = {}
    for row in rows:
        groups.setdefault(row.get("pair", ""), []).append(row)
    return groups


def _plot_metrics(plt, rows, axis, folder) -> str:
    figure, panels = plt.subplots(1, len(_METRICS), figsize=(4 * len(_METRICS), 3.2))
    for panel, metric in zip(panels, _METRICS):
        for label, group in _groups(rows).items():
            points = sorted((r[axis], r[metric]) for r in group if _is_number(r.get(metric)))
            if points:
                panel.plot(*zip(*points), "o-", label=label or None, markersize=4)
        panel.set_xlabel(axis)
        panel.set_ylabel(metric)
        if metric == "loss":
            panel.set_yscale("log")
    if any(label for label in _groups(rows)):
        panels[-1].legend(fontsize=7)
    figure.tight_layout()
    path = os.path.join(folder, f"metrics_vs_{axis}.png")
    figure.savefig(path, dpi=100)
    plt.close(figure)
    return path


def _plot_params(plt, rows, axis, folder) -> str:
    figure, panels = plt.subplots(1, len(_SCALARS), figsize=(4 * len(_SCALARS), 3.2))
    for panel, name in zip(panels, _SCALARS):
        for label, group in _groups(rows).items():
            points = sorted((r[axis], r[f"param.{name}"], r.get(f"stderr.{name}") or 0.0)
                            for r in group if _is_number(r.get(f"param.{name}")))
            if points:
                x, y, err = zip(*points)
                panel.errorbar(x, y, yerr=err, fmt="o-", capsize=3, markersize=4, label=label or None)
        panel.set_xlabel(axis)
        panel.set_ylabel(name)
    if any(label for label in _groups(rows)):
        panels[-1].legend(fontsize=7)
    figure.tight_layout()
    path = os.path.join(folder, f"params_vs_{axis}.png")
    figure.savefig(path, dpi=100)
    plt.close(figure)
    return path


def _plot_spread(plt, rows, folder) -> str:
    pairs = sorted({r["pair"] for r in rows})
    figure, panels = plt.subplots(1, len(_SCALARS), figsize=(4 * len(_SCALARS), 3.2))
    for panel, name in zip(panels, _SCALARS):
        for k, pair in enumerate(pairs):
            values = [(r[f"param.{name}"], r.get(f"stderr.{name}") or 0.0) for r in rows
                      if r["pair"] == pair and _is_number(r.get(f"param.{name}"))]
            if values:
                y, err = zip(*values)
                panel.errorbar([k] * len(y), y, yerr=err, fmt="o", capsize=3, markersize=4, color=f"C{k}")
        panel.set_xticks(range(len(pairs)), pairs, rotation=30, fontsize=7)
        panel.set_ylabel(name)
    figure.tight_layout()
    path = os.path.join(folder, "params_by_pair.png")
    figure.savefig(path, dpi=100)
    plt.close(figure)
    return path


def _contact_sheets(plt, rows, axes, out, folder) -> list[str]:
    import numpy as np

    from ..io import read_image
    from ..io.colour import linear_to_srgb

    first, second = axes[:2]
    written = []
    for label, group in _groups(rows).items():
        rows_values = sorted({r[first] for r in group})
        cols_values = sorted({r[second] for r in group})
        figure, panels = plt.subplots(len(rows_values), len(cols_values), squeeze=False,
                                      figsize=(2.2 * len(cols_values), 2.7 * len(rows_values)))
        for panel in panels.flat:
            panel.axis("off")
        for r in group:
            path = os.path.join(out, "trials", r["id"], "render.exr")
            if r["status"] != "done" or not os.path.isfile(path):
                continue
            image = read_image(path)
            shown = linear_to_srgb(np.clip(image / max(float(image.max()), 1e-12), 0.0, 1.0))
            panel = panels[rows_values.index(r[first]), cols_values.index(r[second])]
            panel.imshow(shown if shown.shape[2] == 3 else shown[..., 0], cmap="gray")
            panel.set_title(f"{first}={_cell(r[first])}\n{second}={_cell(r[second])}", fontsize=7)
            panel.text(0.5, -0.06, f"PSNR {_cell(r.get('psnr'))} dB", transform=panel.transAxes,
                       ha="center", va="top", fontsize=7)
        figure.tight_layout()
        name = f"contact_{label}.png" if label else "contact.png"
        path = os.path.join(folder, name)
        figure.savefig(path, dpi=100)
        plt.close(figure)
        written.append(path)
    return written


def _write_parquet(rows: list[dict], path: str) -> None:
    import pandas

    table = pandas.DataFrame(rows)
    # A column mixing numbers and None or lists is stored as it is; an empty
    # column of None has no type Parquet knows, so it is written as text.
    for column in table.columns:
        if table[column].isna().all():
            table[column] = table[column].astype("string")
    table.to_parquet(path, index=False)


def _check_parquet_available() -> None:
    try:
        import pandas  # noqa: F401
        import pyarrow  # noqa: F401
    except ImportError as err:
        raise InvalidInputError(
            f"--parquet: needs pandas and pyarrow ({err.name} is not installed); "
            "pip install 'invsss[report]'"
        ) from None


def write_report(out, *, plots: bool = True, parquet: bool = False) -> tuple[str, list[str]]:
    """Write ``OUT/report/`` (see the module docstring); return the table and the files.

    Raises
    ------
    InvalidInputError
        ``out`` holds no sweep, or ``parquet=True`` without pandas and pyarrow.
    """
    out = os.fspath(out)
    if parquet:
        _check_parquet_available()
    rows, meta = flat_rows(out)
    if not rows:
        raise InvalidInputError(f"{out}: the sweep has no trials")
    folder = os.path.join(out, "report")
    os.makedirs(folder, exist_ok=True)
    written = [os.path.join(folder, "results.csv")]
    _write_csv(rows, written[0])
    if parquet:
        written.append(os.path.join(folder, "results.parquet"))
        _write_parquet(rows, written[-1])
    tasks: dict = {}
    for row in rows:
        tasks.setdefault(row["task"], []).append(row)
    if len(tasks) == 1:
        meta_axes = list(meta.get("axes", []))
        axes = [a for a in dict.fromkeys([*meta_axes, "pair"]) if any(a in r for r in rows)]
        written.extend(_task_plots(rows, axes, rows[0]["task"], out, folder) if plots else [])
        return format_table(rows, axes), written
    # Trials of several experiments: a fit's and a render's rows share no columns
    # worth comparing, so each task has its own table and plots.
    tables = []
    for task, task_rows in tasks.items():
        # The pair last, as in a folder of one experiment.
        axes = [a for a in (*(a for a in meta["row_axes"] if a != "pair"), "pair")
                if any(r.get(a) is not None for r in task_rows)]
        tables.append(f"task {task}: {len(task_rows)} trial(s)\n{format_table(task_rows, axes)}")
        if plots:
            written.extend(_task_plots(task_rows, axes, task, out, os.path.join(folder, task)))
    return "\n\n".join(tables), written


def _task_plots(rows: list[dict], axes: list[str], task: str, out: str, folder: str) -> list[str]:
    """The plots of the done trials of one task (module docstring) in ``folder``."""
    done = [r for r in rows if r["status"] == "done"]
    if not done:
        return []
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(folder, exist_ok=True)
    written = []
    numeric = _numeric_axes(done, axes)
    for axis in numeric:
        written.append(_plot_metrics(plt, done, axis, folder))
        if task != "render":
            written.append(_plot_params(plt, done, axis, folder))
    if task == "fit" and len({r.get("pair") for r in done}) > 1:
        written.append(_plot_spread(plt, done, folder))
    if task == "render" and len(numeric) >= 2:
        written.extend(_contact_sheets(plt, done, numeric, out, folder))
    return written
