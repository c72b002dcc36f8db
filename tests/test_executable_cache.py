"""invsss.runtime.executable_cache: a second process runs the estimator's compiled
functions from disk without tracing them, with the very same numbers; a bad or
missing entry costs a compilation, never a wrong result or a crash."""

from __future__ import annotations

import contextlib
import json
import os
import pickle
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest

from invsss.runtime import executable_entries
from invsss.runtime.executable_entries import prune as _prune

_TESTS = Path(__file__).resolve().parent

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
from _estimator_scenes import make_pair

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
    out = subprocess.run([sys.executable, "-c", _FIT, str(directory), str(starts), str(_TESTS)], env=env,
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
    children = [subprocess.Popen([sys.executable, "-c", _FIT, str(tmp_path), "2", str(_TESTS)], env=env,
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


def test_prune_removes_the_least_recently_used(tmp_path):
    now = time.time()
    for age, name in enumerate(["new", "mid", "old"]):
        path = tmp_path / f"{name}.executable"
        path.write_bytes(b"x" * 100)
        os.utime(path, (now - 100 * age, now - 100 * age))
    (tmp_path / "other.txt").write_bytes(b"y" * 1000)  # not an entry: left alone
    _prune(tmp_path, 250)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mid.executable", "new.executable", "other.txt"]
    _prune(tmp_path, 100)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new.executable", "other.txt"]


# ------------------------------------------------- checks before anything is unpickled

_ROOT = os.geteuid() == 0


def _double(x, factor):
    return x * factor


@pytest.fixture
def cache_dir(tmp_path):
    """A fresh cache switched on in this process (the session's is put back afterwards)."""
    from invsss.runtime import compile_cache, executable_cache
    from invsss.runtime.compile_cache import enable_compile_cache

    def forget():  # what this process has warned about and checked
        for name, module in (("_warned", compile_cache), ("_checked_folders", executable_cache)):
            getattr(module, name, {}).clear()

    session = os.environ["INVSSS_CACHE_DIR"]
    forget()
    yield lambda path=tmp_path / "cache": enable_compile_cache(path)
    forget()
    enable_compile_cache(session)


def _call(x=None):
    """A fresh persistent_jit of _double (nothing in memory), called; its result and warnings."""
    import warnings

    import jax.numpy as jnp

    from invsss.runtime.executable_cache import persistent_jit

    function = persistent_jit(_double)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = function(jnp.arange(4.0) if x is None else x, 2.0)
    return [float(v) for v in out], function.traces, [str(w.message) for w in caught]


def _entry_files(cache: Path) -> list[Path]:
    return sorted((cache / "executables").glob("*.executable"))


def _sealed(payload: bytes) -> bytes:
    """``payload`` as an entry file holds it (a pickle, after the checksum)."""
    from invsss.runtime.executable_entries import seal

    return seal(payload)


class _Bomb:
    """A pickle that runs ``call(*args)`` when it is loaded."""

    def __init__(self, call, *args):
        self.call, self.args = call, args

    def __reduce__(self):
        return self.call, self.args


def test_a_checksum_is_written_with_each_entry_and_checked():
    from invsss.runtime.executable_entries import seal as _seal, unseal as _unseal

    sealed = _seal(b"payload bytes")
    assert _unseal(sealed) == b"payload bytes"
    for position in (len(sealed) // 2, len(sealed) - 1, 3):
        damaged = bytearray(sealed)
        damaged[position] ^= 0x10
        assert _unseal(bytes(damaged)) is None
    assert _unseal(sealed[:-1]) is None and _unseal(b"") is None


def test_a_damaged_entry_is_warned_about_once_and_compiled_again(cache_dir):
    cache = cache_dir()
    assert _call()[:2] == ([0.0, 2.0, 4.0, 6.0], 1)
    (entry,) = _entry_files(cache)
    data = bytearray(entry.read_bytes())
    data[len(data) * 2 // 3] ^= 0x10
    entry.write_bytes(bytes(data))
    out, traces, warned = _call()
    assert out == [0.0, 2.0, 4.0, 6.0] and traces == 1
    assert len(warned) == 1 and f"executable cache: {entry.name} is damaged" in warned[0]
    assert _call()[1:] == (0, [])  # compiled again and stored whole


@pytest.mark.slow
def test_an_entry_that_crashes_its_loader_is_tried_in_a_separate_process_first(cache_dir):
    # Bytes that were wrong when written pass their checksum: such an entry (here
    # a pickle that aborts the process loading it, as a flipped bit in compiled
    # code did) must not take this process down.
    cache = cache_dir()
    _call()
    (entry,) = _entry_files(cache)
    entry.write_bytes(_sealed(pickle.dumps(_Bomb(os.abort))))
    out, traces, warned = _call()
    assert out == [0.0, 2.0, 4.0, 6.0] and traces == 1
    assert len(warned) == 1, warned
    assert f"executable cache: {entry.name} failed when a separate process tried it" in warned[0]
    assert "SIGABRT" in warned[0]
    # Replaced by the compilation; tried once more in a child, then recorded as tried.
    from invsss.cli.progress import trial_seconds

    before = trial_seconds()
    assert _call()[1:] == (0, [])
    assert entry.with_suffix(".verified").is_file()
    tried = trial_seconds() - before
    assert tried > 0.1  # the child's time, as the command line reports it
    assert _call()[1:] == (0, [])
    assert trial_seconds() - before == tried  # a verified entry is not tried again


def test_entries_not_yours_alone_are_refused_before_anything_is_unpickled(cache_dir, tmp_path):
    import jax.numpy as jnp

    cache = cache_dir()
    _call()
    _call(jnp.arange(5.0))  # a second entry
    entries = _entry_files(cache)
    assert len(entries) == 2
    markers = [tmp_path / "ran-0", tmp_path / "ran-1"]
    for entry, marker in zip(entries, markers):
        entry.write_bytes(_sealed(pickle.dumps(_Bomb(open, str(marker), "w"))))
    entries[0].chmod(0o666)  # writable by group and others
    if _ROOT:
        os.chown(entries[1], 4242, 4242)  # someone else's
    else:
        entries[1].chmod(0o620)
    first = _call()
    second = _call(jnp.arange(5.0))
    assert first[:2] == ([0.0, 2.0, 4.0, 6.0], 1) and second[1] == 1
    assert not any(marker.exists() for marker in markers)
    # One notice for the run, however many entries are refused.
    notices = first[2] + second[2]
    assert len(notices) == 1 and "not used, as it is" in notices[0], notices
    assert "writable by group and others" in notices[0] or "not by you" in notices[0]


def test_a_folder_not_yours_alone_is_refused_with_one_notice(cache_dir, tmp_path):
    cache = cache_dir()
    _call()
    (entry,) = _entry_files(cache)
    marker = tmp_path / "ran"
    entry.write_bytes(_sealed(pickle.dumps(_Bomb(open, str(marker), "w"))))
    (cache / "executables").chmod(0o777)
    first, second = _call(), _call()
    assert first[0] == [0.0, 2.0, 4.0, 6.0] and not marker.exists()
    assert len(first[2]) == 1 and "executable cache" in first[2][0] and "not used" in first[2][0]
    assert "writable by group and others (mode 0777)" in first[2][0]
    assert second[2] == []


def _mount_tmpfs(where: Path, size: str) -> None:
    where.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({done.stderr.strip() or done.returncode})")


def _unmount(where: Path) -> None:
    subprocess.run(["umount", "-l", str(where)], capture_output=True)


@pytest.fixture
def read_only(tmp_path):
    """``read_only(folder)``: a copy of ``folder`` this process can read but not write
    (a read-only tmpfs when running as root, who may write anything else; else chmod)."""
    import shutil

    mounted = []

    def make(folder: Path) -> Path:
        copy = tmp_path / "read-only"
        if _ROOT:
            _mount_tmpfs(copy, "64m")
            mounted.append(copy)
            shutil.copytree(folder, copy, dirs_exist_ok=True, symlinks=True)
            done = subprocess.run(["mount", "-o", "remount,ro", str(copy)], capture_output=True, text=True)
            if done.returncode != 0:
                pytest.skip(f"cannot remount a tmpfs read-only here ({done.stderr.strip()})")
        else:
            shutil.copytree(folder, copy, symlinks=True)
            for path in [copy, *copy.rglob("*")]:
                path.chmod(path.stat().st_mode & ~0o222)
        return copy

    yield make
    for where in mounted:
        _unmount(where)
    for path in [tmp_path, *tmp_path.rglob("*")] if not _ROOT else []:
        with contextlib.suppress(OSError):
            path.chmod(path.stat().st_mode | 0o200)


@pytest.mark.slow
def test_a_read_only_cache_is_used_for_reading_quietly(cache_dir, read_only):
    import jax
    import jax.numpy as jnp

    cache = cache_dir()
    _call()
    _call()  # tried in a child process and recorded
    frozen = read_only(cache)
    listing = sorted(str(p.relative_to(frozen)) for p in frozen.rglob("*"))
    assert cache_dir(frozen) == frozen
    out, traces, warned = _call()
    assert out == [0.0, 2.0, 4.0, 6.0] and traces == 0  # loaded, not compiled
    with warnings.catch_warnings(record=True) as caught:  # JAX's own cache: nothing written, no lock
        warnings.simplefilter("always")
        jax.jit(lambda x: jnp.tanh(x @ x.T) * 3.0)(jnp.ones((7, 7))).block_until_ready()
    assert warned == [] and [str(w.message) for w in caught] == []
    assert sorted(str(p.relative_to(frozen)) for p in frozen.rglob("*")) == listing


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
