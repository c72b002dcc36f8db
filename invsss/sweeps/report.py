"""A finished (or running) sweep as a table, a CSV file and plots: :func:`write_report`.

Written into ``OUT/report/``:

* ``results.csv`` -- every column of :func:`invsss.sweeps.results`
  (lists as JSON text);
* ``results.parquet`` with ``parquet=True`` -- the same table through
  pandas (needs ``pip install 'invsss[report]'``: pandas and pyarrow), lists
  kept as lists where one column can hold them (a grey and an RGB fit's
  weights cannot: that column is JSON text);
* ``<metric>_vs_<axis>.png`` -- loss, PSNR and SSIM against each axis with more
  than one value, a line per pair and per value of the other grid and zip axes
  (the legend beside the panels); text values (a model's name) as categories,
  sampled axes as points, on a log axis where the ``[sample]`` table says ``log``;
* for fits, ``params_vs_<axis>.png`` -- the fitted ``sss_level``,
  ``correction``, ``maxdd`` against each such axis with their standard
  errors as error bars, and ``params_by_pair.png`` -- their spread across the
  pairs;
* for a render sweep with two numeric grid axes (not sampled; at most
  :data:`CONTACT_SHEET_MAX` values each), ``contact_<pair>.png`` -- the
  rendered images laid out on those axes with the PSNR under each (the
  thesis's sssLevel x correction matrix, made from the results).

Plots an earlier report drew and this one does not (an axis no longer varied,
a folder that gained a second task) are removed, so that every plot there is
of the results as they are. The table :func:`write_report` returns is plain
text, one line per trial. A
folder that holds the trials of experiments with different tasks (a render
matrix and a fit written into one ``--out``) gets one table per task, each
under a ``task <name>: N trial(s)`` line, and each task's plots in
``OUT/report/<task>/``: their columns and metrics differ.
"""

from __future__ import annotations

import csv
import dataclasses
import fnmatch
import io
import json
import math
import os
import tomllib

from ..io.writing import atomic_output, write_texts_atomic
from ..validation import InvalidInputError
from .axes import flatten
from .results import flat_rows

__all__ = ["SampleKeys", "format_table", "plot_series", "plotted_axes", "write_parquet", "write_report"]

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


def format_table(rows: list[dict], axes: list[str], fitted: tuple = ()) -> str:
    """Plain-text table: id, status, the axes, loss/PSNR/SSIM, the ``fitted``
    columns (a fit's ``param.sss_level``...), seconds, error.

    Examples
    --------
    >>> print(format_table([{"id": "abc", "status": "done", "x": 1.5, "loss": 0.25,
    ...                      "psnr": 30.0, "ssim": 0.9, "seconds": 2.0, "error": None}], ["x"]))
    id   status  x    loss  psnr  ssim  seconds  error
    abc  done    1.5  0.25  30    0.9   2        -
    """
    columns = ["id", "status", *axes, *_METRICS, *fitted, "seconds", "error"]
    cells = [columns] + [[_cell(row.get(c)) for c in columns] for row in rows]
    widths = [max(len(line[i]) for line in cells) for i in range(len(columns))]
    return "\n".join(
        "  ".join(text.ljust(width) for text, width in zip(line, widths)).rstrip() for line in cells
    )


def _write_csv(rows: list[dict], path: str) -> None:
    columns = list(dict.fromkeys(key for row in rows for key in row))
    text = io.StringIO(newline="")
    writer = csv.writer(text)
    writer.writerow(columns)
    for row in rows:
        writer.writerow(["" if row.get(c) is None else
                         json.dumps(row[c]) if isinstance(row.get(c), (list, dict)) else row[c]
                         for c in columns])
    # A report is made again from the results: its earlier file is replaced, whole.
    write_texts_atomic({path: text.getvalue()}, overwrite=True)


def _report_folder(folder: str) -> None:
    """Create ``folder`` for the report, or refuse in one line before anything is written."""
    if os.path.lexists(folder) and not os.path.isdir(folder):
        raise InvalidInputError(f"{folder}: is in the way of the report (not a folder); move it away")
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as err:
        raise InvalidInputError(f"{folder}: cannot create the report's folder ({err.strerror or err})") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InvalidInputError(f"{folder}: cannot write the report, the folder is not writable")


def _save_figure(figure, path: str, **options) -> None:
    """``figure.savefig`` to a temporary beside ``path``, renamed over it when whole."""
    with atomic_output(path) as temporary:
        figure.savefig(temporary, **options)


def _numeric_axes(rows: list[dict], axes: list[str]) -> list[str]:
    return [a for a in axes if a != "pair" and all(_is_number(r.get(a)) for r in rows)
            and len({r.get(a) for r in rows}) > 1]


def plotted_axes(rows: list[dict], axes: list[str]) -> list[str]:
    """Axes with more than one value, all numbers or all text: a plot each
    (text values, such as a model's name, as categories)."""
    return [a for a in axes if a != "pair" and len({_cell(r.get(a)) for r in rows}) > 1
            and (all(_is_number(r.get(a)) for r in rows) or all(isinstance(r.get(a), str) for r in rows))]


@dataclasses.dataclass(frozen=True)
class SampleKeys:
    """Which axes of the sweep's experiment file are sampled, and which of them in log space."""

    sampled: frozenset = frozenset()
    log: frozenset = frozenset()

    @classmethod
    def of(cls, meta: dict) -> SampleKeys:
        # The experiment's own text is in the store; an older store, or one whose
        # text no longer parses, has no sampled axes as far as the plots know.
        try:
            sample = tomllib.loads(meta.get("text") or "").get("sample") or {}
        except tomllib.TOMLDecodeError:
            return cls()
        return cls(frozenset(flatten(sample.get("ranges") or {})), frozenset(sample.get("log") or ()))


def plot_series(rows: list[dict], axis: str, axes: list[str], sampled) -> dict:
    """The rows of each line of a plot against ``axis``, keyed ``(pair, others)``:
    one line per pair and per value of every other grid or zip axis (sampled axes
    change from trial to trial, so they split nothing); ``others`` says which
    values (``"y=5, model=sog"``, or ``""``)."""
    others = [a for a in axes if a not in (axis, "pair") and a not in sampled
              and len({_cell(r.get(a)) for r in rows}) > 1]
    series: dict = {}
    for row in rows:
        key = (str(row.get("pair", "")), ", ".join(f"{a}={_cell(row.get(a))}" for a in others))
        series.setdefault(key, []).append(row)
    return series


def _x_positions(rows: list[dict], axis: str):
    """``(x of a value, tick positions, tick labels)``: numbers as they are, text
    values as categories in the order the trials meet them."""
    if all(_is_number(r.get(axis)) for r in rows):
        values = sorted({r[axis] for r in rows})
        integers = all(float(v).is_integer() for v in values) and len(values) <= 12
        # Integer axes (n_starts) get a tick per value, not 1.5 and 2.5.
        return (lambda v: v), (values if integers else None), None
    categories = list(dict.fromkeys(r.get(axis) for r in rows))
    return categories.index, list(range(len(categories))), [_cell(c) for c in categories]


_LINE_STYLES = ("-", "--", ":", "-.")
_MARKERS = ("o", "s", "^", "D", "v", "P")


def _plot_against(plt, rows, axis, axes, keys: SampleKeys, names, y_of, err_of, path) -> str:
    """One panel per name in ``names``: ``y_of(row, name)`` against ``axis``, a line
    (for a sampled axis or categories, points) per :func:`plot_series`: a colour per
    pair and a line style and marker per value of the other axes, each with its
    own legend beside the panels."""
    from matplotlib.lines import Line2D

    series = plot_series(rows, axis, axes, keys.sampled)
    pairs = list(dict.fromkeys(pair for pair, _ in series))
    others = list(dict.fromkeys(other for _, other in series))
    # The colour tells the pairs apart; with one pair, the other axes' values.
    coloured = pairs if len(pairs) > 1 else others
    palette = plt.get_cmap("tab10" if len(coloured) <= 10 else "tab20")

    def colour(k):
        return palette(k) if len(coloured) <= 20 else plt.get_cmap("viridis")(k / (len(coloured) - 1))

    def style(other):
        k = others.index(other) if len(pairs) > 1 else 0
        return _LINE_STYLES[k % len(_LINE_STYLES)], _MARKERS[k % len(_MARKERS)]

    x_of, ticks, tick_labels = _x_positions(rows, axis)
    joined = tick_labels is None and axis not in keys.sampled
    figure, panels = plt.subplots(1, len(names), figsize=(4 * len(names), 3.2), squeeze=False)
    for panel, name in zip(panels[0], names):
        for (pair, other), group in series.items():
            points = sorted((x_of(r[axis]), y_of(r, name), err_of(r, name)) for r in group
                            if _is_number(y_of(r, name)))
            if not points:
                continue
            x, y, err = zip(*points)
            line, marker = style(other)
            panel.errorbar(x, y, yerr=err if any(err) else None, linestyle=line if joined else "none",
                           marker=marker, capsize=3, markersize=4,
                           color=colour(coloured.index(pair if len(pairs) > 1 else other)))
        panel.set_xlabel(axis)
        panel.set_ylabel(name)
        if axis in keys.log:
            panel.set_xscale("log")
        if tick_labels is not None:
            panel.set_xticks(ticks, tick_labels, rotation=30, fontsize=7)
        elif ticks is not None:
            panel.set_xticks(ticks)
        if name == "loss":
            panel.set_yscale("log")
    legends = []
    if any(coloured):
        legends.append([Line2D([], [], color=colour(k), marker="o", label=label) for k, label in enumerate(coloured)])
    if len(pairs) > 1 and len(others) > 1:
        legends.append([Line2D([], [], color="0.3", linestyle=style(o)[0] if joined else "none",
                               marker=style(o)[1], label=o) for o in others])
    # Beside the panels, not over the last one; long lists in two columns.
    top = 1.0
    for handles in legends:
        legend = figure.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0, top), fontsize=7,
                               ncol=1 if len(handles) <= 20 else 2, frameon=False)
        figure.add_artist(legend)
        top -= 0.06 + 0.045 * min(len(handles), 20)
    figure.tight_layout()
    _save_figure(figure, path, dpi=100, bbox_inches="tight")
    plt.close(figure)
    return path


def _plot_metrics(plt, rows, axis, axes, keys, folder) -> str:
    return _plot_against(plt, rows, axis, axes, keys, _METRICS, lambda r, m: r.get(m), lambda r, m: 0.0,
                         os.path.join(folder, f"metrics_vs_{axis}.png"))


def _plot_params(plt, rows, axis, axes, keys, folder) -> str:
    return _plot_against(plt, rows, axis, axes, keys, _SCALARS, lambda r, n: r.get(f"param.{n}"),
                         lambda r, n: r.get(f"stderr.{n}") or 0.0, os.path.join(folder, f"params_vs_{axis}.png"))


def _plot_spread(plt, rows, folder) -> str:
    pairs = sorted({r["pair"] for r in rows})
    figure, panels = plt.subplots(1, len(_SCALARS), figsize=(4 * len(_SCALARS), 3.2))
    for panel, name in zip(panels, _SCALARS):
        for k, pair in enumerate(pairs):
            values = [(r[f"param.{name}"], r.get(f"stderr.{name}") or 0.0) for r in rows
                      if r["pair"] == pair and _is_number(r.get(f"param.{name}"))]
            if values:
                y, err = zip(*values)
                panel.errorbar([k] * len(y), y, yerr=err, fmt="o", capsize=3, markersize=4, color=f"C{k % 10}")
        panel.set_xticks(range(len(pairs)), pairs, rotation=30, fontsize=7)
        panel.set_ylabel(name)
    figure.tight_layout()
    path = os.path.join(folder, "params_by_pair.png")
    _save_figure(figure, path, dpi=100)
    plt.close(figure)
    return path


#: A contact sheet is drawn for two grid axes of at most this many values each.
CONTACT_SHEET_MAX = 12


def _contact_sheets(plt, rows, axes, out, folder) -> list[str]:
    import numpy as np

    from ..io import read_image
    from ..io.colour import linear_to_srgb

    first, second = axes[:2]
    written = []
    for (label, _), group in plot_series(rows, first, [first, second, "pair"], {second}).items():
        rows_values = sorted({r[first] for r in group})
        cols_values = sorted({r[second] for r in group})
        if max(len(rows_values), len(cols_values)) > CONTACT_SHEET_MAX:
            continue
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
        _save_figure(figure, path, dpi=100)
        plt.close(figure)
        written.append(path)
    return written


def write_parquet(rows: list[dict], path: str) -> None:
    """``rows`` (one dict per trial) as a Parquet table at ``path``, written whole."""
    import pandas
    import pyarrow

    table = pandas.DataFrame(rows)
    # A column mixing numbers and None or lists is stored as it is; an empty
    # column of None has no type Parquet knows, so it is written as text.
    for column in table.columns:
        if table[column].isna().all():
            table[column] = table[column].astype("string")
        elif any(isinstance(v, (list, dict)) for v in table[column]):
            try:
                pyarrow.array(list(table[column]))
            except (pyarrow.ArrowInvalid, pyarrow.ArrowTypeError):
                # Nestings Parquet cannot hold in one column (a grey fit's weights,
                # [w], beside an RGB fit's, [[r, g, b]]): JSON text, as in the CSV.
                table[column] = [None if v is None else json.dumps(v) for v in table[column]]
    with atomic_output(path) as temporary:
        table.to_parquet(temporary, index=False)


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

    Each file is written whole, through a temporary file renamed over it, and
    replaces the one an earlier report wrote; a report folder that cannot be
    written to is refused before anything is written.

    Raises
    ------
    InvalidInputError
        ``out`` holds no sweep, ``parquet=True`` without pandas and pyarrow, a
        report folder that is a file or cannot be created or written to, or a
        file that cannot be written.
    """
    out = os.fspath(out)
    if parquet:
        _check_parquet_available()
    rows, meta = flat_rows(out)
    if not rows:
        raise InvalidInputError(f"{out}: the sweep has no trials")
    keys = SampleKeys.of(meta)
    folder = os.path.join(out, "report")
    _report_folder(folder)
    written = [os.path.join(folder, "results.csv")]
    _write_csv(rows, written[0])
    if parquet:
        written.append(os.path.join(folder, "results.parquet"))
        write_parquet(rows, written[-1])
    tasks: dict = {}
    for row in rows:
        tasks.setdefault(row["task"], []).append(row)
    if len(tasks) == 1:
        meta_axes = list(meta.get("axes", []))
        axes = [a for a in dict.fromkeys([*meta_axes, "pair"]) if any(a in r for r in rows)]
        written.extend(_task_plots(rows, axes, rows[0]["task"], out, folder, keys) if plots else [])
        _remove_stale_plots(folder, written, plots)
        return format_table(rows, axes, _fitted_columns(rows[0]["task"])), written
    # Trials of several experiments: a fit's and a render's rows share no columns
    # worth comparing, so each task has its own table and plots.
    tables = []
    for task, task_rows in tasks.items():
        # The pair last, as in a folder of one experiment.
        axes = [a for a in (*(a for a in meta["row_axes"] if a != "pair"), "pair")
                if any(r.get(a) is not None for r in task_rows)]
        tables.append(f"task {task}: {len(task_rows)} trial(s)\n"
                      f"{format_table(task_rows, axes, _fitted_columns(task))}")
        if plots:
            written.extend(_task_plots(task_rows, axes, task, out, os.path.join(folder, task), keys))
    _remove_stale_plots(folder, written, plots)
    return "\n\n".join(tables), written


#: The names of the plots a report draws (``fnmatch`` patterns).
_PLOT_NAMES = ("metrics_vs_*.png", "params_vs_*.png", "params_by_pair.png", "contact_*.png", "contact.png")


def _remove_stale_plots(folder: str, written: list[str], plots: bool) -> None:
    """Remove the plots of an earlier report that this one did not draw again (an
    axis no longer varied, a folder that gained a second task and moved its plots
    into ``report/<task>/``), so that every plot in ``folder`` is of these results.
    Only the report's own file names are touched; ``--no-plots`` keeps them all."""
    if not plots:
        return
    kept = {os.path.abspath(p) for p in written}
    for directory, _, files in os.walk(folder):
        for name in files:
            path = os.path.abspath(os.path.join(directory, name))
            if path not in kept and any(fnmatch.fnmatch(name, pattern) for pattern in _PLOT_NAMES):
                try:
                    os.remove(path)
                except OSError as err:
                    raise InvalidInputError(
                        f"{path}: cannot remove this plot of an earlier report ({err.strerror or err})"
                    ) from None


def _fitted_columns(task: str) -> tuple:
    """The estimates a fit's table shows (the rest are in results.csv)."""
    return () if task == "render" else tuple(f"param.{name}" for name in _SCALARS)


def _task_plots(rows: list[dict], axes: list[str], task: str, out: str, folder: str,
                keys: SampleKeys) -> list[str]:
    """The plots of the done trials of one task (module docstring) in ``folder``."""
    done = [r for r in rows if r["status"] == "done"]
    if not done:
        return []
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    _report_folder(folder)
    written = []
    for axis in plotted_axes(done, axes):
        written.append(_plot_metrics(plt, done, axis, axes, keys, folder))
        if task != "render":
            written.append(_plot_params(plt, done, axis, axes, keys, folder))
    if task == "fit" and len({r.get("pair") for r in done}) > 1:
        written.append(_plot_spread(plt, done, folder))
    # Sampled points fill no grid: a sheet of them would be almost all empty panels.
    grid = [a for a in _numeric_axes(done, axes) if a not in keys.sampled]
    if task == "render" and len(grid) >= 2:
        written.extend(_contact_sheets(plt, done, grid, out, folder))
    return written
