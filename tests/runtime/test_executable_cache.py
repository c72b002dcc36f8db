"""invsss.runtime.executable_cache: entries are pruned least recently used first, sealed
with a checksum that is checked, and refused before anything is unpickled when they
or their folder are not the user's alone; a damaged entry costs a compilation and
one warning, a read-only cache is read quietly, and ``persistent_jit.prepare``
compiles what the call then runs. (The estimator's fits through the cache:
tests/estimator/test_executable_cache.py.)"""

from __future__ import annotations

import os
import pickle
import time
import warnings

import jax.numpy as jnp
import pytest

from invsss.runtime import executable_cache
from invsss.runtime.executable_cache import persistent_jit
from invsss.runtime.executable_entries import prune as _prune
from tests.runtime._compilations import Compilations
from tests.runtime._executables import AS_ROOT, Bomb, call, entry_files, sealed
from tests.runtime._executables import cache_dir, read_only  # noqa: F401 (fixtures)


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


def test_a_checksum_is_written_with_each_entry_and_checked():
    from invsss.runtime.executable_entries import seal as _seal
    from invsss.runtime.executable_entries import unseal as _unseal

    sealed = _seal(b"payload bytes")
    assert _unseal(sealed) == b"payload bytes"
    for position in (len(sealed) // 2, len(sealed) - 1, 3):
        damaged = bytearray(sealed)
        damaged[position] ^= 0x10
        assert _unseal(bytes(damaged)) is None
    assert _unseal(sealed[:-1]) is None and _unseal(b"") is None


def test_a_damaged_entry_is_warned_about_once_and_compiled_again(cache_dir):
    cache = cache_dir()
    assert call()[:2] == ([0.0, 2.0, 4.0, 6.0], 1)
    (entry,) = entry_files(cache)
    data = bytearray(entry.read_bytes())
    data[len(data) * 2 // 3] ^= 0x10
    entry.write_bytes(bytes(data))
    out, traces, warned = call()
    assert out == [0.0, 2.0, 4.0, 6.0] and traces == 1
    assert len(warned) == 1 and f"executable cache: {entry.name} is damaged" in warned[0]
    assert call()[1:] == (0, [])  # compiled again and stored whole


def test_entries_not_yours_alone_are_refused_before_anything_is_unpickled(cache_dir, tmp_path):
    import jax.numpy as jnp

    cache = cache_dir()
    call()
    call(jnp.arange(5.0))  # a second entry
    entries = entry_files(cache)
    assert len(entries) == 2
    markers = [tmp_path / "ran-0", tmp_path / "ran-1"]
    for entry, marker in zip(entries, markers):
        entry.write_bytes(sealed(pickle.dumps(Bomb(open, str(marker), "w"))))
    entries[0].chmod(0o666)  # writable by group and others
    if AS_ROOT:
        os.chown(entries[1], 4242, 4242)  # someone else's
    else:
        entries[1].chmod(0o620)
    first = call()
    second = call(jnp.arange(5.0))
    assert first[:2] == ([0.0, 2.0, 4.0, 6.0], 1) and second[1] == 1
    assert not any(marker.exists() for marker in markers)
    # One notice for the run, however many entries are refused.
    notices = first[2] + second[2]
    assert len(notices) == 1 and "not used, as it is" in notices[0], notices
    assert "writable by group and others" in notices[0] or "not by you" in notices[0]


def test_a_folder_not_yours_alone_is_refused_with_one_notice(cache_dir, tmp_path):
    cache = cache_dir()
    call()
    (entry,) = entry_files(cache)
    marker = tmp_path / "ran"
    entry.write_bytes(sealed(pickle.dumps(Bomb(open, str(marker), "w"))))
    (cache / "executables").chmod(0o777)
    first, second = call(), call()
    assert first[0] == [0.0, 2.0, 4.0, 6.0] and not marker.exists()
    assert len(first[2]) == 1 and "executable cache" in first[2][0] and "not used" in first[2][0]
    assert "writable by group and others (mode 0777)" in first[2][0]
    assert second[2] == []


@pytest.mark.slow
def test_a_read_only_cache_is_used_for_reading_quietly(cache_dir, read_only):
    import jax
    import jax.numpy as jnp

    cache = cache_dir()
    call()
    call()  # tried in a child process and recorded
    frozen = read_only(cache)
    listing = sorted(str(p.relative_to(frozen)) for p in frozen.rglob("*"))
    assert cache_dir(frozen) == frozen
    out, traces, warned = call()
    assert out == [0.0, 2.0, 4.0, 6.0] and traces == 0  # loaded, not compiled
    with warnings.catch_warnings(record=True) as caught:  # JAX's own cache: nothing written, no lock
        warnings.simplefilter("always")
        jax.jit(lambda x: jnp.tanh(x @ x.T) * 3.0)(jnp.ones((7, 7))).block_until_ready()
    assert warned == [] and [str(w.message) for w in caught] == []
    assert sorted(str(p.relative_to(frozen)) for p in frozen.rglob("*")) == listing


@pytest.mark.parametrize("on_disk", [False, True], ids=["memory", "disk"])
def test_prepare_compiles_what_the_call_then_runs(tmp_path, monkeypatch, on_disk):
    # The executable cache is on when a folder is configured; either way a
    # prepared call must find its executable.
    monkeypatch.setattr(executable_cache, "_folder", (lambda: tmp_path / "executables") if on_disk else (lambda: None))

    @persistent_jit
    def prepared_scaled_sum(x, factor):
        return jnp.sum(x * factor)

    x = jnp.arange(5.0)
    with Compilations("prepared_scaled_sum") as compiled:
        prepared_scaled_sum.prepare(x, 2.0)
        by_prepare = compiled.count()
        value = prepared_scaled_sum(x, 2.0)
        prepared_scaled_sum.prepare(x, 2.0)  # compiled already: nothing to do
        assert compiled.count() == by_prepare == 1
        assert float(value) == 20.0
        # Another static argument or shape is another executable.
        assert float(prepared_scaled_sum(x, 3.0)) == 30.0
        assert float(prepared_scaled_sum(jnp.arange(6.0), 2.0)) == 30.0
        assert compiled.count() == 3
    assert len(list((tmp_path / "executables").glob("*.executable"))) == (3 if on_disk else 0)
