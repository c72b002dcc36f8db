"""A one-page picture of a fit: what went in, what came out, and how well it matches.

:func:`plot_fit_report` draws, for every pair, one row

    source | fitted | target | residual (target - fitted, on the mask)

and below them the solver's convergence (every start's loss curve and the
refinement rounds, on one axis of all the fit's steps), the fitted diffusion
profile ``R(r)`` against the one the fit started from, and the fitted parameters
with their standard errors (conditional on the profile, as the page says; an
entry the data did not determine shows its point estimate marked with a dagger,
explained under the table). Loss tick labels carry the digits that tell them
apart (a fit's loss often moves by less than a decade). Images are stretched linearly between their 1st and 99th
percentiles on the mask (the blur lowers contrast; a fixed white point would show
a blurred target as flat grey), the fitted image and the target with the
target's stretch, so a brightness or contrast mismatch stays visible; the mask's
edge is outlined and the outside veiled. The residual (for RGB, the mean over channels) uses a
diverging colour map with limits symmetric about zero and one scale for all
pairs, so its sign reads directly (red: the target is brighter than the fit).

Drawn with matplotlib's non-interactive Agg canvas: no display is needed and no
global pyplot state is touched.
"""

from __future__ import annotations

import os
import textwrap

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import LogFormatter, MaxNLocator

from ..estimator.blur_width import blur_line
from ..estimator.diagnostics import masked_psnr, masked_ssim
from ..forward.models import MODEL_NAMES, get_model
from ..forward.params import PARAM_NAMES
from ..forward.profiles import sum_of_gaussians
from ..validation import InvalidInputError

__all__ = ["UNDETERMINED", "parameter_lines", "plot_convergence", "plot_fit_report", "plot_profile", "report_figure"]

_PANEL_INCHES = 2.9
#: Resolution of the page (dots per inch), for the layout and the saved image alike.
_DPI = 110
#: The colour of a mask note under a source panel (a mask its checks doubt).
_MASK_NOTE_COLOUR = "#c0392b"
_TEXT_WIDTH = 84  # characters per line in the parameter box


def _hwc(x) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    return x[..., None] if x.ndim == 2 else x


def _display_range(image, mask) -> tuple[float, float]:
    """Black and white points: the 1st and 99th percentiles over the mask (all channels)."""
    on = image[mask > 0]
    lo, hi = (np.percentile(on, [1.0, 99.0]) if on.size else (np.min(image), np.max(image)))
    return (float(lo), float(hi)) if hi > lo else (float(lo), float(lo) + 1.0)


def _display(image, limits: tuple[float, float]) -> np.ndarray:
    """(H, W, C) stretched linearly to [0, 1] between ``limits``, ready for imshow."""
    lo, hi = limits
    shown = np.clip((image - lo) / (hi - lo), 0.0, 1.0)
    return shown[..., 0] if shown.shape[-1] == 1 else shown


def _show(ax, image, title: str, mask) -> None:
    ax.imshow(image, cmap="gray", vmin=0.0, vmax=1.0, interpolation="nearest")
    _outline(ax, mask)
    ax.set_title(title, fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])


def _outline(ax, mask) -> None:
    """Outline the mask and veil what lies outside it: only the inside was fitted."""
    if 0 < np.count_nonzero(mask > 0.5) < mask.size:
        veil = np.zeros((*mask.shape, 4))
        veil[..., :3] = 1.0
        veil[..., 3] = 0.6 * (mask <= 0.5)
        ax.imshow(veil, interpolation="nearest")
        ax.contour(mask, levels=[0.5], colors="#ff9f1c", linewidths=0.8)


def _format_value(value, error=None, unknown=None) -> str:
    """``902.2±3.3`` for a scalar, ``[a±e, b±f]`` (rows as tuples) for an array.

    ``unknown`` (bool, the value's shape) marks entries the data did not
    determine: they print as the point estimate with :data:`UNDETERMINED` after
    it and no standard error (params.json writes them as null): the value the
    fitted image used, which the data would not have moved.
    """
    value = np.asarray(value, dtype=np.float64)
    rows = value.reshape(value.shape[0], -1) if value.ndim else value.reshape(1, 1)
    errors = np.full(rows.shape, np.nan)
    if error is not None and np.shape(error) == value.shape:
        errors = np.asarray(error, dtype=np.float64).reshape(rows.shape)  # None -> nan
    flags = np.zeros(rows.shape, bool) if unknown is None else np.broadcast_to(unknown, value.shape).reshape(rows.shape)

    def one(v, e, flag):
        if flag:
            return f"{v:.4g}{UNDETERMINED}"
        return f"{v:.4g}" if not np.isfinite(e) else f"{v:.4g}±{e:.2g}"

    cells = [[one(v, e, f) for v, e, f in zip(*row)] for row in zip(rows, errors, flags)]
    if value.ndim == 0:
        return cells[0][0]
    return "[" + ", ".join(c[0] if len(c) == 1 else "(" + ", ".join(c) + ")" for c in cells) + "]"


#: The mark after an undetermined entry's point estimate, explained under the table.
UNDETERMINED = "\u2020"  # a dagger
_UNDETERMINED_NOTE = (
    f"{UNDETERMINED} undetermined: the data did not fix this value; it is where the fit "
    "stopped (the value the fitted image used), with no standard error, and null in params.json."
)


def parameter_lines(result, depth_unit: str | None = None) -> list[str]:
    """One line per parameter: value ± standard error, and what is fixed or undetermined
    (the blur's depth in ``depth_unit`` when given)."""
    params = result.params
    stderr = dict(result.stderr or {})
    fixed = dict(result.fixed or {})
    lines = []
    any_unknown = False
    for name in PARAM_NAMES:
        unknown = np.asarray(result.is_undetermined(name))
        any_unknown = any_unknown or bool(unknown.any())
        flags = ["fixed"] if name in fixed else []
        if unknown.all():
            flags.append(f"undetermined {UNDETERMINED}")
        elif unknown.any():
            flags.append(f"{int(unknown.sum())} undetermined {UNDETERMINED}")
        value = _format_value(getattr(params, name), None if name in fixed else stderr.get(name), unknown)
        lines.append(f"{name:<11} {value}" + (f"  [{', '.join(flags)}]" if flags else ""))
    if any_unknown:
        lines.extend(textwrap.wrap(_UNDETERMINED_NOTE, width=_TEXT_WIDTH, subsequent_indent="  "))
    lines.append("")
    status = "interrupted" if getattr(result, "interrupted", False) else (
        "converged" if result.converged else "NOT converged")
    lines.append(
        f"model {result.model}   gauge {result.gauge}   "
        f"{status} after {result.iterations} iterations (all starts and rounds)"
    )
    lines.append(f"loss {float(result.loss):.4g}   PSNR {float(result.psnr):.2f} dB   SSIM {float(result.ssim):.4f}")
    lines.append(f"gain {_format_value(result.gain)}   offset {_format_value(result.offset)}")
    blur = blur_line(getattr(result, "blur", None), depth_unit)
    if blur:
        lines.append(blur)
    if result.mix is not None:
        lines.append(f"RGB -> grey mix {_format_value(result.mix)}")
    for k, record in enumerate(getattr(result, "alignment", ()) or ()):
        dy, dx = record["shift_px"]
        extra = (f", rotation {record['rotation_deg']:+.2f} deg, scale {record['scale']:.4f}"
                 if record["kind"] == "similarity" else "")
        where = f"pair {k} " if len(result.alignment) > 1 else ""
        shift_err = (record.get("stderr") or {}).get("shift_px")
        if shift_err is not None:
            extra += "; shift stderr (" + ", ".join("?" if e is None else f"{e:.2g}" for e in shift_err) + ") px"
        lines.append(f"{where}target registered ({record['kind']}): shift ({dy:+.2f}, {dx:+.2f}) px (dy, dx){extra}")
    vignetting = getattr(result, "vignetting", None)
    if vignetting is not None:
        a1, a2 = vignetting["coefficients"]
        errors = ", ".join("?" if e is None else f"{e:.2g}" for e in vignetting["stderr"])
        lines.append(f"vignetting: corner gain {vignetting['corner_gain']:.3f} "
                     f"(1 + {a1:+.3f} rho^2 {a2:+.3f} rho^4; stderr {errors})")
    terms = getattr(result, "light_terms", None)
    if terms is not None:
        lines.extend(_light_term_lines(terms, result.psnr))
    lines.extend(textwrap.wrap(_CONDITIONAL_NOTE, width=_TEXT_WIDTH, subsequent_indent="  "))
    for message in result.warnings:
        lines.extend(textwrap.wrap("! " + message, width=_TEXT_WIDTH, subsequent_indent="  "))
    return lines


def _per_channel(terms: dict, name: str, form: str) -> tuple[str, str]:
    """A per-channel term's values and standard errors, each joined by ``/`` (``?`` where
    undetermined): one value per source channel, or one held value."""
    values = np.atleast_1d(terms[name]).tolist()
    errs = terms["stderr"].get(name)
    errs = [None] * len(values) if errs is None else np.atleast_1d(np.asarray(errs, object)).tolist()
    return ("/".join(f"{v:{form}}" for v in values), "/".join("?" if e is None else f"{e:.2g}" for e in errs))


def _light_term_lines(terms: dict, psnr: float) -> list[str]:
    """The report's lines for a fit's ``light_terms`` record: each term's value with its
    standard error, then the PSNR with the terms, of the plain fit and with each term off."""
    parts = []
    for name, unit in (("shift", " mm"), ("grazing", ""), ("incidence", "")):
        if name in terms:
            err = terms["stderr"].get(name)
            parts.append(f"{name} {terms[name]:+.3g}{unit} (stderr {'?' if err is None else f'{err:.2g}'})")
    if "law" in terms:
        shown, spread = _per_channel(terms, "law", ".3f")
        strength = terms.get("law_strength", 1.0)
        s_err = terms["stderr"].get("law_strength")
        parts.append(f"law albedo {shown} (stderr {spread}), strength {strength:.3g} "
                     f"(stderr {'?' if s_err is None else f'{s_err:.2g}'})")
    if "fill" in terms:
        f_err = terms["stderr"].get("fill")
        parts.append(f"law on the other lights, strength {terms['fill']:.3g} "
                     f"(stderr {'?' if f_err is None else f'{f_err:.2g}'})")
    if "transmission" in terms:
        # The thickness's scale is one number (docs/model.md, section 8).
        tints, spread = _per_channel(terms, "transmission", ".3g")
        k_err = terms["stderr"].get("thickness_scale")
        parts.append(f"transmission tint {tints} (stderr {spread}), thickness scale "
                     f"{terms.get('thickness_scale', 1.0):.3g}/mm "
                     f"(stderr {'?' if k_err is None else f'{k_err:.2g}'})")
    lines = ["light terms: " + ", ".join(parts)]
    if "psnr_plain" in terms:
        # Measured: the plain fit, and this fit with each term at its identity.
        knocked = ", ".join(f"{term} {value:.2f}" for term, value in terms.get("psnr_without", {}).items())
        lines.append(f"PSNR {psnr:.2f} dB with the terms, {terms['psnr_plain']:.2f} dB plain fit"
                     + (f"; with one term at its identity: {knocked}" if knocked else ""))
    return lines


# Standard errors measure the noise for the profile held fixed, not the choice
# of profile: another profile moved sss_level by 14 of them at the same PSNR.
_CONDITIONAL_NOTE = (
    "± standard errors are conditional on the chosen profile (its variances held "
    "fixed): a different profile can shift the estimate by many of them at equal PSNR."
)


def plot_convergence(ax, result) -> None:
    """Every solve's loss curve on one axis of the fit's steps: each start in its
    own colour (the winner drawn thick), the refinement rounds in black after a
    dashed line."""
    history = np.asarray(result.history, dtype=np.float64).ravel()
    stages = tuple(getattr(result, "stages", ()) or ()) or (("fit", 0, history.size),)
    starts = [(label, a, b) for label, a, b in stages if label.startswith("start") and b > a]
    best = min(starts, key=lambda s: history[s[2] - 1], default=None)
    for i, (label, first, stop) in enumerate(stages):
        steps = np.arange(first + 1, stop + 1)
        losses = history[first:stop]
        shown = np.isfinite(losses) & (losses > 0)
        if not np.any(shown):
            continue
        if label.startswith("start") or label == "fit":
            winner = best is not None and label == best[0]
            ax.semilogy(steps[shown], losses[shown], color=f"C{i % 10}", lw=2.0 if winner else 1.0,
                        marker=".", ms=3, label=label + (" (best)" if winner else ""))
        else:
            ax.axvline(first + 0.5, color="0.4", ls="--", lw=0.8)
            ax.semilogy(steps[shown], losses[shown], color="k", lw=1.5, marker=".", ms=3)
            # On a light backing: the round's first points sit right under its label.
            ax.annotate(label, (first + 1, losses[shown][0]), fontsize=7, rotation=90,
                        va="bottom", ha="right", color="0.3",
                        bbox={"boxstyle": "square,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.75})
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel(f"iteration (all {history.size} steps of the fit)")
    ax.set_ylabel("loss")
    _plain_log_labels(ax)
    ax.set_title("convergence: every start, then the refinement rounds", fontsize=9)
    ax.grid(True, which="major", alpha=0.3)
    if len(starts) > 1:
        ax.legend(fontsize=7, loc="upper right")


def plot_profile(ax, result) -> None:
    """The fitted ``R(r)`` (sum of Gaussians) against the profile the fit started
    from, weights normalised to sum 1 per channel so the shapes compare."""
    variances = np.asarray(result.values["variances"], np.float64)
    weights = np.asarray(result.values["weights"], np.float64)
    curves = [("fitted", weights, variances, "-")]
    start = getattr(result, "start_profile", None)
    if start is not None:
        curves.append(("start", np.asarray(start["weights"], np.float64),
                       np.asarray(start["variances"], np.float64), ":"))
    r_max = 3.0 * float(np.sqrt(max(np.max(c[2]) for c in curves)))
    # A model whose variances are Burley's d^2 (issue 34) is drawn as Burley's profile.
    burley = get_model(getattr(result, "model", MODEL_NAMES[0])).variance_meaning == "burley_d2"
    if burley:
        r_max = max(r_max, 6.0 * float(np.sqrt(np.max(variances))))
    r = np.linspace(r_max / 400.0 if burley else 0.0, r_max, 200)
    for label, w, v, style in curves:
        w = w / np.sum(w, axis=0)
        if burley and label == "fitted":
            # Christensen & Burley's R(r) per channel (docs/model.md, section 4), unit albedo.
            d = np.maximum(np.sqrt(v), 1e-9)[None, :]
            profile = (np.exp(-r[:, None] / d) + np.exp(-r[:, None] / (3 * d))) / (8 * np.pi * d * r[:, None])
        else:
            # NumPy in and out (no compilation), where the annotations say jax Array.
            profile = sum_of_gaussians(r, w, v)  # type: ignore[arg-type]
        profile = profile.reshape(r.size, -1)
        for c in range(profile.shape[1]):
            name = label if profile.shape[1] == 1 else f"{label}, channel {c}"
            colour = "C0" if profile.shape[1] == 1 else ("C3", "C2", "C0")[c % 3]
            ax.semilogy(r, np.clip(profile[:, c], 1e-12, None), color=colour, ls=style, lw=1.5, label=name)
    ax.set_xlabel("r (scene units, mm for depth in mm)")
    ax.set_ylabel("R(r)")
    _plain_log_labels(ax)
    ax.set_title("diffusion profile: fitted vs start", fontsize=9)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")


class _DistinctLogFormatter(LogFormatter):
    """:class:`~matplotlib.ticker.LogFormatter` whose labels on one axis differ.

    Over less than a decade a log axis falls back to linear ticks (2.05e-4,
    2.10e-4, ...), which the log formatter's one significant digit labels all
    ``2e-04``. Where its labels repeat, these carry as many significant digits
    (up to six) as it takes to tell them apart.
    """

    def format_ticks(self, values):
        labels = super().format_ticks(values)
        for digits in range(2, 7):
            shown = [label for label in labels if label]
            if len(set(shown)) == len(shown):
                break
            labels = [self.fix_minus(f"{value:.{digits - 1}e}") if label else ""
                      for value, label in zip(values, labels)]
        return labels


def _plain_log_labels(ax) -> None:
    """Distinct tick labels such as ``1e-05`` or ``2.05e-04``: matplotlib's default
    ``10^{-5}`` goes through its mathtext parser, whose first use in a process costs
    about 0.3 s."""
    ax.yaxis.set_major_formatter(_DistinctLogFormatter())
    ax.yaxis.set_minor_formatter(_DistinctLogFormatter(labelOnlyBase=False))


def _residual_limit(residuals) -> float:
    on = np.concatenate([np.abs(r[np.isfinite(r)]).ravel() for r in residuals])
    limit = float(np.percentile(on, 99.0)) if on.size else 0.0
    return limit if limit > 0 else 1.0


def _draw_pair_rows(fig, grid, pairs, fitted, mask_notes=None) -> None:
    """One row per pair in ``grid``'s first rows: source, fitted, target, residual; a
    pair's mask note (what its checks found) under its source panel, in red."""
    rows = len(pairs)
    residuals, residual_axes = [], []
    for k, (source, target, _depth, mask) in enumerate(pairs):
        source, target = _hwc(source), _hwc(target)
        mask = np.ones(target.shape[:2]) if mask is None else np.asarray(mask, dtype=np.float64)
        pred = _hwc(fitted[k])
        if pred.shape != target.shape:
            raise InvalidInputError(
                f"pairs[{k}].target: shape {target.shape} differs from the fitted image's {pred.shape}"
            )
        limits = _display_range(target, mask)
        psnr, ssim = masked_psnr(pred, target, mask), masked_ssim(pred, target, mask)
        label = f"pair {k}: " if rows > 1 else ""
        source_ax = fig.add_subplot(grid[k, 0])
        _show(source_ax, _display(source, _display_range(source, mask)), f"{label}source", mask)
        if mask_notes and k < len(mask_notes) and mask_notes[k]:
            source_ax.text(0.0, -0.02, mask_notes[k], transform=source_ax.transAxes, va="top", ha="left",
                           fontsize=7, color=_MASK_NOTE_COLOUR)
        _show(fig.add_subplot(grid[k, 1]), _display(pred, limits),
              f"fitted  PSNR {psnr:.2f} dB  SSIM {ssim:.3f}", mask)
        _show(fig.add_subplot(grid[k, 2]), _display(target, limits), "target", mask)
        residual = np.mean(target - pred, axis=-1)
        residual[mask <= 0] = np.nan
        residuals.append(residual)
        residual_axes.append(fig.add_subplot(grid[k, 3]))

    # One colour scale for every residual panel, so the pairs compare.
    limit = _residual_limit(residuals)
    channel_note = " (channel mean)" if _hwc(pairs[0][1]).shape[-1] > 1 else ""
    for ax, residual in zip(residual_axes, residuals):
        image = ax.imshow(residual, cmap="RdBu_r", vmin=-limit, vmax=limit, interpolation="nearest")
        ax.set_facecolor("0.85")  # outside the mask
        ax.set_title(f"residual  target - fitted{channel_note}", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
        # The colour bar sits in the gutter beside the panel, which keeps the
        # size of the other image panels.
        fig.colorbar(image, cax=ax.inset_axes([1.04, 0.08, 0.05, 0.84]), format="%.2g")


def plot_fit_report(result, pairs, path, mask_notes=None, depth_unit: str | None = None) -> None:
    """Draw a fit's report page and save it as an image.

    Parameters
    ----------
    result : FitResult
        What :func:`invsss.fit_pair` or :func:`invsss.fit_pairs` returned for ``pairs``.
    pairs : sequence of ImagePair or (source, target, depth, mask) tuples
        The fitted pairs, in the order given to the fit. ``source`` (H, W, C),
        ``target`` (H, W, C'), ``mask`` (H, W) or None (every pixel).
    path : str or os.PathLike
        Output file; the format follows the extension (``.png``, ``.pdf``, ``.svg``).
    mask_notes : sequence of (str or None), optional
        Per pair, a short line on what its mask's checks found
        (:func:`invsss.io.skin_mask.mask_note`), drawn under its source panel.
    depth_unit : str, optional
        The depth's unit (``"mm"``), printed with the blur's depth.

    Raises
    ------
    InvalidInputError
        ``pairs`` and ``result.fitted`` differ in number or image size.

    Examples
    --------
    >>> import numpy as np, os, tempfile, invsss
    >>> from invsss.cli.report import plot_fit_report
    >>> y, x = np.mgrid[0:24, 0:24]
    >>> source = 0.5 + 0.3 * np.sin(x / 2.0) * np.cos(y / 3.0)
    >>> depth, mask = 600.0 + 0.5 * x, np.ones((24, 24))
    >>> truth = invsss.SSSParams(900.0, 0.0, 1.0, [1.0], [1.0])
    >>> target = np.asarray(invsss.render(source, depth, mask, truth))
    >>> fit = invsss.fit_pair(source, target, depth, mask, fix={"variances": [1.0]},
    ...                       n_starts=1, max_steps=20)
    >>> path = os.path.join(tempfile.mkdtemp(), "report.png")
    >>> plot_fit_report(fit, [(source, target, depth, mask)], path)
    >>> os.path.getsize(path) > 0
    True
    """
    report_figure(result, pairs, mask_notes, depth_unit).savefig(os.fspath(path), dpi=_DPI)


def report_figure(result, pairs, mask_notes=None, depth_unit: str | None = None) -> Figure:
    """The page of :func:`plot_fit_report`, drawn on an Agg canvas, not yet saved."""
    pairs = [
        (p.source, p.target, p.depth, p.mask) if hasattr(p, "source") else tuple(p) for p in pairs
    ]
    if result.alignment:
        # An aligned fit's images are on the target's grid: show the source there too.
        from ..estimator.registration import Warp, align_source

        moved = []
        for (source, target, depth, mask), record in zip(pairs, result.alignment):
            source, depth, mask = align_source(source, depth, mask, Warp.from_dict(record), np.shape(target)[:2])
            moved.append((source, target, depth, mask))
        pairs = moved
    fitted = list(result.fitted)
    if len(fitted) != len(pairs):
        raise InvalidInputError(
            f"pairs: the result has {len(fitted)} fitted image(s) but {len(pairs)} pair(s) were given"
        )
    rows = len(pairs)
    lines = parameter_lines(result, depth_unit)
    # The text box grows with its lines (8 pt monospace: 0.147 in each, measured), so
    # a fit with many warnings keeps the last of them on the page.
    text_inches = max(2.3, 0.35 + 0.15 * len(lines))
    width, height = 4 * _PANEL_INCHES + 0.6, rows * _PANEL_INCHES + 3.3 + text_inches
    fig = Figure(figsize=(width, height), dpi=_DPI)
    FigureCanvasAgg(fig)
    # Fixed margins (inches) instead of matplotlib's constrained layout, which
    # measured every text box twice and took a third of the page's 0.55 s.
    grid = fig.add_gridspec(
        rows + 2, 4, height_ratios=[_PANEL_INCHES] * rows + [3.0, text_inches],
        left=1.0 / width, right=1.0 - 1.0 / width, top=1.0 - 0.3 / height, bottom=0.1 / height,
        wspace=0.32, hspace=0.3,
    )

    _draw_pair_rows(fig, grid, pairs, fitted, mask_notes)

    # The profile's tick labels and its ylabel sit between the two plots: they get a
    # gap of their own (1.2 in, the image panels' is 0.7 in), clear of the loss plot.
    plots = grid[rows, 0:4].subgridspec(1, 2, wspace=0.25)
    plot_convergence(fig.add_subplot(plots[0]), result)
    plot_profile(fig.add_subplot(plots[1]), result)

    text = fig.add_subplot(grid[rows + 1, 0:4])
    text.axis("off")
    box = text.text(
        0.0, 1.0, "\n".join(lines), va="top", ha="left",
        family="monospace", fontsize=8, transform=text.transAxes, wrap=True,
        bbox={"boxstyle": "round", "facecolor": "0.96", "edgecolor": "0.7"},
    )
    box.set_in_layout(False)  # long lines must not squeeze the panels above
    return fig
