"""report.png reads: distinct loss ticks, a profile label clear of its neighbours, and
the estimate of an undetermined parameter shown with its mark.

The page is drawn from a :class:`~invsss.estimator.result.FitResult` built from its
fields (the numbers of a path-traced fit, data_synthetic/pt_face_940), so no fit runs.
"""

from __future__ import annotations

import numpy as np
import pytest

from invsss.cli.report import UNDETERMINED, parameter_lines, plot_convergence, report_figure
from invsss.estimator.result import FitResult
from invsss.forward.params import SSSParams

# A path-traced fit's loss: four starts, then rounds, all within 2.28e-4 .. 2.43e-4
# (less than a decade, where a log axis falls back to linear ticks).
_HISTORY = np.concatenate([np.linspace(2.425e-4, 2.30e-4, 10), np.linspace(2.292e-4, 2.284e-4, 30)])
_STAGES = (("start 1", 0, 10), ("refine", 10, 40))
_WEIGHTS = [0.1, 0.2, 0.3, 0.25, 0.15]
_VARIANCES = [8.749, 2.099, 0.549, 0.5574, 1.194]


def _result(history=_HISTORY, stages=_STAGES, size=16) -> FitResult:
    values = {"sss_level": 1015.0, "correction": 183.7, "maxdd": 40.0,
              "weights": np.array(_WEIGHTS), "variances": np.array(_VARIANCES)}
    return FitResult(
        params=SSSParams(**values), values=values,
        stderr={"sss_level": 130.0, "correction": 61.0, "maxdd": None,
                "weights": [0.079, None, 0.05, 0.05, None], "variances": None},
        undetermined=("maxdd", "weights[1]", "weights[4]"), fixed={"variances": _VARIANCES},
        gauge="variances", loss=float(history[-1]), sigma=0.015, psnr=25.4, ssim=0.949, converged=True,
        iterations=int(np.size(history)), history=np.asarray(history), gain=np.array([1.02]),
        offset=np.array([0.0079]), mix=None, fitted=[np.full((size, size, 1), 0.5)], warnings=(),
        model="sog", tap_weights="thesis", stages=stages,
        start_profile={"weights": np.full(5, 0.2), "variances": np.array(_VARIANCES)},
    )


def _visible_labels(ax) -> list[tuple[float, str]]:
    """``(tick value, label)`` of the y tick labels drawn inside the axis' view."""
    ax.figure.canvas.draw()
    low, high = ax.get_ylim()
    ticks = ax.yaxis.get_major_ticks() + ax.yaxis.get_minor_ticks()
    return [(t.get_loc(), t.label1.get_text()) for t in ticks
            if low <= t.get_loc() <= high and t.label1.get_visible() and t.label1.get_text()]


def _convergence_axis(history, stages):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5.0, 3.0), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    plot_convergence(ax, _result(history, stages))
    return ax


def test_loss_ticks_over_less_than_a_decade_are_distinct_and_read_as_their_values():
    labels = _visible_labels(_convergence_axis(_HISTORY, _STAGES))
    assert len(labels) >= 3
    texts = [text for _, text in labels]
    assert len(set(texts)) == len(texts), texts
    for value, text in labels:
        assert float(text.replace("\u2212", "-")) == pytest.approx(value, rel=1e-3), (value, text)


def test_loss_ticks_over_decades_stay_plain_powers_of_ten():
    history = np.geomspace(1e-1, 1e-5, 30)
    labels = _visible_labels(_convergence_axis(history, (("fit", 0, 30),)))
    texts = [text for _, text in labels]
    assert len(set(texts)) == len(texts) >= 3
    assert all(text.replace("\u2212", "-") in {"1e-01", "1e-02", "1e-03", "1e-04", "1e-05"} for text in texts), texts


def test_undetermined_weights_show_their_estimate_with_a_mark_and_a_note():
    lines = parameter_lines(_result())
    weights = next(line for line in lines if line.startswith("weights"))
    # Determined entries with their standard error; undetermined ones with the mark, none with "--".
    assert "0.1±0.079" in weights and "0.3±0.05" in weights
    assert f"0.2{UNDETERMINED}" in weights and f"0.15{UNDETERMINED}" in weights and "--" not in weights
    assert f"2 undetermined {UNDETERMINED}" in weights
    maxdd = next(line for line in lines if line.startswith("maxdd"))
    assert maxdd.split()[1] == f"40{UNDETERMINED}"
    notes = [line for line in lines if line.startswith(UNDETERMINED)]
    assert len(notes) == 1 and "undetermined" in notes[0]


def test_a_fit_with_everything_determined_has_no_mark():
    result = _result()
    result = FitResult(**{**{f: getattr(result, f) for f in result.__dataclass_fields__}, "undetermined": ()})
    assert not any(UNDETERMINED in line for line in parameter_lines(result))


def test_the_profile_label_clears_its_tick_labels_and_the_loss_plot():
    size = 16
    y, x = np.mgrid[0:size, 0:size]
    source = (0.5 + 0.2 * np.sin(x / 2.0))[..., None]
    pair = (source, np.full((size, size, 1), 0.5), np.full((size, size), 500.0), np.ones((size, size)))
    fig = report_figure(_result(size=size), [pair])
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    by_label = {ax.get_ylabel(): ax for ax in fig.axes}
    profile, loss = by_label["R(r)"], by_label["loss"]
    label = profile.yaxis.label.get_window_extent(renderer)
    ticks = [t.label1.get_window_extent(renderer) for t in profile.yaxis.get_major_ticks()
             if t.label1.get_visible() and t.label1.get_text()]
    points = renderer.points_to_pixels(1.0)
    # At least 4 points of white between the label and the widest tick label ...
    assert label.x1 + 4 * points <= min(b.x0 for b in ticks)
    # ... and at least 10 between it and the loss plot's frame and legend.
    assert loss.get_window_extent(renderer).x1 + 10 * points <= label.x0
    assert loss.get_legend() is None or loss.get_legend().get_window_extent(renderer).x1 + 10 * points <= label.x0
