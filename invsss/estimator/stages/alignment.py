"""Stage: the source side registered onto the target (``align``).

A user's photograph is never on the render's pixel grid: the stage estimates a
warp (:mod:`invsss.estimator.registration`) in rounds with the fit, resamples the
source, depth and mask onto the target, and counts the warp's uncertainty in the
final fit's (:class:`WarpSensitivity`).
"""

from __future__ import annotations

import dataclasses
import functools
import warnings

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from scipy import ndimage

from ...forward.pair import ImagePair
from ...forward.screen_space import render
from ...validation import InputNotice, InvalidInputError
from ..canvas import frame_terms, unused_note
from ..core import Fit, FitCall, Start, estimate_of
from ..inputs import prepare_pairs
from ..pigment import pigment_at
from ..registration import Warp, align_source, align_target, align_vectors, estimate_warp, match_photometry
from ..result import FitResult
from ..vignetting import vignetting_at

__all__ = ["ALIGN_RIM_PX", "WarpSensitivity", "aligned"]


def aligned(inner: Fit, rounds: Fit) -> Fit:
    """The stage that registers the source side onto the target (``align``; see
    :func:`invsss.fit_pair`).

    Fits on the current registration give parameters whose prediction carries the
    blur; registering against that removes the blur's pull on the warp. The two
    depend on each other, so the stage alternates ``rounds`` (a one-start fit each,
    without the highlights refit) with a refinement of the warp until the warp
    settles, then fits once with ``inner`` on the last registration, the warp
    counted in the covariance. A warp off by a tenth of a pixel at the face's edge
    moves sss_level by tens of per cent.
    """

    def fit(call: FitCall) -> FitResult:
        options = call.options
        if options.align == "none":
            return inner(call)
        prepared = prepare_pairs(call.pairs)
        checked = [
            (np.asarray(p.source, np.float64), np.asarray(p.target, np.float64), np.asarray(p.depth, np.float64),
             np.asarray(p.mask, np.float64), p.target_ndim)
            for p in prepared
        ]
        # The warp's sensitivity resamples the pairs at their own sizes: no canvas
        # (the warning says so; see ..canvas).
        own_size = dataclasses.replace(options, canvas=None)
        warps = [estimate_warp(target, match_photometry(source, target, mask), mask, options.align)
                 for source, target, _, mask, _ in checked]
        previous = None
        for _ in range(ALIGN_ROUNDS):
            # After the first round the warp moves by a fraction of a pixel: start from
            # the last round's estimate instead of scanning again.
            rough = dataclasses.replace(own_size, n_starts=1, max_steps=min(options.max_steps, ALIGN_ROUND_STEPS))
            trial = rounds(dataclasses.replace(call, pairs=_resampled(checked, prepared, warps), options=rough,
                                               start=previous))
            previous = Start(estimate_of(trial))
            if trial.interrupted:
                return dataclasses.replace(trial, alignment=tuple(w.to_dict() for w in warps))
            refined = _refined_warps(trial, checked, prepared, warps, options)
            moved = max(warp_change(a, b, mask) for a, b, (_, _, _, mask, _) in zip(warps, refined, checked))
            warps = refined
            if moved < ALIGN_SETTLED_PX:
                break
        sensitivity = WarpSensitivity(checked, warps)
        # The warp's uncertainty goes into the covariance: the report is given it.
        result = inner(dataclasses.replace(call, pairs=_resampled(checked, prepared, warps), options=own_size,
                                           report=functools.partial(call.report, nuisance=sensitivity)))
        messages = result.warnings + _notes(options, warps, checked)
        return dataclasses.replace(result, alignment=sensitivity.records(), warnings=messages)

    return fit


def _resampled(checked, prepared, warps) -> list[ImagePair]:
    """The pairs with their source side moved onto the target by ``warps``."""
    out = []
    for (source, target, depth, mask, ndim), warp, pair in zip(checked, warps, prepared):
        moved, moved_depth, kept = align_source(source, depth, mask, warp, target.shape[:2])
        if not (kept > 0).any():
            raise InvalidInputError("align: the registered source does not overlap the target", field="align")
        # The rim of the resampled mask is where the resampling is least like the
        # camera's own view (the mask and depth jump there): leave it out of the
        # comparison, not out of the model.
        inner = ndimage.binary_erosion(kept > 0, iterations=ALIGN_RIM_PX).astype(np.float64)
        if pair.fit_weight is not None:
            # The comparison is on the target's grid, and so is a fit weight
            # (the clipped pixels of saturation=, for one).
            inner = inner * np.asarray(pair.fit_weight)
        if not inner.any():
            inner = None
        # The key light's part of the source moves with the source.
        key = None if pair.key is None else align_source(pair.key, depth, mask, warp, target.shape[:2])[0]
        # So do the transmission's buffers, which belong to the source's pixels.
        key_irradiance = (None if pair.key_irradiance is None
                          else align_source(pair.key_irradiance, depth, mask, warp, target.shape[:2])[0])
        thickness = (None if pair.thickness is None
                     else align_source(np.asarray(pair.thickness)[..., None], depth, mask, warp,
                                       target.shape[:2])[0][..., 0])
        out.append(ImagePair(moved, target[..., 0] if ndim == 2 else target, moved_depth, kept,
                             fit_weight=inner, normal=align_vectors(pair.normal, warp, target.shape[:2]),
                             light=align_vectors(pair.light, warp, target.shape[:2]), key=key,
                             fill_light=align_vectors(pair.fill_light, warp, target.shape[:2]),
                             inputs_noted=True, thickness=thickness, key_irradiance=key_irradiance))
    return out


def _refined_warps(trial, checked, prepared, warps, options) -> list:
    """Each warp re-estimated against the prediction of a round's fit ``trial``."""
    refined = []
    for k, ((source, target, depth, mask, _), warp, pair) in enumerate(zip(checked, warps, prepared)):
        # The whole model, light terms included: a prediction without the
        # shift would leave it for the warp to take.
        lit = {} if trial.light_terms is None else {
            "light_terms": trial.light_terms_params(),
            "light_buffers": pair.light_buffers}
        with warnings.catch_warnings():
            # A round's own estimate, not the user's parameters: a collapsed blur is
            # reported by the fit (undetermined sss_level), not as absurd input.
            warnings.simplefilter("ignore", InputNotice)
            prediction = np.asarray(render(source, depth, mask, trial.params, options.model,
                                           tap_weights=options.tap_weights, **lit), np.float64)
        prediction = prediction[..., None] if prediction.ndim == 2 else prediction
        if trial.vignetting is not None:
            # Shaded as the photograph is, where the warp puts each source pixel: an
            # unshaded prediction leaves the fall-off to the warp's scale (20 % at
            # the corners of fran_front read as a scale of 0.999, which moved
            # correction by +7 %).
            rows, cols = np.mgrid[0:mask.shape[0], 0:mask.shape[1]]
            at = warp.map_points(np.stack([rows.ravel(), cols.ravel()], axis=1))
            shade = vignetting_at(trial.vignetting["coefficients"], at, target.shape[:2])
            prediction = prediction * shade.reshape(mask.shape)[..., None]
        if trial.pigment is not None:
            # The pigment field too: it lives on the photograph's frame, as the fall-off does.
            rows, cols = np.mgrid[0:mask.shape[0], 0:mask.shape[1]]
            at = warp.map_points(np.stack([rows.ravel(), cols.ravel()], axis=1))
            shade = pigment_at(np.asarray(trial.pigment["estimate"])[k], at, target.shape[:2])
            prediction = prediction * shade.reshape(mask.shape + (shade.shape[-1],))
        # The prediction in the target's channels (gain, offset, RGB -> grey mix),
        # matched against the current registration of the target.
        reference = match_photometry(prediction, align_target(target, mask, warp)[0], mask)
        refined.append(estimate_warp(target, reference, mask, options.align, start=warp))
    return refined


def _notes(options, warps, checked) -> tuple[str, ...]:
    """The warnings an aligned fit adds: an unused canvas, a resampled source, the shift term."""
    # How far the warp moves the mask's corners from where they were: zero parameters are the identity.
    resampled = max(warp_change(w, Warp(w.kind, (0.0,) * len(w.params), w.centre), mask)
                    for w, (_, _, _, mask, _) in zip(warps, checked))
    messages: tuple[str, ...] = ()
    if options.canvas is not None:
        messages += (unused_note(frame_terms(options)),)
    if resampled > ALIGN_SETTLED_PX:
        messages += (
            f"align: the source was resampled onto the photograph's grid (the warp moves it by up to "
            f"{resampled:.2f} px); that alone biases sss_level by a few per cent beyond its standard "
            "error (-3 to -5 % on a model-made face). "
            "For final numbers render the source again from the camera the warp implies (invsss scene "
            "--warp params.json --source-only, for a scene invsss renders) and fit that with align again",
        )
    if "shift" in options.light_terms and "shift" not in options.light_fixed:
        messages += (
            "light_terms: the shift term moves the image along the light's direction, and where that "
            "direction varies little over the mask so does a translation of the warp: one pair cannot "
            "tell them apart, and the split between the fitted shift and the warp is not determined "
            "(measure the shift on a pair whose registration is known)",
        )
    elif "shift" in options.light_terms:
        messages += (
            "light_terms: with the shift held, the registration rounds see it but converge slowly (on a "
            "model-made card 4 rounds left the warp 0.3 px off and sss_level 34 % low); check the warp "
            "in report.png",
        )
    return messages


#: The warp's parameters are perturbed by steps that move the mask's farthest
#: corner this far (px) to differentiate the residual: below the 0.1 px that
#: moves the blur estimate, above the resampling's rounding.
WARP_STEP_PX = 0.05


@eqx.filter_jit
def _explicit_residual(objective, z, coef, offset):
    return objective.explicit_residual(z, coef, offset)


class WarpSensitivity:
    """How the final fit's residual changes with each warp parameter, so that the
    standard errors count the warp as estimated (:func:`gauss_newton_uncertainty`'s
    ``nuisance``), and the warps with their own standard errors for params.json.

    The derivative is a central difference of the whole resampling (source,
    depth and mask moved by :func:`~invsss.estimator.registration.align_source`) with the
    scattering parameters, the linear unknowns and the residual's weights held.
    The fit's report calls :meth:`columns` and stores the warp parameters'
    standard errors in ``stderr``, which :meth:`records` then writes out.
    """

    def __init__(self, checked, warps):
        self.checked, self.warps = checked, warps
        self.stderr = None

    def _steps(self, warp, mask) -> np.ndarray:
        reach = float(np.max(np.linalg.norm(mask_corners(mask) - np.asarray(warp.centre), axis=1)))
        steps = np.full(len(warp.params), WARP_STEP_PX / max(reach, 1.0))
        steps[:2] = WARP_STEP_PX  # the shift is in pixels already
        return steps

    def columns(self, objective, z, coef, offset) -> np.ndarray:
        out = []
        for i, ((source, target, depth, mask, _), warp) in enumerate(zip(self.checked, self.warps)):
            for j, h in enumerate(self._steps(warp, mask)):
                sides = []
                for sign in (1.0, -1.0):
                    params = np.array(warp.params, np.float64)
                    params[j] += sign * h
                    moved, moved_depth, kept = align_source(
                        source, depth, mask, Warp(warp.kind, tuple(params), warp.centre), target.shape[:2])
                    # tree_at calls the lambda at once, within this iteration (B023 looks for a late call).
                    shifted = eqx.tree_at(
                        lambda o: (o.pairs[i].source, o.pairs[i].depth, o.pairs[i].mask), objective,  # noqa: B023
                        (jnp.asarray(moved), jnp.asarray(moved_depth), jnp.asarray(kept)))
                    sides.append(np.asarray(_explicit_residual(shifted, z, coef, offset)))
                out.append((sides[0] - sides[1]) / (2.0 * h))
        return np.stack(out, axis=1)

    def records(self) -> tuple:
        """Each warp as params.json writes it, with the standard errors of its parameters."""
        out, first = [], 0
        for warp in self.warps:
            record = warp.to_dict()
            n = len(warp.params)
            if self.stderr is not None:
                err = [None if not np.isfinite(e) else float(e) for e in self.stderr[first:first + n]]
                first += n
                stderr: dict[str, list[float | None] | float | None] = {"shift_px": err[:2]}
                if warp.kind == "similarity":
                    stderr["rotation_deg"] = None if err[2] is None else float(np.degrees(err[2]))
                    stderr["scale"] = None if err[3] is None else float(np.exp(warp.params[3]) * err[3])
                elif warp.kind == "affine":
                    stderr["matrix_2x2"] = err[2:]
                record["stderr"] = stderr
            out.append(record)
        return tuple(out)


#: Registration rounds (a one-start fit and a warp refinement each) at most.
ALIGN_ROUNDS = 4
#: Solver steps per solve in a registration round's fit: the round only needs a
#: prediction that carries about the right blur, and on a badly registered pair
#: the loss is rough enough that a robust round crept for 189 steps (38 s of a
#: 63 s fit of fran_front moved by (1.2, -0.7) px and 0.5 deg).
ALIGN_ROUND_STEPS = 30
#: An aligned fit compares the images from this many pixels inside the resampled
#: mask's edge. Measured on fran_front seen from a camera moved by (0.6, 0.8) px,
#: fitted with the true warp: all of the mask gave sss_level +58 %, correction
#: -32 %; without a 2 px rim, -5 % and -2 %.
ALIGN_RIM_PX = 2
#: The warp has settled when no corner of the mask's bounding box moves more (px).
ALIGN_SETTLED_PX = 0.01


def mask_corners(mask) -> np.ndarray:
    """The corners (4, 2) of the mask's bounding box, (row, col)."""
    rows, cols = np.nonzero(mask > 0)
    return np.array([[rows.min(), cols.min()], [rows.min(), cols.max()],
                     [rows.max(), cols.min()], [rows.max(), cols.max()]], np.float64)


def warp_change(a, b, mask) -> float:
    """How far (px) two warps take any corner of the mask's bounding box apart."""
    corners = mask_corners(mask)
    return float(np.abs(a.map_points(corners) - b.map_points(corners)).max())
