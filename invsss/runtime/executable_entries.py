"""The executable cache's entry files, and the checks an entry passes before it is used.

:mod:`invsss.runtime.executable_cache` keeps compiled functions on disk as
entry files; its module docstring gives the three checks in order. This module
holds the files' side of them: an entry is :func:`seal`-ed (a magic line and the
SHA-256 of the payload before it) and :func:`unseal`-ed only if its bytes still
match; :func:`read_private` reads only a regular file that is this user's alone;
:func:`try_in_child` loads and runs an entry once in a separate process, whose
success :func:`record_verified` writes down next to it; :func:`prune` keeps the
folder under its size bound. Files are written through a temporary file and a
rename (:func:`write_atomic`), so a reader sees a whole file or none.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import hashlib
import json
import os
import pickle
import signal
import stat
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax

from .compile_cache import ownership_problem, warn_once

__all__ = [
    "TRIAL_EVENT",
    "VERIFY_SECONDS",
    "Refused",
    "discard",
    "is_verified",
    "prepare_runtime",
    "prune",
    "read_private",
    "record_verified",
    "seal",
    "try_entry",
    "try_in_child",
    "unseal",
    "warn_entry",
    "write_atomic",
]

#: An entry file: this, the SHA-256 digest of the rest (32 bytes), the pickle.
_MAGIC = b"invsss-executable-2\n"
_DIGEST_BYTES = 32

#: How long the child process that tries an entry may take (it loads the entry
#: and runs one call) before the entry counts as failed.
VERIFY_SECONDS = 600


#: The ``jax.monitoring`` event that :func:`try_in_child` records with its seconds, so
#: that the command line can say where a first warm run's time went.
TRIAL_EVENT = "/invsss/executable_cache/trial"


@functools.lru_cache(maxsize=1)
def prepare_runtime() -> None:
    """Set up what lowering would have: an executable loaded without lowering
    finds jaxlib's LAPACK table empty (its first linear solve then crashes the
    process), since jaxlib fills it only when a linear-algebra call is lowered."""
    try:
        from jax._src.lax.linalg import initialize_lapack
    except ImportError:  # a JAX without the hook: lowering a tiny solve fills it too
        import jax.numpy as jnp

        jax.jit(jnp.linalg.solve).lower(jnp.eye(2), jnp.ones(2))
    else:
        initialize_lapack()


class Refused(Exception):
    """A file that is not this user's alone."""


def seal(payload: bytes) -> bytes:
    """An entry file's bytes: the magic line, the payload's SHA-256 digest, the payload."""
    return _MAGIC + hashlib.sha256(payload).digest() + payload


def unseal(data: bytes) -> bytes | None:
    """The payload of an entry file's bytes, or None if they do not match their checksum."""
    head = len(_MAGIC) + _DIGEST_BYTES
    if len(data) < head or not data.startswith(_MAGIC):
        return None
    payload = data[head:]
    return payload if hashlib.sha256(payload).digest() == data[len(_MAGIC):head] else None


def read_private(path: Path) -> bytes:
    """The bytes of ``path``; :class:`Refused` unless it is a regular file (not a
    symbolic link) owned by this user and writable by nobody else."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
    except OSError as err:
        if err.errno == errno.ELOOP:
            raise Refused("a symbolic link") from None
        raise
    try:
        info = os.fstat(fd)
        problem = "not a regular file" if not stat.S_ISREG(info.st_mode) else ownership_problem(info)
        if problem is not None:
            raise Refused(problem)
        with os.fdopen(os.dup(fd), "rb") as file:
            return file.read()
    finally:
        os.close(fd)


def warn_entry(path: Path, what: str) -> None:
    """One warning per entry and run: ``executable cache: NAME <what>; compiling it again``."""
    warn_once(("entry", path.name), f"executable cache: {path.name} {what}; compiling it again")


def discard(path: Path, writable: bool) -> None:
    """Remove a bad entry, so that no later run meets it, even where this run
    does not get to store its replacement."""
    if writable:
        for doomed in (path, _record_path(path)):
            with contextlib.suppress(OSError):
                doomed.unlink()


def _record_path(path: Path) -> Path:
    return path.with_suffix(".verified")


def is_verified(path: Path, digest: str) -> bool:
    """Whether a child process has already run the entry whose file has SHA-256 ``digest``."""
    try:
        return read_private(_record_path(path)).decode("ascii", "replace").strip() == digest
    except (OSError, Refused):
        return False


def record_verified(path: Path, digest: str) -> None:
    write_atomic(_record_path(path), (digest + "\n").encode())


def write_atomic(path: Path, data: bytes) -> bool:
    """Write ``data`` to ``path`` through a temporary file and a rename; False if the disk refused."""
    temporary = None
    try:
        handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=".writing-")
        with os.fdopen(handle, "wb") as file:
            file.write(data)
        os.replace(temporary, path)
        return True
    except OSError:
        # A full or read-only disk costs the next process a compilation.
        if temporary is not None and os.path.exists(temporary):
            with contextlib.suppress(OSError):
                os.unlink(temporary)
        return False



# The child process that tries an entry: argv[1] the entry's bytes (a copy of what
# the parent checked), argv[2] its SHA-256, argv[3] the call's arguments (.npz),
# argv[4] options (JSON). It prints "ok" after the call has finished.
_TRY = """
import sys
from invsss.runtime.executable_entries import try_entry
try_entry(*sys.argv[1:5])
print("ok", flush=True)
"""


def try_in_child(data: bytes, digest: str, leaves) -> str | None:
    """None if a child process loaded the entry ``data`` and ran it on ``leaves``; else what went wrong.

    Its wall time is recorded as the ``jax.monitoring`` event :data:`TRIAL_EVENT`.
    """
    start = time.monotonic()
    try:
        return _try_in_child(data, digest, leaves)
    finally:
        jax.monitoring.record_event_duration_secs(TRIAL_EVENT, time.monotonic() - start)


def _try_in_child(data: bytes, digest: str, leaves) -> str | None:
    import numpy as np

    env = dict(os.environ, INVSSS_NO_CACHE="1")
    # On a GPU this process's JAX already holds most of the device's memory
    # (XLA preallocates 75 %); a child preallocating too left the GPU solver
    # no memory for its handle (issue 35), so the child allocates as it goes.
    env.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
    package_root = str(Path(__file__).resolve().parents[2])  # the folder holding invsss/
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [package_root, env.get("PYTHONPATH")]))
    weak = [bool(getattr(jax.typeof(leaf), "weak_type", False)) for leaf in leaves]
    options = json.dumps({"x64": bool(jax.config.jax_enable_x64), "weak": weak})  # type: ignore[attr-defined]  # jax.config's options are run-time attributes
    with tempfile.TemporaryDirectory(prefix="invsss-try-entry-") as scratch:
        entry_file = os.path.join(scratch, "entry")
        arguments = os.path.join(scratch, "arguments.npz")
        try:
            with open(entry_file, "wb") as file:
                file.write(data)
            np.savez(arguments, *[np.asarray(leaf) for leaf in leaves])
        except OSError as err:
            return f"its arguments could not be written for the trial ({err.strerror})"
        try:
            child = subprocess.run([sys.executable, "-c", _TRY, entry_file, digest, arguments, options],
                                   env=env, capture_output=True, timeout=VERIFY_SECONDS)
        except subprocess.TimeoutExpired:
            return f"no answer within {VERIFY_SECONDS} s"
        except OSError as err:
            return f"the process could not start ({err.strerror})"
    if child.returncode == 0 and child.stdout.split()[-1:] == [b"ok"]:
        return None
    if child.returncode < 0:
        try:
            return f"the process was killed by {signal.Signals(-child.returncode).name}"
        except ValueError:
            return f"the process was killed by signal {-child.returncode}"
    lines = child.stderr.decode(errors="replace").strip().splitlines()
    return f"exit status {child.returncode}" + (f": {lines[-1][:100]}" if lines else "")


def try_entry(entry_file: str, digest: str, arguments: str, options: str) -> None:
    """In the child process of :func:`try_in_child`: load the entry, run it once."""
    import numpy as np
    from jax.experimental import serialize_executable

    settings = json.loads(options)
    jax.config.update("jax_enable_x64", settings["x64"])
    data = Path(entry_file).read_bytes()
    payload = unseal(data)
    if payload is None or hashlib.sha256(data).hexdigest() != digest:
        sys.exit("the entry's bytes changed on their way to the trial")
    prepare_runtime()
    entry = pickle.loads(payload)
    executable = serialize_executable.deserialize_and_load(entry["executable"], entry["in_tree"], entry["out_tree"])
    with np.load(arguments, allow_pickle=False) as stored:
        leaves = [stored[f"arr_{i}"] for i in range(len(settings["weak"]))]
    leaves = [_weak(value) if weak else jax.numpy.asarray(value) for value, weak in zip(leaves, settings["weak"])]
    jax.block_until_ready(executable(*leaves))


def _weak(value):
    """``value`` as a weakly typed array (as a Python scalar argument is traced)."""
    from jax._src.lax import lax as lax_internal

    return lax_internal._convert_element_type(jax.numpy.asarray(value), value.dtype, weak_type=True)


def prune(folder: Path, limit: int) -> None:
    """Delete the least recently used entries until the folder holds at most ``limit`` bytes."""
    entries = []
    for path in folder.glob("*.executable"):
        try:
            stat = path.stat()
        except OSError:
            continue  # removed by another process meanwhile
        entries.append((stat.st_mtime, stat.st_size, path))
    total = sum(size for _, size, _ in entries)
    for _, size, path in sorted(entries):
        if total <= limit:
            break
        try:
            path.unlink()
        except OSError:
            pass
        total -= size
    # The records of entries that are gone (pruned, or replaced by another process).
    for record in folder.glob("*.verified"):
        if not record.with_suffix(".executable").exists():
            with contextlib.suppress(OSError):
                record.unlink()
