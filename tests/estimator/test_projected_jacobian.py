"""The closed-form derivative of the variable projection against forward mode
through :func:`~invsss.estimator.projection.solve_linear`, and the estimator's
difference Jacobian against forward mode through the whole model, with every
kind of unknown the projection's derivative meets (gain ratios, terms after the
blur, vignetting, a grey mix, an inactive basis image)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import invsss
from invsss.estimator import FitOptions, build_problem
from invsss.estimator.projection import combine, projected_jacobian, solve_linear


def _random_problem(seed, active_first=1.0):
    """Two pairs of different sizes, two channels, three basis images and four
    unknowns, all float64 (call under ``jax.enable_x64``)."""
    rng = np.random.default_rng(seed)
    n, nb, c = 4, 3, 2
    shapes = [(9, 7), (6, 8)]
    bases = tuple(jnp.asarray(rng.uniform(0.1, 1.0, (nb, h, w, c))) for h, w in shapes)
    targets = tuple(jnp.asarray(rng.uniform(0.1, 1.0, (h, w, c))) for h, w in shapes)
    # Zero weights where pixels are left out, as the mask and robust weights do.
    weights = tuple(jnp.asarray(rng.uniform(0.0, 1.0, (h, w, c)) * (rng.uniform(size=(h, w, c)) > 0.2))
                    for h, w in shapes)
    ratios = jnp.asarray(np.vstack([np.ones((1, c)), rng.uniform(0.5, 2.0, (1, c))]))
    active = jnp.asarray(np.array([[active_first, 1.0], [1.0, 1.0], [1.0, 1.0]]))
    d_bases = tuple(jnp.asarray(rng.normal(size=(n, nb, h, w, c))) for h, w in shapes)
    d_ratios = jnp.asarray(rng.normal(size=(n, 2, c))).at[:, 0].set(0.0)  # pair 0's ratio is 1
    return bases, targets, weights, ratios, active, d_bases, d_ratios


@pytest.mark.slow
@pytest.mark.parametrize("active_first", [1.0, 0.0])
def test_projected_jacobian_matches_forward_mode_through_the_solve(active_first):
    def predictions(u):
        moved = tuple(x + jnp.tensordot(u, d, axes=1) for x, d in zip(bases, d_bases))
        r = ratios + jnp.tensordot(u, d_ratios, axes=1)
        coef, offset = solve_linear(moved, targets, weights, r, active)
        return tuple(combine(x, r[k], coef, offset[k]) for k, x in enumerate(moved))

    with jax.enable_x64(True):
        bases, targets, weights, ratios, active, d_bases, d_ratios = _random_problem(0, active_first)
        n = d_ratios.shape[0]
        u0 = jnp.zeros(n)
        # Jitted: run op by op, forward mode through the solve took 23 s on 2 cores.
        expected = jax.jit(jax.jacfwd(predictions))(u0)  # per pair (H, W, C, n)
        coef, offset, got = jax.jit(projected_jacobian)(bases, targets, weights, ratios, active, d_bases, d_ratios)
        coef0, offset0 = jax.jit(solve_linear)(bases, targets, weights, ratios, active)
    np.testing.assert_allclose(coef, coef0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(offset, offset0, rtol=0, atol=1e-12)
    if active_first == 0.0:
        assert float(coef[0, 0]) == 0.0
    for e, g in zip(expected, got):
        e = np.moveaxis(np.asarray(e), -1, 0)
        assert np.linalg.norm(e) > 0
        np.testing.assert_allclose(np.asarray(g), e, rtol=0, atol=1e-10 * np.abs(e).max())


@pytest.mark.slow
def test_projected_jacobian_without_moving_ratios_equals_zero_ratio_slopes():
    with jax.enable_x64(True):
        bases, targets, weights, ratios, active, d_bases, d_ratios = _random_problem(1)
        jacobian = jax.jit(projected_jacobian)
        _, _, without = jacobian(bases, targets, weights, ratios, active, d_bases, None)
        _, _, zero = jacobian(bases, targets, weights, ratios, active, d_bases, jnp.zeros_like(d_ratios))
    for a, b in zip(without, zero):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def _lit_pair(size, seed, gain):
    """A textured RGB dome with normals, a light direction and the key light's part
    of the source, and a grey target (not a fit's: only the Jacobian is compared)."""
    rng = np.random.default_rng(seed)
    y, x = (np.mgrid[0:size, 0:size] - (size - 1) / 2.0) / (size / 2.0)
    r2 = np.minimum(x**2 + y**2, 0.9)
    normal = np.stack([0.9 * x, -0.9 * y, np.sqrt(1.0 - 0.81 * r2)], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    light = np.broadcast_to(np.array([-0.6, 0.3, np.sqrt(0.55)]), (size, size, 3)).copy()
    depth = 500.0 - 40.0 * np.sqrt(1.0 - 0.81 * r2)
    source = rng.uniform(0.2, 1.0, (size, size, 3))
    key = 0.7 * source
    mask = (x**2 + y**2 < 0.85).astype(float)
    target = gain * source.mean(axis=-1) + rng.normal(0.0, 0.01, (size, size))
    return invsss.ImagePair(source, target, depth, mask, normal=normal, light=light, key=key)


@pytest.mark.slow  # forward mode through every term compiles for about half a minute
def test_difference_jacobian_matches_forward_mode_for_every_kind_of_unknown():
    """Two pairs (a gain ratio), a grey mix, the law, the three terms after the
    blur and the vignetting: the columns the blur does not depend on, and the mix's
    (exact by linearity), agree with forward mode to rounding; the differenced
    ones to what forward differences of a piecewise-linear interpolation give."""
    from invsss.estimator.solve import DenseJacobian

    pairs = [_lit_pair(20, 0, 1.0), _lit_pair(24, 1, 1.3)]
    options = FitOptions(profile={"weights": [0.5, 0.3, 0.2], "variances": [0.25, 1.2, 5.0]}, n_starts=1,
                         vignetting=True, light_terms=("shift", "grazing", "incidence", "law"))
    problem = build_problem(pairs, options)
    blocks = problem.param.layout()
    assert set(blocks) == {"sss_level", "correction", "maxdd", "mix", "gain_ratio", "vignetting",
                           "light_shift", "grazing", "incidence", "law", "law_strength"}
    with jax.enable_x64(True):
        z = problem.z0 + jnp.asarray(np.random.default_rng(3).uniform(-0.1, 0.1, problem.param.size))

        def jacobian(differences):
            fn = DenseJacobian(problem.objective, differences=differences)
            return np.asarray(jax.jit(jax.jacfwd(lambda u: fn(u)[0]))(z))

        exact, approx = jacobian(False), jacobian(True)
        residual, _ = jax.jit(lambda u: problem.objective(u))(z)
        residual_d, _ = jax.jit(lambda u: problem.objective.difference_jacobian(u, 1e-5))(z)
    np.testing.assert_allclose(np.asarray(residual_d), np.asarray(residual), rtol=0, atol=1e-10)
    for name, (first, stop) in blocks.items():
        tolerance = 1e-3 if name in ("sss_level", "correction", "maxdd", "law", "law_strength") else 1e-9
        for k in range(first, stop):
            assert np.linalg.norm(exact[:, k]) > 0, name
            error = np.linalg.norm(approx[:, k] - exact[:, k]) / np.linalg.norm(exact[:, k])
            assert error < tolerance, (name, k, error)


@pytest.mark.parametrize("grey_target, model, fix, side_by_side", [
    (True, "sog", {}, True), (False, "sog", {}, True),
    pytest.param(True, "thesis", {}, True, marks=pytest.mark.slow),
    # Fixed weights: the layered render mixes them per channel, so one blur per move.
    pytest.param(True, "sog", {"weights": [0.5, 0.3, 0.2]}, False, marks=pytest.mark.slow),
])
def test_lighting_differences_side_by_side_equal_one_blur_per_move(grey_target, model, fix, side_by_side):
    """The law, the fill and the transmission move the source, and their columns
    of the difference Jacobian come from one blur of the source and its moved
    copies side by side as channels. Each must equal the difference of two
    separate blurs, the source at ``z`` and at ``z`` moved in that unknown (made
    here with the objective's own ``blurred_bases``), to rounding: a copy sliced
    from the wrong channels, or mixed with the wrong weights, is off by the size
    of the column itself."""
    size = 20
    pair = _lit_pair(size, 4, 1.0)
    rng = np.random.default_rng(5)
    target = pair.target if grey_target else np.stack([pair.target, 0.8 * pair.target, 0.6 * pair.target], -1)
    pair = invsss.ImagePair(pair.source, target, pair.depth, pair.mask, normal=pair.normal, light=pair.light,
                            key=pair.key, fill_light=-pair.light,
                            thickness=rng.uniform(1.0, 8.0, (size, size)),
                            key_irradiance=rng.uniform(0.2, 1.0, (size, size, 3)))
    options = FitOptions(profile={"weights": [0.5, 0.3, 0.2], "variances": [0.25, 1.2, 5.0]}, n_starts=1,
                         light_terms=("shift", "law", "fill", "transmission"), model=model, fix=fix)
    problem = build_problem([pair], options)
    assert problem.objective._passes_alike_per_channel() == side_by_side
    blocks = problem.param.layout()
    lighting = [name for name in ("law", "law_strength", "fill_strength", "transmission", "thickness_scale")
                if name in blocks]
    assert len(lighting) == 5 and ("mix" in blocks) == grey_target
    step = 1e-5
    with jax.enable_x64(True):
        objective = problem.objective
        z = problem.z0 + jnp.asarray(np.random.default_rng(6).uniform(-0.2, 0.2, problem.param.size))
        blurred, slopes = jax.jit(lambda u: objective._blurred_with_slopes(u, objective.param.natural(u), step))(z)

        def one_blur(u):
            values = objective.param.natural(u)
            # blurred_bases mixes the source to grey before the blur; the slopes mix after it.
            return objective.blurred_bases(values)[0]

        at_z = jax.jit(one_blur)(z)
        np.testing.assert_allclose(np.asarray(blurred[0]), np.asarray(at_z), rtol=0,
                                   atol=1e-12 * float(jnp.abs(at_z).max()))
        for name in lighting:
            first, stop = blocks[name]
            for j in range(first, stop):
                moved = z.at[j].add(step)
                expected = (jax.jit(one_blur)(moved) - at_z) / (moved[j] - z[j])
                column = np.asarray(slopes[0][j])
                norm = float(np.linalg.norm(np.asarray(expected)))
                assert norm > 0, (name, j)
                assert np.linalg.norm(column - np.asarray(expected)) < 1e-5 * norm, (name, j)
