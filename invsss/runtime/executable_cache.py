"""Compiled functions kept whole on disk, so a new process skips tracing as well.

JAX's persistent compilation cache (:mod:`invsss.runtime.compile_cache`) saves XLA's
work, but every new process still traces each jitted function to a jaxpr and
lowers it to find the cache key. For the estimator's three big functions (the
solver's ``init`` and ``step``, and ``evaluate``) that took 1.8 s of a fit of
data_synthetic/fran_front on a 2-core CPU (the solve itself: 1.9 s).

:func:`persistent_jit` is :func:`equinox.filter_jit` plus a second cache:
the compiled executable itself, keyed by everything that decides what tracing
would produce, so a hit needs neither tracing nor lowering:

- the function (module and qualified name) and a fingerprint of invsss's own
  source files and the versions of JAX, jaxlib, equinox, optimistix, lineax
  and jaxtyping, so an edit or an upgrade is a miss;
- the non-array arguments and the tree structure (pickled), and every array
  argument's shape, dtype and weak type;
- the settings that change a trace or a compilation: float64 mode, the default
  matmul precision, dtype promotion, ``XLA_FLAGS``, ``INVSSS_PASS_KERNEL`` and
  ``INVSSS_SCAN_UNROLL`` (which passes are traced), the backend and its device.

It is on exactly when the compilation cache is (:func:`invsss.runtime.compile_cache.enable_compile_cache`
was called and ``$INVSSS_NO_CACHE`` is unset); its files live in the
``executables`` folder of that cache directory. Otherwise the decorated
function is plain :func:`equinox.filter_jit`.

Several processes may share the folder: an entry is written to a temporary
file and renamed into place, so a reader sees a whole entry or none. An entry
that cannot be read or loaded costs a compilation (and one warning), never a
wrong result. The folder is kept under :data:`MAX_EXECUTABLE_BYTES`, the
least recently used entries going first.

Entries are pickles holding machine code, so nothing in one is unpickled or run
before these checks, in this order:

1. **Yours alone.** The folder is created with mode 0700; a folder or an entry
   that is not owned by you, or that group or others may write to, is refused
   (one warning per run) and the function compiled as usual.
2. **Whole.** Each entry starts with the SHA-256 of the rest of its bytes,
   taken when it was written; an entry whose bytes no longer match (a flipped
   bit, a truncated or overwritten file) is reported once and compiled again.
3. **Tried in another process first.** A checksum cannot tell bytes that were
   wrong when they were written (a bug in a writer, memory corruption) from
   good ones, and such an entry can crash the process that loads or runs it
   (a segmentation fault). So the first time an entry is used, a child process
   loads it and runs it once on this call's arguments; only if that child
   succeeds is the entry loaded here, and ``<entry>.verified`` records the
   entry's digest so that later runs load it directly. A child that fails or
   dies costs one warning, and the entry is replaced by a fresh compilation.

A folder you can read but not write is used for reading only, without a word
(its entries still pass the three checks; a child process then tries each
entry on every run, as no record can be written).

The entry files and the checks' code are in :mod:`invsss.runtime.executable_entries`;
this module keys, compiles, stores and loads them.
"""

from __future__ import annotations

import collections
import contextlib
import functools
import hashlib
import io
import os
import pickle
import threading
import weakref
from importlib import metadata
from pathlib import Path

import equinox as eqx
import jax
from jax.extend.core import ClosedJaxpr, Jaxpr

from .executable_entries import (
    Refused,
    discard,
    is_verified,
    prepare_runtime,
    prune,
    read_private,
    record_verified,
    seal,
    try_in_child,
    unseal,
    warn_entry,
    write_atomic,
)

__all__ = ["MAX_EXECUTABLE_BYTES", "MAX_IN_MEMORY", "StaleStatics", "persistent_jit", "release_compiled"]

#: Executables each :class:`persistent_jit` function keeps in memory (the most
#: recently used); older ones are loaded from disk, or compiled, again when next
#: called. XLA's CPU client maps each executable's code into the process, about
#: 41 memory maps apiece (measured 2026-11-27, jax 0.10.2), and Linux allows a
#: process 65530 by default (vm.max_map_count): CI's test workers, which kept
#: every executable they compiled (about 1600 at that rate), aborted in LLVM
#: ("Unable to allocate section memory") compiling the next one. A fit at one
#: size uses one or two per function.
MAX_IN_MEMORY = 16

_INSTANCES: weakref.WeakSet[persistent_jit] = weakref.WeakSet()


def release_compiled() -> None:
    """Drop every executable this process holds in memory: every :class:`persistent_jit`
    function's and JAX's own (:func:`jax.clear_caches`).

    For a long-lived process that compiles for many image sizes (a test run, a
    notebook): XLA keeps each executable's machine code mapped until the
    executable is freed, and the process's memory maps are bounded
    (:data:`MAX_IN_MEMORY`). Executables on disk stay; the next call loads or
    compiles again.

    Examples
    --------
    >>> import jax.numpy as jnp
    >>> @persistent_jit
    ... def doubled(x):
    ...     return 2 * x
    >>> _ = doubled(jnp.ones(3))
    >>> release_compiled()
    >>> doubled(jnp.ones(2)).tolist()
    [2.0, 2.0]
    """
    for fun in list(_INSTANCES):
        fun.release()
    jax.clear_caches()

#: Bound on the ``executables`` folder's size. A 224 x 224 fit's three entries
#: take 1.7 MB.
MAX_EXECUTABLE_BYTES = 512 * 1024**2

_LIBRARIES = ("jax", "jaxlib", "equinox", "optimistix", "lineax", "jaxtyping")
_FORMAT = 2  # of the entry files; bump when their layout changes


@functools.lru_cache(maxsize=1)
def _code_fingerprint() -> str:
    """sha256 of invsss's source files and the tracing libraries' versions."""
    digest = hashlib.sha256(f"format {_FORMAT}".encode())
    for name in _LIBRARIES:
        try:
            version = metadata.version(name)
        except metadata.PackageNotFoundError:
            version = "absent"
        digest.update(f"{name} {version}\n".encode())
    package = Path(__file__).resolve().parent.parent  # invsss/, every layer
    for path in sorted(package.rglob("*.py")):
        digest.update(str(path.relative_to(package)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _settings() -> tuple:
    device = jax.devices()[0]
    return (
        # jax.config's options are attributes made at run time, unknown to mypy.
        bool(jax.config.jax_enable_x64),  # type: ignore[attr-defined]
        str(jax.config.jax_default_matmul_precision),  # type: ignore[attr-defined]
        str(jax.config.jax_numpy_dtype_promotion),  # type: ignore[attr-defined]
        os.environ.get("XLA_FLAGS", ""),
        # Which pass implementation is traced (invsss.forward.pass_kernels) and whether
        # the passes' scan is unrolled (invsss.forward.screen_space).
        os.environ.get("INVSSS_PASS_KERNEL", "auto"),
        os.environ.get("INVSSS_SCAN_UNROLL", "0"),
        device.platform,
        device.device_kind,
    )


class StaleStatics(Exception):
    """A call whose static arguments came from a loaded entry (they hold
    :class:`_JaxprText` in place of a jaxpr) missed the cache, so it cannot be
    traced: start again from arguments of this process (see
    :func:`invsss.estimator.solve.run_solver`)."""


class _JaxprText:
    """A jaxpr kept as its text.

    optimistix keeps the solver's linearisation as a jaxpr in the static part
    of its state; jaxprs do not pickle, so an entry stores their text. A state
    loaded from disk then holds these stand-ins, which serve as keys (equal
    when the text is) and are never traced.
    """

    __slots__ = ("text",)

    def __init__(self, text: str):
        self.text = text

    def __eq__(self, other):
        return isinstance(other, _JaxprText) and other.text == self.text

    def __hash__(self):
        return hash(self.text)

    def __reduce__(self):  # as _Pickler writes a jaxpr, so both give one key
        return _JaxprText, (self.text,)

    def __repr__(self):
        return f"_JaxprText({self.text[:40]!r}...)"


class _Pickler(pickle.Pickler):
    def reducer_override(self, obj):
        if isinstance(obj, (Jaxpr, ClosedJaxpr)):
            return _JaxprText, (str(obj),)
        return NotImplemented


def _dumps(value, shared: bool = True) -> bytes:
    """``value`` pickled, jaxprs as their text. ``shared=False`` writes every
    occurrence of an object in full (no memo), so that the bytes depend on the
    values only, not on which of them happen to be one object: a key."""
    with io.BytesIO() as file:
        pickler = _Pickler(file, protocol=5)
        pickler.fast = not shared
        pickler.dump(value)
        return file.getvalue()


def _never_stored():
    """A context in which JAX's persistent cache stores no compilation (this thread)."""
    from jax._src import config

    return config.persistent_cache_min_compile_time_secs(float("inf"))


def _aval(x) -> tuple:
    aval = jax.typeof(x)
    return tuple(aval.shape), str(aval.dtype), bool(getattr(aval, "weak_type", False))


_checked_folders: dict = {}


def _folder() -> Path | None:
    """The ``executables`` folder, or None when the cache is off or the folder is refused."""
    from .compile_cache import enabled_directory, private_folder_problem, warn_once

    directory = enabled_directory()
    if directory is None:
        return None
    folder = directory / "executables"
    verdict = _checked_folders.get(folder)
    if verdict is None:
        problem = private_folder_problem(folder)
        if problem is not None:
            warn_once(("refused", str(folder)), f"executable cache {folder}: not used, as it is {problem}; "
                      "compiling as usual (make it yours alone, e.g. chmod 700)")
            verdict = False
        elif folder.is_dir():
            verdict = True
        else:
            return folder  # not made yet: the first entry stored creates it, mode 0700
        _checked_folders[folder] = verdict
    return folder if verdict else None


def _writable(folder: Path) -> bool:
    """False for a folder this process may read but not write (then it only reads, quietly)."""
    from .compile_cache import read_only

    target = folder if folder.exists() else folder.parent
    return not read_only() and os.access(target, os.W_OK)


class _Slot:
    """Where an output array goes, in the stored outline of a function's result."""


class _Compiled:
    """One executable (a flat list of arrays in and out) with what turns its
    outputs back into the function's result: the tree of the arrays and the
    result's static part."""

    def __init__(self, executable, out_tree, out_static, loaded_from: Path | None = None):
        self.executable, self.out_tree, self.out_static = executable, out_tree, out_static
        self.loaded_from = loaded_from  # the entry's file, until its first call has run

    def __call__(self, leaves):
        return eqx.combine(jax.tree_util.tree_unflatten(self.out_tree, self.executable(*leaves)),
                           self.out_static)


class persistent_jit:
    """:func:`equinox.filter_jit` whose compiled executables also persist on disk.

    Parameters
    ----------
    fun : callable
        Called with positional arguments only; arrays (``eqx.is_array``) are
        traced, everything else is static and must be hashable, as for
        ``filter_jit``. Its non-array outputs must pickle to be kept on disk
        (if they do not, the executable is kept for this process only).

    Attributes
    ----------
    traces : int
        How many times this process traced ``fun`` through the disk-backed path
        (0 after a run that loaded everything from disk).

    Examples
    --------
    >>> import jax.numpy as jnp
    >>> @persistent_jit
    ... def scaled(x, factor):
    ...     return x * factor
    >>> scaled(jnp.arange(3.0), 2.0)
    Array([0., 2., 4.], dtype=float32)
    """

    def __init__(self, fun) -> None:
        self.fun = fun
        self.jitted = eqx.filter_jit(fun)
        self.traces = 0
        # Most recently used last; at most MAX_IN_MEMORY (see there).
        self._memory: collections.OrderedDict = collections.OrderedDict()
        self._prepared: set = set()  # keys compiled by prepare() without the disk cache
        self._lock = threading.Lock()
        functools.update_wrapper(self, fun)
        _INSTANCES.add(self)

    def _remember(self, key, compiled) -> None:
        self._memory[key] = compiled
        self._memory.move_to_end(key)
        while len(self._memory) > MAX_IN_MEMORY:
            self._memory.popitem(last=False)

    def release(self) -> None:
        """Drop the executables this function holds in memory (not those on disk)."""
        with self._lock:
            self._memory.clear()
            self._prepared.clear()

    @staticmethod
    def _key(args):
        dynamic, static = eqx.partition(args, eqx.is_array)
        leaves, in_tree = jax.tree_util.tree_flatten(dynamic)
        static_leaves, static_tree = jax.tree_util.tree_flatten(static)
        avals = tuple(_aval(x) for x in leaves)
        return (in_tree, static_tree, tuple(static_leaves), avals, _settings()), leaves, in_tree, static

    def prepare(self, *args) -> None:
        """Compile (or load from disk) what a call with ``args`` would run, without running it.

        A later call with arguments of the same shapes, dtypes and static parts
        then starts at once. The fit uses it to compile the solver's step on
        another thread while the start scan runs. Arguments with an unhashable
        static part are left alone (the call itself will say what is wrong).
        """
        key, leaves, in_tree, static = self._key(args)
        folder = _folder()
        try:
            hash(key)
        except TypeError:
            return
        with self._lock:
            if key in self._memory or key in self._prepared:
                return
            if folder is not None:
                self._remember(key, self._load_or_compile(folder, key, leaves, in_tree, static))
                return
            # filter_jit keeps what lower().compile() made for its later calls. (Its
            # wrapper has lower(), though equinox annotates it as a plain callable.)
            self.jitted.lower(*args).compile()  # type: ignore[attr-defined]
            self._prepared.add(key)

    def __call__(self, *args):
        folder = _folder()
        if folder is None:
            return self.jitted(*args)
        key, leaves, in_tree, static = self._key(args)
        try:
            compiled = self._memory.get(key)
        except TypeError:  # an unhashable static argument: filter_jit says so precisely
            return self.jitted(*args)
        with self._lock:
            if compiled is None:
                compiled = self._memory.get(key)
                if compiled is None:
                    compiled = self._load_or_compile(folder, key, leaves, in_tree, static)
            # Used now: the last to leave memory (popitem removes the least recent).
            self._remember(key, compiled)
        if compiled.loaded_from is None:
            return compiled(leaves)
        # A loaded entry's first call waits for its result: an executable that
        # cannot run here fails now, and is compiled again, instead of failing
        # wherever its result is next read.
        try:
            out = jax.block_until_ready(compiled(leaves))
        except jax.errors.JaxRuntimeError as err:
            path = compiled.loaded_from
            warn_entry(path, f"could not run ({str(err).splitlines()[0][:80]})")
            with self._lock:
                compiled = self._compile_and_store(path if _writable(path.parent) else None,
                                                   leaves, in_tree, static)
                self._remember(key, compiled)
            return compiled(leaves)
        compiled.loaded_from = None
        return out

    # ------------------------------------------------------------------ disk

    def _file_key(self, key, static) -> str | None:
        in_tree, static_tree, _, avals, settings = key
        try:
            described = _dumps((in_tree, static, avals, settings), shared=False)
        except Exception:  # noqa: BLE001 - a static part that does not pickle: memory only
            return None
        digest = hashlib.sha256(_code_fingerprint().encode())
        digest.update(f"{self.fun.__module__}.{self.fun.__qualname__}".encode())
        digest.update(described)
        return digest.hexdigest()

    def _load_or_compile(self, folder: Path, key, leaves, in_tree, static) -> _Compiled:
        """The entry for ``key`` from disk, else compiled here and stored."""
        name = self._file_key(key, static)
        path = None if name is None else folder / f"{name}.executable"
        writable = _writable(folder)
        if path is not None and os.path.lexists(path):
            loaded = self._load(path, leaves, writable)
            if loaded is not None:
                return loaded
        return self._compile_and_store(path if writable else None, leaves, in_tree, static)

    @staticmethod
    def _load(path: Path, leaves, writable: bool) -> _Compiled | None:
        """The entry at ``path``, checked (module docstring) before anything in it is
        unpickled or run; None (with one warning) if it is refused, damaged or fails."""
        from jax.experimental import serialize_executable

        from .compile_cache import warn_once

        try:
            data = read_private(path)
        except Refused as err:
            warn_once("refused entry", f"executable cache: {path.name}: not used, as it is {err}; "
                      "compiling it (and any other such entry) as usual")
            return None
        except FileNotFoundError:  # pruned by another process meanwhile
            return None
        except OSError as err:
            warn_entry(path, f"could not be read ({err.strerror})")
            return None
        payload = unseal(data)
        if payload is None:
            warn_entry(path, "is damaged (its bytes do not match the checksum written with it)")
            discard(path, writable)
            return None
        digest = hashlib.sha256(data).hexdigest()
        if not is_verified(path, digest):
            failure = try_in_child(data, digest, leaves)
            if failure is not None:
                warn_entry(path, f"failed when a separate process tried it ({failure})")
                discard(path, writable)
                return None
            if writable:
                record_verified(path, digest)
        try:
            prepare_runtime()
            entry = pickle.loads(payload)
            executable = serialize_executable.deserialize_and_load(
                entry["executable"], entry["in_tree"], entry["out_tree"]
            )
            # The outline is pickled as a pytree of slots, not as a PyTreeDef:
            # equinox's tree nodes do not survive pickling.
            out_tree = jax.tree_util.tree_structure(entry["outline"])
        except Exception as err:  # noqa: BLE001 - any unreadable entry means: compile again
            warn_entry(path, f"could not be loaded ({type(err).__name__})")
            return None
        if writable:
            with contextlib.suppress(OSError):
                os.utime(path)  # most recently used
        return _Compiled(executable, out_tree, entry["out_static"], loaded_from=path)

    def _compile_and_store(self, path: Path | None, leaves, in_tree, static) -> _Compiled:
        compiled, out_tree, out_static = self._compile(leaves, in_tree, static)
        if path is not None:
            self._store(path, compiled, out_tree, out_static)
        return _Compiled(compiled, out_tree, out_static)

    def _compile(self, leaves, in_tree, static):
        if any(isinstance(leaf, _JaxprText) for leaf in jax.tree_util.tree_leaves(static)):
            raise StaleStatics(f"{self.fun.__qualname__}: arguments from a loaded entry missed the cache")
        captured = []

        def flat(*flat_leaves):
            self.traces += 1
            dynamic = jax.tree_util.tree_unflatten(in_tree, flat_leaves)
            out = self.fun(*eqx.combine(dynamic, static))
            out_dynamic, out_static = eqx.partition(out, eqx.is_array)
            out_leaves, out_tree = jax.tree_util.tree_flatten(out_dynamic)
            captured.append((out_tree, out_static))
            return out_leaves

        flat.__name__ = flat.__qualname__ = self.fun.__name__  # what profiles and logs show
        lowered = jax.jit(flat).lower(*leaves)
        # Compiled here, not taken from JAX's persistent cache: an executable JAX
        # loaded from its cache serialises incompletely on a CPU (the next
        # process finds functions missing). So JAX is kept from storing these
        # compilations, and then never has one of them to hand back.
        with _never_stored():
            compiled = lowered.compile()
        return (compiled, *captured[-1])

    @staticmethod
    def _store(path: Path, compiled, out_tree, out_static) -> None:
        from jax.experimental import serialize_executable

        # A host callback is a pointer into this process: such an executable
        # cannot be used by another one (JAX's own cache refuses them too).
        if getattr(getattr(compiled._executable, "_unloaded_executable", None), "host_callbacks", True):
            return
        try:
            executable, in_tree, flat_tree = serialize_executable.serialize(compiled)
            outline = jax.tree_util.tree_unflatten(out_tree, [_Slot() for _ in range(out_tree.num_leaves)])
            data = _dumps({"executable": executable, "in_tree": in_tree, "out_tree": flat_tree,
                           "outline": outline, "out_static": out_static})
        except Exception:  # noqa: BLE001 - not serialisable: kept in memory only
            return
        from .compile_cache import make_private_folder

        folder = path.parent
        try:
            make_private_folder(folder)
        except OSError:
            return
        if write_atomic(path, seal(data)):
            prune(folder, MAX_EXECUTABLE_BYTES)


