"""Suite-wide settings: keep JAX's persistent compilation cache out of the user's home.

The command line switches the cache on (``invsss.runtime.compile_cache``), and the CLI
tests call it in this process and in subprocesses that inherit the environment,
so the whole session points ``INVSSS_CACHE_DIR`` at a temporary directory, set
before any test runs and removed at the end. ``invsss ... --no-cache`` sets
``INVSSS_NO_CACHE`` in the process environment (for a sweep's workers); the
autouse fixture puts both variables back after every test so one test's flag
does not switch the cache off for the next.

The suite compiles with XLA's cheaper CPU optimisation (:data:`TEST_XLA_FLAGS`,
added to ``XLA_FLAGS`` unless it already sets the option): its images are small,
so most of a test's time is XLA compiling the estimator, and LLVM's expensive
passes cost more there than they save (one light-term fit test: 42 s with the
default, 32 s with these, measured 2026-11-26 on an idle 2-core machine). The
numbers do not change meaning: fast math stays off, so the arithmetic is IEEE
either way; only the machine code's speed differs. Child processes inherit it.

Tests marked ``slow`` (a fit that takes more than about 5 s on 2 cores) run in CI
with the rest; ``pytest -m "not slow"`` leaves them out for a quick run while
developing. Doctests cannot carry a marker, so the slow ones are named here.
"""

from __future__ import annotations

import os
import shutil
import signal
import tempfile

import pytest

#: LLVM at its lowest optimisation level, without its expensive passes.
TEST_XLA_FLAGS = "--xla_backend_optimization_level=0 --xla_llvm_disable_expensive_passes=true"
if "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
    # Before any test starts JAX's backend, which reads XLA_FLAGS once.
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {TEST_XLA_FLAGS}".strip()

_VARIABLES = ("INVSSS_CACHE_DIR", "INVSSS_NO_CACHE")
_session_cache: str | None = None


def pytest_configure(config):
    global _session_cache
    _session_cache = tempfile.mkdtemp(prefix="invsss-test-jax-cache-")
    os.environ["INVSSS_CACHE_DIR"] = _session_cache


#: Docstring examples over about 2 s on an idle 2-core machine (a fit, a profile fit,
#: a kernel in interpret mode): in the slow tier, as the tests marked slow are.
SLOW_DOCTESTS = frozenset({
    "invsss.cli.report.plot_fit_report",
    "invsss.estimator.fit.fit_pair",
    "invsss.estimator.problem.build_problem",
    "invsss.estimator.registration.estimate_warp",
    "invsss.estimator.result.FitResult.history_by_stage",
    "invsss.estimator.solve.gauss_newton_distance",
    "invsss.forward.burley_screen_space.render_burley",
    "invsss.forward.burley_screen_space.sample_bilinear",
    "invsss.forward.light_terms",
    "invsss.forward.light_terms.apply_law",
    "invsss.forward.pass_kernels.directional_pass_kernel",
    "invsss.forward.profiles.jensen_dipole",
    "invsss.forward.profiles.total_diffuse_reflectance",
    "invsss.measurement.dipole_fit.fit_dipole",
    "invsss.measurement.profile_fit.fit_sum_of_gaussians",
    "invsss.scenes.media.dipole_fit_to_thesis_profile",
})


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.name in SLOW_DOCTESTS:
            item.add_marker(pytest.mark.slow)


def pytest_unconfigure(config):
    if _session_cache is not None:
        shutil.rmtree(_session_cache, ignore_errors=True)


@pytest.fixture(autouse=True)
def _restore_cache_variables():
    saved = {name: os.environ.get(name) for name in _VARIABLES}
    yield
    for name, value in saved.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value


@pytest.fixture(autouse=True)
def _signal_handlers_left_as_found(request):
    """Fail the test that leaves SIGINT's or SIGTERM's handler changed, and put it back.

    A handler is process state that outlives the test: a worker left with SIGINT
    ignored passes that to every child it starts (an ignored signal survives
    exec), and a later test of Ctrl-C in a child then sees its child finish
    instead of stop (seen in CI's slow tier).
    """
    watched = (signal.SIGINT, signal.SIGTERM)
    before = {sig: signal.getsignal(sig) for sig in watched}
    yield
    after = {sig: signal.getsignal(sig) for sig in watched}
    changed = {sig: handler for sig, handler in after.items() if handler is not before[sig]}
    for sig in changed:
        signal.signal(sig, before[sig])
    if changed:
        pytest.fail(", ".join(f"{signal.Signals(sig).name}: handler {before[sig]!r} left as {now!r}"
                              for sig, now in changed.items()) + f" by {request.node.nodeid}")


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_after_each_file():
    """Free the executables a test file compiled once it is done.

    A test worker lives for hundreds of fits at dozens of image sizes. XLA keeps
    each executable's machine code mapped until it is freed, about 41 memory maps
    apiece, and a process may have 65530 (Linux's vm.max_map_count): CI's workers,
    which kept them all, aborted in LLVM ("Unable to allocate section memory")
    near the end of the slow tier, in whichever test came next (2026-11-27).
    """
    yield
    import gc

    from invsss.runtime.executable_cache import release_compiled

    release_compiled()
    gc.collect()


@pytest.fixture
def float64():
    """JAX's float64 mode for this test alone, so that the other tests in the same worker
    keep its float32 default: for tests compared against float64 references."""
    import jax

    with jax.enable_x64(True):
        yield
