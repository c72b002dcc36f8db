"""The command line switches XLA's concurrency-optimised CPU scheduler off before JAX
starts (invsss.runtime.determinism; with it, the solver's step was not
deterministic), and a value the user gave is kept. Each runs in a child process."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from invsss.runtime.determinism import SCHEDULER_FLAG


def _child(code: str, xla_flags: str | None) -> str:
    env = dict(os.environ)
    env.pop("XLA_FLAGS", None)
    if xla_flags is not None:
        env["XLA_FLAGS"] = xla_flags
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


_CLI = (
    "import json, os; from jax._src import xla_bridge; from invsss.cli import main\n"
    "code = main(['--version'])\n"
    "print(json.dumps([xla_bridge.backends_are_initialized(), os.environ.get('XLA_FLAGS')]))\n"
)


@pytest.mark.slow
def test_the_command_line_sets_the_flag_before_jax_starts():
    started, flags = json.loads(_child(_CLI, None).splitlines()[-1])
    assert started is False  # so XLA will read it
    assert flags == SCHEDULER_FLAG


@pytest.mark.slow
def test_other_flags_are_kept_and_a_given_value_wins():
    _, flags = json.loads(_child(_CLI, "--xla_cpu_multi_thread_eigen=false").splitlines()[-1])
    assert flags == f"--xla_cpu_multi_thread_eigen=false {SCHEDULER_FLAG}"
    _, flags = json.loads(_child(_CLI, "--xla_cpu_enable_concurrency_optimized_scheduler=true").splitlines()[-1])
    assert flags == "--xla_cpu_enable_concurrency_optimized_scheduler=true"
