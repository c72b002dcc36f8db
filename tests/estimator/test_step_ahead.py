"""The solver loop that steps ahead (``INVSSS_STEP_AHEAD``, on by default on a GPU).

Stepping ahead dispatches step ``i + 1`` before step ``i``'s loss is read, and
drops it when step ``i`` ends the solve. Every way a solve ends (convergence,
the step budget, the stall test, ``stop``, ``arrived``, a loss that is not
finite) must give the record the plain loop gives, bit for bit, and the loop
must really have dispatched one step more (else this file tests the plain loop
twice).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import invsss.estimator.solve as solve_module
from invsss.estimator.solve import STEP_AHEAD_VARIABLE, run_solver, step_ahead
from invsss.validation import InvalidInputError


class _Decay(eqx.Module):
    """Residual of ``a exp(-t / tau) + b`` against noisy samples; z = (a, log tau, b)."""

    t: jax.Array
    y: jax.Array

    def __call__(self, z, args=None):
        return z[0] * jnp.exp(-self.t * jnp.exp(-z[1])) + z[2] - self.y, None


class _Blows(eqx.Module):
    """A residual that is finite at the start and infinite one step later."""

    def __call__(self, z, args=None):
        return jnp.array([jnp.where(z[0] > 0.5, jnp.inf, z[0] - 1.0), z[0] - 1.0]), None


def _problem():
    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 5.0, 200)
    y = 2.0 * np.exp(-t / 1.3) + 0.3 + 0.05 * rng.standard_normal(t.size)
    return _Decay(jnp.asarray(t), jnp.asarray(y)), jnp.array([0.5, 1.5, 0.0])


def _counting_step(monkeypatch):
    calls = []
    inner = solve_module._step

    def step(*args):
        calls.append(1)
        return inner(*args)

    monkeypatch.setattr(solve_module, "_step", step)
    return calls


def _solve_both(monkeypatch, solve):
    """``solve()`` with the plain loop and with stepping ahead: both records and step calls."""
    out = {}
    for mode in ("0", "1"):
        monkeypatch.setenv(STEP_AHEAD_VARIABLE, mode)
        calls = _counting_step(monkeypatch)
        out[mode] = (solve(), len(calls))
        monkeypatch.undo()
    return out["0"], out["1"]


def _assert_same(plain, ahead):
    assert ahead.history.tobytes() == plain.history.tobytes()
    assert np.asarray(ahead.z).tobytes() == np.asarray(plain.z).tobytes()
    assert (ahead.steps, ahead.converged, ahead.failure, ahead.interrupted) == (
        plain.steps, plain.converged, plain.failure, plain.interrupted)
    # The state handed back resumes the same solve (run_solver(state=)).
    for a, b in zip(jax.tree_util.tree_leaves(ahead.state), jax.tree_util.tree_leaves(plain.state)):
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes()


def _lm():
    return optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize("ending", ["converged", "budget", "stall", "stop", "arrived"])
def test_stepping_ahead_returns_the_plain_loops_record(monkeypatch, ending):
    kwargs = {}
    max_steps = 200
    if ending == "budget":
        max_steps = 3
    elif ending == "stall":
        kwargs["stall_tolerance"] = 10.0
    elif ending == "stop":
        kwargs["stop"] = None  # set afresh for each solve below
    elif ending == "arrived":
        kwargs["arrived"] = lambda z: float(z[0]) > 1.0

    def solve():
        if "stop" in kwargs:
            polls = iter(range(100))
            kwargs["stop"] = lambda: next(polls) == 2  # true at the third step's poll
        return run_solver(_lm(), problem, z0, max_steps, **kwargs)

    with jax.enable_x64(True):
        problem, z0 = _problem()
        (plain, plain_calls), (ahead, ahead_calls) = _solve_both(monkeypatch, solve)
    _assert_same(plain, ahead)
    assert plain_calls == plain.steps
    # One step dispatched past the end, unless the budget ended the solve.
    assert ahead_calls == plain.steps + (0 if plain.steps == max_steps else 1)
    expected = {"converged": plain.converged, "budget": plain.steps == 3 and not plain.converged,
                "stall": plain.converged and plain.steps < 20, "stop": plain.interrupted and plain.steps == 3,
                "arrived": plain.converged}
    assert expected[ending], (ending, plain)


def test_stepping_ahead_keeps_the_failure_of_a_loss_that_is_not_finite(monkeypatch):
    def solve():
        return run_solver(optx.GaussNewton(rtol=1e-8, atol=1e-8), _Blows(), jnp.zeros(1), 20)

    with jax.enable_x64(True):
        (plain, _), (ahead, ahead_calls) = _solve_both(monkeypatch, solve)
    assert plain.failure, plain
    _assert_same(plain, ahead)
    assert ahead_calls == plain.steps + 1


def test_step_ahead_reads_its_variable(monkeypatch):
    monkeypatch.setenv(STEP_AHEAD_VARIABLE, "1")
    assert step_ahead()
    monkeypatch.setenv(STEP_AHEAD_VARIABLE, "0")
    assert not step_ahead()
    monkeypatch.setenv(STEP_AHEAD_VARIABLE, "auto")
    assert step_ahead() == (jax.default_backend() != "cpu")
    monkeypatch.setenv(STEP_AHEAD_VARIABLE, "yes")
    with pytest.raises(InvalidInputError, match=r"^INVSSS_STEP_AHEAD: expected one of auto, 1, 0, got 'yes'$"):
        step_ahead()
