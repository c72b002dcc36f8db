"""FitOptions(canvas=...): pairs padded onto one canvas fit as at their own size
and share one compilation (invsss.estimator.canvas)."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import invsss
from invsss import InvalidInputError, fit_pair
from invsss.estimator import FitOptions, build_problem
from invsss.estimator.canvas import pad_pair
from invsss.estimator.inputs import prepare_pair

from tests.runtime._compilations import Compilations
from tests.forward._estimator_scenes import make_pair

PROFILE3 = {"weights": [0.3, 0.45, 0.25], "variances": [0.25, 1.2, 5.0]}
TRUTH = invsss.SSSParams(700.0, 300.0, 2.0, PROFILE3["weights"], PROFILE3["variances"])


def _scene(size, seed=0):
    source, target, depth, mask, _ = make_pair("face", TRUTH, size=size, contrast=3.0, seed=seed)
    return source, target, depth, mask


def _wide_mask(shape):
    # Masked up to the second-last row and column: the blur's taps reach past the edge.
    mask = np.ones(shape)
    mask[-1] = 0.0
    mask[:, -1] = 0.0
    return mask


def _losses(pair, options, points):
    problem = build_problem([pair], options, start={})
    with jax.enable_x64(True):
        return np.array([problem.loss(z) for z in points]), problem


def _points(pair, count=4):
    """Unknown vectors around the start of ``pair``'s fit (the same for every canvas)."""
    z0 = np.asarray(build_problem([pair], FitOptions(profile=PROFILE3), start={}).z0)
    rng = np.random.default_rng(0)
    return [z0 + 0.5 * rng.standard_normal(z0.shape) for _ in range(count)]


# The masks of these two reach into the scene's background on purpose.
@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::invsss.InputNotice")
def test_padded_pair_has_the_loss_of_the_pair_at_its_own_size():
    source, target, depth, _ = _scene(36)
    pair = (source, target, depth, _wide_mask(depth.shape))
    points = _points(pair)
    own, _ = _losses(pair, FitOptions(profile=PROFILE3), points)
    padded, on_canvas = _losses(pair, FitOptions(profile=PROFILE3, canvas=(44, 50)), points)
    assert on_canvas.data[0].source.shape[:2] == (44, 50) and not on_canvas.notes
    np.testing.assert_allclose(padded, own, rtol=1e-13)


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::invsss.InputNotice")
def test_a_mask_on_the_last_row_would_change_the_blur_and_keeps_the_pair_at_its_own_size():
    source, target, depth, _ = _scene(36)
    mask = np.ones(depth.shape)  # reaches every edge
    with jax.enable_x64(True):
        checked = prepare_pair(source, target, depth, mask)
        padded = pad_pair(checked, (44, 36))
    points = _points((source, target, depth, mask))
    own, _ = _losses((source, target, depth, mask), FitOptions(profile=PROFILE3), points)
    # Padding it anyway changes the loss: the rule that keeps such a pair off the canvas is needed.
    forced, _ = _losses(padded, FitOptions(profile=PROFILE3), points)
    assert np.max(np.abs(forced / own - 1.0)) > 1e-6
    kept, on_canvas = _losses((source, target, depth, mask), FitOptions(profile=PROFILE3, canvas=(44, 36)), points)
    assert on_canvas.data[0].source.shape[:2] == (36, 36)
    assert on_canvas.notes and "own size (36 x 36)" in on_canvas.notes[0]
    np.testing.assert_array_equal(kept, own)


@pytest.mark.slow
def test_pairs_of_two_sizes_on_one_canvas_fit_as_alone_and_compile_the_step_once():
    first, second = _scene(38, seed=1), _scene(42, seed=2)
    second = tuple(x[:, :40] for x in second)  # 42 x 40
    options = dict(profile=PROFILE3, n_starts=2)
    canvas = (46, 45)  # a size no other test compiles
    with Compilations("_step") as on_canvas:
        a = fit_pair(*first, options=FitOptions(**options, canvas=canvas))
        compiled_for_first = on_canvas.count()
        b = fit_pair(*second, options=FitOptions(**options, canvas=canvas))
    assert compiled_for_first == 1 and on_canvas.count() == 1  # the second pair reused the step
    with Compilations("_step") as alone:
        a_alone = fit_pair(*first, options=FitOptions(**options))
        b_alone = fit_pair(*second, options=FitOptions(**options))
    assert alone.count() == 2  # the counter sees compilations: one per size
    for fit, own, pair in ((a, a_alone, first), (b, b_alone, second)):
        assert np.shape(fit.fitted[0]) == np.shape(pair[1])
        # These small pairs blur by 0.8 px, which the fit reports as unresolved, on a canvas
        # as alone; nothing else is to be said of them.
        assert [w for w in fit.warnings if not w.startswith("blur:")] == []
        assert fit.warnings == own.warnings
        for name in ("sss_level", "correction", "maxdd"):
            assert float(getattr(fit.params, name)) == pytest.approx(float(getattr(own.params, name)), rel=1e-6)
        np.testing.assert_allclose(fit.fitted[0], own.fitted[0], rtol=1e-6, atol=1e-9)
        assert fit.psnr == pytest.approx(own.psnr, rel=1e-9)


def test_frame_dependent_options_keep_pairs_at_their_own_size():
    source, target, depth, mask = _scene(32)
    problem = build_problem([(source, target, depth, mask)],
                            FitOptions(profile=PROFILE3, canvas=(40, 40), vignetting=True), start={})
    assert problem.data[0].source.shape[:2] == (32, 32)
    assert problem.notes == ["canvas: not used with vignetting (it depends on the frame); "
                             "every pair was fitted at its own size"]


@pytest.mark.parametrize("canvas", [(40,), (40, 0), (40.5, 40), "40x40", (True, 40)])
def test_a_malformed_canvas_is_a_one_line_error(canvas):
    with pytest.raises(InvalidInputError, match=r"^canvas: expected \(height, width\), two integers >= 1"):
        FitOptions(canvas=canvas)


def test_a_pair_larger_than_the_canvas_is_a_one_line_error():
    source, target, depth, mask = _scene(32)
    with pytest.raises(InvalidInputError, match=r"^canvas: the pair is 32 x 32 pixels, larger than the canvas of 40 x 30$"):
        build_problem([(source, target, depth, mask)], FitOptions(profile=PROFILE3, canvas=(40, 30)))


@pytest.mark.slow
def test_the_highlight_refit_on_a_canvas_is_the_refit_at_the_pairs_own_size():
    # The refit reads the first fit's (cropped) prediction against the pair as given.
    source, target, depth, mask = _scene(40)
    target = target.copy()
    target[18:21, 18:21] += 0.5  # a specular highlight
    options = dict(profile=PROFILE3, n_starts=2, highlights=True)
    own = fit_pair(source, target, depth, mask, options=FitOptions(**options))
    padded = fit_pair(source, target, depth, mask, options=FitOptions(**options, canvas=(48, 46)))
    assert own.highlights["excluded_pixels"] == padded.highlights["excluded_pixels"] != [0]
    assert float(padded.params.sss_level) == pytest.approx(float(own.params.sss_level), rel=1e-6)
    assert np.shape(padded.fitted[0]) == np.shape(own.fitted[0])
