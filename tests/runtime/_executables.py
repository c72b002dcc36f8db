"""Helpers for the executable cache's tests: a cache switched on in this process
(:func:`cache_dir`), a small function run through it (:func:`call`), entry files and
sealed payloads, a pickle that runs a call when loaded, and a read-only copy of a
folder (:func:`read_only`)."""

from __future__ import annotations

import contextlib
import os
import subprocess
from pathlib import Path

import pytest

#: Whether this process runs as root, who may write anything and mount.
AS_ROOT = os.geteuid() == 0


def double(x, factor):
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


def call(x=None):
    """A fresh persistent_jit of double (nothing in memory), called; its result and warnings."""
    import warnings

    import jax.numpy as jnp

    from invsss.runtime.executable_cache import persistent_jit

    function = persistent_jit(double)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = function(jnp.arange(4.0) if x is None else x, 2.0)
    return [float(v) for v in out], function.traces, [str(w.message) for w in caught]


def entry_files(cache: Path) -> list[Path]:
    return sorted((cache / "executables").glob("*.executable"))


def sealed(payload: bytes) -> bytes:
    """``payload`` as an entry file holds it (a pickle, after the checksum)."""
    from invsss.runtime.executable_entries import seal

    return seal(payload)


class Bomb:
    """A pickle that runs ``call(*args)`` when it is loaded."""

    def __init__(self, call, *args):
        self.call, self.args = call, args

    def __reduce__(self):
        return self.call, self.args


def mount_tmpfs(where: Path, size: str) -> None:
    where.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({done.stderr.strip() or done.returncode})")


def unmount(where: Path) -> None:
    subprocess.run(["umount", "-l", str(where)], capture_output=True)


@pytest.fixture
def read_only(tmp_path):
    """``read_only(folder)``: a copy of ``folder`` this process can read but not write
    (a read-only tmpfs when running as root, who may write anything else; else chmod)."""
    import shutil

    mounted = []

    def make(folder: Path) -> Path:
        copy = tmp_path / "read-only"
        if AS_ROOT:
            mount_tmpfs(copy, "64m")
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
        unmount(where)
    for path in [tmp_path, *tmp_path.rglob("*")] if not AS_ROOT else []:
        with contextlib.suppress(OSError):
            path.chmod(path.stat().st_mode | 0o200)
