"""The robust loss, not plain least squares, decides between the starts' basins.

The starts are ranked by plain least squares with the weights' sign free; the fit
ends on the robust loss with the sign imposed. Each pixel weighs in by its own mask
entry, and where two basins fit equally well within the noise (another noise draw
could rank them the other way), the fit must say so. (A JPEG photograph on which
least squares and the robust loss disagree is fitted from its files in
tests/cli/test_robust_basins.py.)
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import ndimage

import invsss
from invsss.estimator.search import SolvePath, choose_basin
from invsss.estimator.summary import rival_basin_warning
from invsss.estimator.options import FitOptions
from invsss.estimator.problem import evaluate, build_problem
from invsss.estimator.robust import robust_loss, robust_scale


def test_robust_loss_weighs_each_pixel_by_its_own_mask_entry():
    # A (H, W) mask against (H, W, 1) residuals of a frame that is not square: the
    # mask must act per pixel, not broadcast against the channel axis.
    rng = np.random.default_rng(3)
    residual = rng.normal(size=(5, 7, 1))
    mask = (rng.uniform(size=(5, 7)) > 0.4).astype(np.float64)
    value = robust_loss([residual], [mask], 0.5, "pseudo-huber")
    assert value == pytest.approx(robust_loss([residual], [mask[..., None]], 0.5, "pseudo-huber"))
    rho = 0.25 * (np.sqrt(1.0 + (residual[..., 0] / 0.5) ** 2) - 1.0)
    assert value == pytest.approx(float(np.sum(rho[mask > 0])))


def _noisy_card_problem():
    """A flat card blurred at sss_level 375, noisy enough that a blur 12 % wider
    fits within the noise (its loss is higher by 0.7 standard deviations of the
    difference), and one 2.4 times wider does not (12)."""
    rng = np.random.default_rng(0)
    shape = (40, 48)  # not square: see the test above
    source = ndimage.gaussian_filter(rng.uniform(0.2, 1.0, shape), 1.0)
    depth, mask = np.full(shape, 500.0), np.ones(shape)
    truth = invsss.SSSParams(375.0, 0.0, 1.0, [0.3, 0.7], [1.0, 4.0])
    target = np.asarray(invsss.render(source, depth, mask, truth)) + 0.01 * rng.standard_normal(shape)
    options = FitOptions(profile={"weights": [0.5, 0.5], "variances": [1.0, 4.0]},
                         fix={"correction": 0.0, "maxdd": 1.0})
    return build_problem([(source, target, depth, mask)], options)


def _candidate(problem, level):
    path = SolvePath(problem.objective, problem.param.unknowns({"sss_level": level}))
    preds = evaluate(path.objective, path.z, jnp.asarray(False))["predictions"]
    residuals = [np.asarray(p.target) - np.asarray(q) for p, q in zip(problem.data, preds)]
    path.delta = robust_scale(residuals, [np.asarray(p.residual_weight) for p in problem.data], "pseudo-huber")
    return path


@pytest.mark.slow
def test_a_second_basin_that_fits_as_well_within_the_noise_is_reported():
    with jax.enable_x64(True):
        problem = _noisy_card_problem()
        tied = [_candidate(problem, 375.0), _candidate(problem, 420.0)]
        chosen = choose_basin(problem, tied, "pseudo-huber")
        clear = [_candidate(problem, 375.0), _candidate(problem, 900.0)]
        clear_choice = choose_basin(problem, clear, "pseudo-huber")
    assert chosen is tied[0]
    level, rivals = chosen.rival_basins
    assert level == pytest.approx(375.0) and len(rivals) == 1 and rivals[0].startswith("420 ")
    warning = rival_basin_warning(chosen.rival_basins, level_determined=True)
    assert "another basin fits as well" in warning and "420" in warning
    assert "its standard error covers one basin only" in warning
    # Where sss_level has no standard error, the warning promises none.
    assert "standard error" not in rival_basin_warning(chosen.rival_basins, level_determined=False)
    assert clear_choice is clear[0]
    assert clear_choice.rival_basins is None
