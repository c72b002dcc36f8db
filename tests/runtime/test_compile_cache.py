"""invsss.runtime.compile_cache: where the persistent compilation cache lives, that a second
process loads what the first compiled, that concurrent processes share one
directory cleanly, and that a folder others may write to is not used. (The command
line's --no-cache: tests/cli/test_compile_cache.py.)"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import jax
import pytest

from invsss import InvalidInputError
from invsss.runtime.compile_cache import cache_directory, enable_compile_cache

# A child process: switch the cache on in argv[1], compile three functions of
# distinct shapes, and print JAX's cache hit/miss counts and a checksum.
_CHILD = r"""
import json, sys
import jax, jax.numpy as jnp
from jax import monitoring
from invsss.runtime.compile_cache import enable_compile_cache

counts = {"hits": 0, "misses": 0}
def listen(event, **kwargs):
    if event == "/jax/compilation_cache/cache_hits":
        counts["hits"] += 1
    elif event == "/jax/compilation_cache/cache_misses":
        counts["misses"] += 1
monitoring.register_event_listener(listen)

used = enable_compile_cache(sys.argv[1], min_compile_seconds=0)

@jax.jit
def work(x):
    for k in range(6):
        x = jnp.tanh(x @ x.T + k) * jnp.cos(x)
    return jnp.sum(x)

total = sum(float(work(jnp.linspace(0.0, 1.0, n * n).reshape(n, n))) for n in (8, 9, 10))
print(json.dumps({"used": str(used), "total": round(total, 6), **counts}))
"""


def _child(directory, env_extra=None):
    env = dict(os.environ)
    env.pop("INVSSS_NO_CACHE", None)
    env.update(env_extra or {})
    return subprocess.Popen([sys.executable, "-c", _CHILD, str(directory)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _finish(process):
    out, err = process.communicate(timeout=240)
    assert process.returncode == 0, err
    return json.loads(out.strip().splitlines()[-1]), err


def _entries(directory: Path) -> list[Path]:
    # JAX names an entry by its key, with "-cache" (and "-atime" beside it).
    return sorted(directory.glob("*-cache"))


def test_directory_precedence(monkeypatch, tmp_path):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.delenv("INVSSS_CACHE_DIR", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    assert cache_directory() == tmp_path / "home" / ".cache" / "invsss" / "jax"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/ignored")
    assert cache_directory() == tmp_path / "home" / ".cache" / "invsss" / "jax"
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_directory() == tmp_path / "xdg" / "invsss" / "jax"
    monkeypatch.setenv("INVSSS_CACHE_DIR", str(tmp_path / "mine"))
    assert cache_directory() == tmp_path / "mine"
    assert cache_directory(tmp_path / "given") == tmp_path / "given"


def test_the_suite_does_not_use_the_home_cache():
    # tests/conftest.py points the cache at a temporary directory for the session.
    assert not cache_directory().is_relative_to(Path.home() / ".cache")


def test_no_cache_variable_leaves_jax_untouched(monkeypatch, tmp_path):
    monkeypatch.setenv("INVSSS_NO_CACHE", "1")
    before = jax.config.jax_compilation_cache_dir
    assert enable_compile_cache(tmp_path / "c") is None
    assert jax.config.jax_compilation_cache_dir == before
    assert not (tmp_path / "c").exists()


def test_bad_inputs(tmp_path):
    with pytest.raises(InvalidInputError, match="directory"):
        enable_compile_cache(42)
    with pytest.raises(InvalidInputError, match="min_compile_seconds"):
        enable_compile_cache(tmp_path, min_compile_seconds="fast")
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert enable_compile_cache(blocker / "jax") is None
    assert any("cannot create it" in str(w.message) for w in caught)


@pytest.mark.slow
def test_a_second_process_loads_instead_of_compiling(tmp_path):
    first, _ = _finish(_child(tmp_path))
    assert first["used"] == str(tmp_path)
    assert first["misses"] >= 3 and first["hits"] == 0
    assert len(_entries(tmp_path)) >= 3
    second, _ = _finish(_child(tmp_path))
    assert second["hits"] >= 3 and second["misses"] == 0
    assert second["total"] == first["total"]


@pytest.mark.slow
def test_without_filelock_the_cache_stays_off_with_one_warning(tmp_path):
    # A child where importing filelock fails, as in an install that lacks it: JAX's
    # size-bounded cache would fail every read; the cache is left off instead.
    process = subprocess.Popen([sys.executable, "-c", "import sys; sys.modules['filelock'] = None\n" + _CHILD,
                                str(tmp_path / "c")], env={k: v for k, v in os.environ.items()
                                                           if k != "INVSSS_NO_CACHE"},
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    result, err = _finish(process)
    assert result["used"] == "None" and result["hits"] == 0
    assert err.count("UserWarning: compilation cache: needs the filelock package") == 1
    assert "Error reading persistent compilation cache" not in err
    assert not _entries(tmp_path / "c")


@pytest.mark.slow
def test_no_cache_in_a_child_process(tmp_path):
    result, _ = _finish(_child(tmp_path / "c", {"INVSSS_NO_CACHE": "1"}))
    assert result["used"] == "None" and result["hits"] == 0
    assert not (tmp_path / "c").exists()


@pytest.mark.slow
def test_concurrent_processes_share_one_directory(tmp_path):
    # Three processes start together on an empty directory and write the same
    # entries; none may fail or read a half-written entry (JAX would warn).
    outcomes = [_finish(p) for p in [_child(tmp_path) for _ in range(3)]]
    for result, err in outcomes:
        assert "persistent compilation cache" not in err, err
        assert result["total"] == outcomes[0][0]["total"]
    after, err = _finish(_child(tmp_path))
    assert after["hits"] >= 3 and after["misses"] == 0, err


def test_cache_folders_are_created_for_you_alone(tmp_path):
    session = os.environ["INVSSS_CACHE_DIR"]
    previous = os.umask(0)  # what made them 0777 before
    try:
        assert enable_compile_cache(tmp_path / "new" / "jax") == tmp_path / "new" / "jax"
    finally:
        os.umask(previous)
        enable_compile_cache(session)
    for folder in (tmp_path / "new", tmp_path / "new" / "jax"):
        assert folder.stat().st_mode & 0o777 == 0o700, folder


@pytest.mark.parametrize("whose", ["writable by others", "someone else's"])
def test_a_cache_folder_not_yours_alone_is_not_used(tmp_path, whose):
    from invsss.runtime import compile_cache

    folder = tmp_path / "shared"
    folder.mkdir()
    if whose == "writable by others":
        folder.chmod(0o777)
        reason = "writable by group and others (mode 0777)"
    else:
        if os.geteuid() != 0:
            pytest.skip("giving a folder to another user needs root")
        os.chown(folder, 4242, 4242)
        reason = "owned by uid 4242, not by you"
    before = jax.config.jax_compilation_cache_dir
    getattr(compile_cache, "_warned", set()).clear()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert enable_compile_cache(folder) is None
        assert enable_compile_cache(folder) is None
    messages = [str(w.message) for w in caught]
    assert len(messages) == 1 and f"compilation cache {folder}: not used, as it is {reason}" in messages[0]
    assert jax.config.jax_compilation_cache_dir == before
