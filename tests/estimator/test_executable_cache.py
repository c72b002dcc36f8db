"""The estimator's compiled functions in the executable cache (invsss.runtime.executable_cache):
a second process runs them from disk without tracing them and fits with the very
same numbers; a damaged, missing or read-only entry costs a compilation, never a
wrong result or a crash. Each fit runs in a child process."""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
from pathlib import Path

import pytest

from invsss.runtime import executable_entries
from tests import ROOT
from tests.runtime._executables import read_only  # noqa: F401 (fixture)

# A child process: switch the cache on in argv[1], fit a small model-made pair
# (argv[2]: how many starts) and print the fit and how often each of the
# estimator's cached functions was traced.
_FIT = r"""
import json, sys, warnings
sys.path.insert(0, sys.argv[3])
from invsss.runtime.compile_cache import enable_compile_cache
enable_compile_cache(sys.argv[1])
import invsss
from invsss.estimator import problem, solve
from tests.forward._estimator_scenes import make_pair

truth = invsss.SSSParams(700.0, 300.0, 2.0, [0.5, 0.3, 0.2], [6.0, 1.5, 0.4])
source, target, depth, mask, _ = make_pair("face", truth, size=40, noise=0.01, seed=3)
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    result = invsss.fit_pair(source, target, depth, mask, n_starts=int(sys.argv[2]))
print(json.dumps({
    "fit": result.to_dict(),
    "iterations": result.iterations,
    "traces": {f.__name__: f.traces for f in (solve._init, solve._step, problem.evaluate)},
    "warnings": [str(w.message) for w in caught if "executable cache" in str(w.message)],
    "all_warnings": [str(w.message) for w in caught],
}, default=str))
"""


def _fit(directory, starts=2, env_extra=None):
    env = dict(os.environ)
    env.pop("INVSSS_NO_CACHE", None)
    env.update(env_extra or {})
    out = subprocess.run([sys.executable, "-c", _FIT, str(directory), str(starts), str(ROOT)], env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def _entries(directory: Path) -> list[Path]:
    return sorted((directory / "executables").glob("*.executable"), key=lambda p: p.stat().st_mtime_ns)


@pytest.fixture(scope="module")
def reference():
    """The fit without any cache."""
    return _fit("/nonexistent-unused", env_extra={"INVSSS_NO_CACHE": "1"})


@pytest.mark.slow
def test_a_second_process_traces_nothing_and_fits_the_same(tmp_path, reference):
    first = _fit(tmp_path)
    assert len(_entries(tmp_path)) == 3  # evaluate, the solver's init and its step
    assert all(count >= 1 for count in first["traces"].values())
    second = _fit(tmp_path)
    assert second["traces"] == {"_init": 0, "_step": 0, "evaluate": 0}
    # Bit for bit: the stored executable is the one the first process compiled.
    assert first["fit"] == reference["fit"]
    assert second["fit"] == reference["fit"]
    assert not first["warnings"] and not second["warnings"]


@pytest.mark.slow  # three or four child processes, each fitting
def test_an_unreadable_entry_is_compiled_again_with_a_warning(tmp_path, reference):
    _fit(tmp_path)
    for entry in _entries(tmp_path):
        entry.write_bytes(b"not an executable")
    again = _fit(tmp_path)
    assert again["fit"] == reference["fit"]
    assert len(again["warnings"]) == 3
    assert all(count >= 1 for count in again["traces"].values())
    # ... and the entries were written again, whole.
    assert _fit(tmp_path)["traces"] == {"_init": 0, "_step": 0, "evaluate": 0}


@pytest.mark.slow  # three or four child processes, each fitting
def test_a_stored_init_without_its_step_starts_the_solve_afresh(tmp_path, reference):
    # The solver's state holds its linearisation as a jaxpr, which a loaded
    # entry keeps as text: a step that must be traced cannot take that state.
    _fit(tmp_path)
    # The step's result is the tuple (z, state, loss, dof, done, ok); the init's
    # is a solver state and evaluate's a dict. (The step compiles on a second
    # thread, so the order the entries were stored in does not tell them apart.)
    # An entry is sealed with its checksum; the payload is the pickle.
    steps = [entry for entry in _entries(tmp_path)
             if isinstance(pickle.loads(executable_entries.unseal(entry.read_bytes()))["outline"], tuple)]
    assert len(steps) == 1
    steps[0].unlink()
    assert len(_entries(tmp_path)) == 2
    again = _fit(tmp_path)
    assert again["fit"] == reference["fit"]
    assert again["traces"]["_init"] == 0


@pytest.mark.slow  # three or four child processes, each fitting
def test_another_layout_is_another_entry(tmp_path):
    _fit(tmp_path, starts=2)
    # One start: no same-basin test, the same three functions and layouts.
    one = _fit(tmp_path, starts=1)
    assert one["traces"] == {"_init": 0, "_step": 0, "evaluate": 0}
    assert len(_entries(tmp_path)) == 3


@pytest.mark.slow  # four child processes, each fitting
def test_concurrent_processes_share_one_folder(tmp_path, reference):
    # What a sweep's workers do: two processes that find the folder empty compile
    # and write the same entries at once; a rename puts each in place whole.
    env = dict(os.environ)
    env.pop("INVSSS_NO_CACHE", None)
    children = [subprocess.Popen([sys.executable, "-c", _FIT, str(tmp_path), "2", str(ROOT)], env=env,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    for child in children:
        out, err = child.communicate(timeout=300)
        assert child.returncode == 0, err
        assert json.loads(out.strip().splitlines()[-1])["fit"] == reference["fit"]
    assert len(_entries(tmp_path)) == 3
    assert not list((tmp_path / "executables").glob(".writing-*"))
    after = _fit(tmp_path)
    assert after["traces"] == {"_init": 0, "_step": 0, "evaluate": 0}
    assert after["fit"] == reference["fit"] and not after["warnings"]


@pytest.fixture(scope="module")
def warm(tmp_path_factory):
    """A cache folder after one fit (copy it before changing it)."""
    folder = tmp_path_factory.mktemp("warm") / "cache"
    _fit(folder)
    return folder


@pytest.mark.slow  # two child processes, each fitting
def test_a_fit_after_entries_were_damaged_gets_the_no_cache_estimate(tmp_path, warm, reference):
    import shutil

    cache = tmp_path / "cache"
    shutil.copytree(warm, cache)
    entries = sorted(_entries(cache), key=lambda p: p.stat().st_size)
    assert len(entries) == 3
    # A flipped bit in the compiled code of the largest (before checksums, this one
    # aborted every later fit at this size) and a block of zeros in another.
    data = bytearray(entries[-1].read_bytes())
    data[len(data) * 65 // 100] ^= 0x10
    entries[-1].write_bytes(bytes(data))
    data = bytearray(entries[-2].read_bytes())
    data[len(data) // 2:len(data) // 2 + 4096] = bytes(4096)
    entries[-2].write_bytes(bytes(data))
    again = _fit(cache)
    assert again["fit"] == reference["fit"]  # bit for bit
    assert sorted(again["warnings"]) == sorted(
        f"executable cache: {entry.name} is damaged (its bytes do not match the checksum written with it); "
        "compiling it again" for entry in entries[-2:])
    healed = _fit(cache)  # the damaged entries are gone
    assert healed["fit"] == reference["fit"] and healed["all_warnings"] == []


@pytest.mark.slow  # one child process fitting
def test_a_fit_from_a_read_only_cache_loads_it_without_a_word(warm, read_only, reference):
    frozen = read_only(warm)
    listing = sorted(str(p.relative_to(frozen)) for p in frozen.rglob("*"))
    again = _fit(frozen)
    assert again["fit"] == reference["fit"]
    assert again["all_warnings"] == []
    assert again["traces"] == {"_init": 0, "_step": 0, "evaluate": 0}
    assert sorted(str(p.relative_to(frozen)) for p in frozen.rglob("*")) == listing
