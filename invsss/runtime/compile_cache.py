"""JAX's persistent compilation cache for invsss: where it lives and how to switch it on.

Most of a fit's wall time on a CPU is XLA compiling the estimator's jitted
functions, and a new process compiles them again. JAX can keep compiled
executables on disk, keyed by the program, its shapes and the jax/XLA versions,
so that a second process with the same image size loads them instead.

The command line (``invsss fit``, ``render``, ``sweep``) and the workers of a
local sweep switch it on; a library user calls :func:`enable_compile_cache`.
Where it lives, first match wins:

1. the ``directory`` argument;
2. ``$INVSSS_CACHE_DIR``;
3. ``$XDG_CACHE_HOME/invsss/jax``;
4. ``~/.cache/invsss/jax``.

``INVSSS_NO_CACHE=1`` (or ``--no-cache`` on the command line) leaves it off,
even where a program asks for it.

Several processes may share one directory (a sweep's workers do). JAX 0.10's
file cache writes an entry with a plain ``write_bytes`` (not a rename), so
without a lock a reader can see half a file. It takes a lock file
(``filelock.FileLock``, an ``fcntl`` lock) around every read and write only
when a size bound is set, to keep its least-recently-used bookkeeping
consistent; so :func:`enable_compile_cache` always sets one
(:data:`MAX_CACHE_BYTES`), which is what makes sharing safe. A lock that cannot
be had within JAX's 10 s, or an unreadable entry, costs a compilation and a
warning, never a wrong result: JAX checks every cache read and compiles
afresh on failure.

The same switch turns on :mod:`invsss.runtime.executable_cache`, which keeps the
estimator's largest functions whole (traced, lowered and compiled) in the
directory's ``executables`` folder.

Cache entries are machine code that this process will run, so the directory
must be yours alone: folders are created with mode 0700, and a directory that
is not owned by you, or that group or others may write to, is not used (one
warning, then everything compiles as usual; :func:`private_folder_problem`). A
directory you may read but not write (a read-only mount, say) is used for
reading only, quietly: JAX's size bound and its lock file are left off, and
nothing is written.
"""

from __future__ import annotations

import os
import stat
import threading
import warnings
from pathlib import Path

from ..validation import InvalidInputError

__all__ = [
    "MAX_CACHE_BYTES",
    "MIN_COMPILE_SECONDS",
    "cache_directory",
    "cache_disabled",
    "enable_compile_cache",
    "enabled_directory",
    "make_private_folder",
    "ownership_problem",
    "private_folder_problem",
    "warn_once",
]

#: Bound on the cache directory's size; least recently used entries go first.
#: Setting any bound is also what turns on JAX's cross-process file lock.
MAX_CACHE_BYTES = 2 * 1024**3

#: Compilations quicker than this are not written. JAX's default (1 s) would
#: skip most of the estimator's functions, each 0.1-1 s to compile on a CPU,
#: while caching the many tiny eager operations (a few ms each) would only
#: trade a compilation for a file read.
MIN_COMPILE_SECONDS = 0.05

_FALSE_WORDS = ("", "0", "false", "no", "off")


def cache_disabled() -> bool:
    """True when ``$INVSSS_NO_CACHE`` asks for no persistent compilation cache.

    Any value other than empty, ``0``, ``false``, ``no`` or ``off`` (any case)
    switches the cache off.

    Examples
    --------
    >>> import os
    >>> os.environ["INVSSS_NO_CACHE"] = "1"
    >>> cache_disabled()
    True
    >>> os.environ["INVSSS_NO_CACHE"] = "0"
    >>> cache_disabled()
    False
    >>> del os.environ["INVSSS_NO_CACHE"]
    """
    return os.environ.get("INVSSS_NO_CACHE", "").strip().lower() not in _FALSE_WORDS


def cache_directory(directory: str | os.PathLike | None = None) -> Path:
    """The cache directory: ``directory``, else ``$INVSSS_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/invsss/jax``, else ``~/.cache/invsss/jax``.

    Nothing is created; the result is absolute.

    Parameters
    ----------
    directory : str or os.PathLike, optional

    Returns
    -------
    pathlib.Path

    Examples
    --------
    >>> cache_directory("/tmp/somewhere")
    PosixPath('/tmp/somewhere')
    >>> cache_directory(3)
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: directory: expected a path (str or os.PathLike), got int
    """
    if directory is None:
        for variable, tail in (("INVSSS_CACHE_DIR", ()), ("XDG_CACHE_HOME", ("invsss", "jax"))):
            value = os.environ.get(variable, "")
            # XDG: a relative value is invalid and is to be ignored.
            if value and (variable == "INVSSS_CACHE_DIR" or os.path.isabs(value)):
                return Path(value, *tail).expanduser().absolute()
        return Path.home() / ".cache" / "invsss" / "jax"
    if not isinstance(directory, (str, os.PathLike)) or directory == "":
        raise InvalidInputError(
            f"directory: expected a path (str or os.PathLike), got {type(directory).__name__}"
        )
    return Path(directory).expanduser().absolute()


_warned: set = set()
_warned_lock = threading.Lock()


def warn_once(topic, message: str) -> bool:
    """``warnings.warn(message)`` the first time this process names ``topic``; True if it warned.

    The caches' notices (a refused folder, a damaged entry) are said once per
    run, however many functions or threads meet the same problem.
    """
    with _warned_lock:
        if topic in _warned:
            return False
        _warned.add(topic)
    warnings.warn(message, stacklevel=3)
    return True


def private_folder_problem(path: str | os.PathLike) -> str | None:
    """Why ``path`` may not hold cache entries this process will run, or None if it may.

    It may when it is a folder (symbolic links followed) owned by this user and
    not writable by group or others. A missing folder has no problem.

    Examples
    --------
    >>> import os, tempfile
    >>> folder = tempfile.mkdtemp()
    >>> private_folder_problem(folder) is None
    True
    >>> os.chmod(folder, 0o777)
    >>> private_folder_problem(folder)
    'writable by group and others (mode 0777)'
    """
    try:
        info = os.stat(path)
    except FileNotFoundError:
        return None
    except OSError as err:
        return f"unreadable ({err.strerror})"
    if not stat.S_ISDIR(info.st_mode):
        return "not a folder"
    return ownership_problem(info)


def ownership_problem(info: os.stat_result) -> str | None:
    """Why a file or folder with status ``info`` is not this user's alone, or None if it is."""
    if info.st_uid != os.getuid():
        return f"owned by uid {info.st_uid}, not by you (uid {os.getuid()})"
    who = {0o020: "group", 0o002: "others", 0o022: "group and others"}.get(info.st_mode & 0o022)
    if who:
        return f"writable by {who} (mode {stat.S_IMODE(info.st_mode):04o})"
    return None


def make_private_folder(path: str | os.PathLike) -> Path:
    """Create ``path`` and any missing parents with mode 0700 (whatever the umask)."""
    path = Path(path)
    missing, folder = [], path
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    for folder in reversed(missing):
        try:
            folder.mkdir(mode=0o700)
        except FileExistsError:  # made by a concurrent process a moment ago
            continue
        os.chmod(folder, 0o700)  # mkdir's mode is masked by the umask
    if not path.is_dir():
        raise NotADirectoryError(20, "Not a directory", str(path))
    return path


_enabled: Path | None = None
_read_only = False


def read_only() -> bool:
    """Whether the directory in use (:func:`enabled_directory`) is used for reading only."""
    return _read_only


def enabled_directory() -> Path | None:
    """The directory :func:`enable_compile_cache` switched on, or None when the
    cache is off (never enabled, ``$INVSSS_NO_CACHE`` set since, or JAX's
    ``jax_compilation_cache_dir`` pointed elsewhere by hand).

    Examples
    --------
    >>> import os, tempfile
    >>> os.environ["INVSSS_NO_CACHE"] = "1"
    >>> print(enabled_directory())
    None
    >>> del os.environ["INVSSS_NO_CACHE"]
    """
    if _enabled is None or cache_disabled():
        return None
    import jax

    return _enabled if jax.config.jax_compilation_cache_dir == str(_enabled) else None  # type: ignore[attr-defined]  # jax.config's options are run-time attributes


def enable_compile_cache(
    directory: str | os.PathLike | None = None,
    *,
    min_compile_seconds: float = MIN_COMPILE_SECONDS,
) -> Path | None:
    """Keep JAX's compiled functions on disk, so a new process with the same
    shapes skips most compilation.

    Call it before the first fit; calling it again with the same directory does
    nothing. It sets process-wide JAX options (``jax_compilation_cache_dir``
    and the cache's thresholds and size bound).

    Parameters
    ----------
    directory : str or os.PathLike, optional
        Where to keep the cache (see :func:`cache_directory` for the default).
        Created if missing.
    min_compile_seconds : float
        Compilations quicker than this are not written (default
        :data:`MIN_COMPILE_SECONDS`).

    Returns
    -------
    pathlib.Path or None
        The directory in use, or None when ``$INVSSS_NO_CACHE`` is set, or the
        directory cannot be created or is not yours alone (then a warning says
        why; fitting works as before, only slower to start). A directory you
        can read but not write is used for reading only.

    Examples
    --------
    >>> import os, tempfile
    >>> os.environ["INVSSS_NO_CACHE"] = "1"
    >>> print(enable_compile_cache(tempfile.mkdtemp()))
    None
    >>> del os.environ["INVSSS_NO_CACHE"]
    >>> enable_compile_cache(tempfile.mkdtemp(), min_compile_seconds=-1)
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: min_compile_seconds: expected a number >= 0, got -1
    """
    global _enabled, _read_only
    path = cache_directory(directory)
    if isinstance(min_compile_seconds, bool) or not isinstance(min_compile_seconds, (int, float)) \
            or not min_compile_seconds >= 0:
        raise InvalidInputError(
            f"min_compile_seconds: expected a number >= 0, got {min_compile_seconds!r}"
        )
    if cache_disabled():
        return None
    try:
        # JAX's size bound, and with it the lock that makes a shared directory safe
        # (module docstring), needs filelock; without it every cache read would
        # fail with a warning and cost a compilation anyway.
        import filelock  # noqa: F401
    except ImportError:
        warnings.warn("compilation cache: needs the filelock package to share its directory safely "
                      "(pip install filelock); not caching", stacklevel=2)
        return None
    try:
        make_private_folder(path)
    except OSError as err:
        warnings.warn(f"compilation cache {path}: cannot create it ({err.strerror}); not caching", stacklevel=2)
        return None
    problem = private_folder_problem(path)
    if problem is not None:
        # JAX would run whatever executables such a folder holds.
        warn_once(("refused", str(path)), f"compilation cache {path}: not used, as it is {problem}; "
                  "compiling as usual (make it yours alone, e.g. chmod 700, or set INVSSS_CACHE_DIR)")
        return None
    read_only = not os.access(path, os.W_OK)

    import jax
    from jax.experimental.compilation_cache import compilation_cache

    if read_only:
        # Reading only: nothing is written (no compilation is slow enough to be
        # stored), and no size bound, whose lock file JAX could not create.
        jax.config.update("jax_persistent_cache_min_compile_time_secs", float("inf"))
        jax.config.update("jax_compilation_cache_max_size", -1)
    else:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_seconds))
        jax.config.update("jax_compilation_cache_max_size", MAX_CACHE_BYTES)
    # -1: no size floor (0 would let JAX substitute its own default).
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    current = jax.config.jax_compilation_cache_dir  # type: ignore[attr-defined]  # jax.config's options are run-time attributes
    if _enabled == path and _read_only == read_only and current == str(path):
        return path
    _read_only = read_only
    jax.config.update("jax_compilation_cache_dir", str(path))
    # JAX decides once per process, at the first compilation, whether a cache is
    # in use (and opens it once); anything compiled before this call (an
    # import-time constant) would otherwise leave it off or on the old directory.
    compilation_cache.reset_cache()
    _enabled = path
    return path
