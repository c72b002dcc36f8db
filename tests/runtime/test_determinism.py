"""invsss.runtime.determinism: a started backend is left alone. (That the command line
switches XLA's concurrency-optimised CPU scheduler off before JAX starts, keeping a
value the user gave: tests/cli/test_determinism.py.)"""

from __future__ import annotations

import os

import jax

from invsss.runtime.determinism import use_deterministic_scheduler


def test_a_started_backend_is_left_alone(monkeypatch):
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    jax.devices()  # XLA has read its flags: setting one now would only mislead
    assert use_deterministic_scheduler() is False
    assert "XLA_FLAGS" not in os.environ
