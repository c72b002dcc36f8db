"""An output directory that holds one run's result as a unit.

``invsss fit --out DIR`` writes several files (``params.json``, ``fit.exr``,
``report.png``); a sweep writes the same per trial. Written one after another
into ``DIR``, an interruption could leave files of two runs side by side that
look like one result, and a rerun would silently replace an earlier result.
:class:`ResultDir` is the one protocol every writer of results uses:

* **A lock.** Opening a :class:`ResultDir` takes an exclusive ``fcntl.flock`` on
  ``DIR/.invsss.lock`` and writes who holds it (pid, host, start time, command).
  A second run into the same directory is refused at once with a message naming
  the first. The kernel releases the lock when the holder dies, even by SIGKILL.
* **No silent replacement.** A directory that already holds an invsss result (a
  manifest, or a ``params.json`` from an older invsss) is refused unless
  ``overwrite=True``; the check runs when the directory is opened, before any work.
* **Nothing of the user's is lost.** A result never writes over a file it did not
  write: a name the run will write that holds a file which is not part of the result
  already there (not in its manifest) is refused, ``overwrite`` or not. The run's
  inputs (``inputs=``) are never removed nor written over: an input among the
  previous result's files is kept when that result is replaced (it leaves the result
  and becomes the user's file), and an input at a name the run writes is refused.
* **Checked up front.** Opening creates the lock file, which proves the
  directory is writable, and refuses result names taken by something that is
  not a regular file (a directory called ``params.json``).
* **Atomic as a whole.** :meth:`ResultDir.commit` writes every file into a hidden
  staging folder inside ``DIR``; only then does it write the manifest
  ``invsss-manifest.json`` with ``"state": "incomplete"``, remove the previous
  result's files, move the new ones in (renames on one file system) and
  rewrite the manifest with ``"state": "complete"`` and the list of files.
  Killed at any moment, ``DIR`` therefore holds the previous complete result,
  the new complete result, or a result whose manifest says ``incomplete``
  (which :func:`result_state` reports and ``read_params`` refuses). Files the
  user put in ``DIR`` are never touched; files of the replaced result are
  removed with it.
* **Nothing left behind by a failure.** A directory that opening had to create
  is removed again if the run ends before :meth:`~ResultDir.commit`, also when a
  signal ends the command at once (``os._exit`` runs no ``finally``; the lock
  registers its release with :func:`invsss.runtime.interrupts.add_quit_cleanup`
  as soon as it is held). A SIGKILL between opening and committing can leave it,
  holding just the hidden lock file, and so can a signal in the microseconds
  between creating the lock file and locking it; the next run treats it as empty.

Fault injection for tests: when the environment variable
``INVSSS_TEST_PAUSE_IN_COMMIT`` holds seconds, :meth:`ResultDir.commit` pauses
twice: after marking the directory incomplete, and after moving the first file
in. Each pause prints ``invsss: test hook: pausing in the write phase`` to
stderr and sleeps; ``"60"`` sleeps 60 s both times, ``"0,60"`` passes the first
pause at once and sleeps at the second. Nothing else changes; unset, it costs
nothing.
"""

from __future__ import annotations

import contextlib
import datetime
import errno
import fcntl
import json
import os
import secrets
import shutil
import socket
import sys
import time
from collections.abc import Callable, Iterable, Mapping

from ..runtime.interrupts import add_quit_cleanup, remove_quit_cleanup
from ..validation import InvalidInputError
from .writing import same_file, write_text_atomic

__all__ = [
    "MANIFEST_NAME",
    "LEGACY_RESULT_FILES",
    "ResultDir",
    "ResultDirBusy",
    "ResultWriteError",
    "result_state",
]

#: The manifest that marks a directory as holding an invsss result.
MANIFEST_NAME = "invsss-manifest.json"

#: What a fit of an invsss without manifests wrote; a directory holding
#: ``params.json`` and no manifest is taken as such a result.
LEGACY_RESULT_FILES = ("params.json", "fit.exr", "report.png")

_LOCK_NAME = ".invsss.lock"
_STAGING_PREFIX = ".invsss-staging-"
_PAUSE_ENV = "INVSSS_TEST_PAUSE_IN_COMMIT"


class ResultDirBusy(InvalidInputError):
    """Another run holds the output directory."""


class ResultWriteError(OSError):
    """Writing a result failed after the work was done (full disk, permissions...).

    The directory is left as it was before :meth:`ResultDir.commit` started, or
    marked incomplete if the failure came after the previous result was removed.
    """


def result_state(directory) -> str | None:
    """What ``directory`` holds: ``"complete"``, ``"incomplete"``, ``"damaged"``, ``"legacy"`` or None.

    ``"damaged"`` is a manifest that cannot be read as a JSON object (not a sign
    of an interrupted run: the commit writes it atomically); ``"legacy"`` is a
    ``params.json`` without a manifest (an invsss older than the manifest); None
    is no result at all (a missing or empty directory, or only the user's own files).

    Examples
    --------
    >>> import tempfile
    >>> result_state(tempfile.mkdtemp()) is None
    True
    """
    path = os.fspath(directory)
    manifest = _read_manifest(path)
    if manifest is not None:
        state = manifest.get("state")
        return "complete" if state == "complete" else "damaged" if state == "unreadable" else "incomplete"
    if os.path.isfile(os.path.join(path, "params.json")):
        return "legacy"
    return None


def _read_manifest(directory: str) -> dict | None:
    try:
        with open(os.path.join(directory, MANIFEST_NAME), encoding="utf-8") as f:
            content = json.load(f)
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        return {"state": "unreadable"}
    return content if isinstance(content, dict) else {"state": "unreadable"}


def _result_files(directory: str) -> list[str]:
    """The files of the result now in ``directory`` (from its manifest, or the legacy names)."""
    manifest = _read_manifest(directory)
    if manifest is not None and isinstance(manifest.get("files"), list):
        names = [n for n in manifest["files"] if isinstance(n, str)]
    else:
        names = list(LEGACY_RESULT_FILES) + [
            n for n in os.listdir(directory) if n.startswith("fit_") and n.endswith(".exr")
        ]
    # Also the files the manifest of an interrupted commit says were on their way in.
    if manifest is not None and isinstance(manifest.get("incoming"), list):
        names += [n for n in manifest["incoming"] if isinstance(n, str)]
    # Only plain names inside the directory: a manifest is data, not a path to follow.
    return sorted({n for n in names if n == os.path.basename(n) and n not in ("", ".", "..")})


def _fsync_directory(directory: str) -> None:
    # Make renames durable: without it a power cut can undo them after we report success.
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _write_json_atomic(path: str, content: Mapping) -> None:
    write_text_atomic(path, json.dumps(content, indent=2) + "\n")


def _pause_for_tests(index: int) -> None:
    setting = os.environ.get(_PAUSE_ENV)
    if setting:
        seconds = setting.split(",")
        print("invsss: test hook: pausing in the write phase", file=sys.stderr, flush=True)
        time.sleep(float(seconds[min(index, len(seconds) - 1)]))


class ResultDir:
    """Exclusive, all-or-nothing access to an output directory (see the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        The output directory; created (with its parents) if missing.
    overwrite : bool
        Replace a result the directory already holds. Without it such a
        directory is refused when it is opened.
    names : iterable of str
        The file names the run will write, checked up front: none may be
        something other than a regular file.
    description : str
        Who holds the lock, shown to a second run (e.g. the command line).
    option : str
        How the user names the overwrite switch, for messages (``"--overwrite"``).
    inputs : iterable of (str, path)
        The run's input files as ``(how the user gave it, path)``, e.g.
        ``("--mask", "run/mask_used.png")``. One that is a file of the result being
        replaced is kept (listed in :attr:`kept`); one at a name the run writes is
        refused when the directory is opened.
    advice : mapping of str to str, optional
        For a name the run writes, what to add when a file of the user's is refused
        there (e.g. ``{"mask_used.png": "pass it with --mask to use it as the mask"}``).

    Attributes
    ----------
    kept : list of str
        Names of the previous result's files that are inputs of this run: the commit
        leaves them in place and out of the new manifest.

    Examples
    --------
    >>> import os, tempfile
    >>> out = os.path.join(tempfile.mkdtemp(), "run")
    >>> with ResultDir(out, names=["a.txt"]) as rd:
    ...     written = rd.commit({"a.txt": lambda p: open(p, "w").write("hello")})
    >>> sorted(os.listdir(out)), result_state(out)
    (['a.txt', 'invsss-manifest.json'], 'complete')
    """

    def __init__(
        self,
        path,
        *,
        overwrite: bool = False,
        names: Iterable[str] = (),
        description: str = "",
        option: str = "--overwrite",
        inputs: Iterable[tuple[str, str | os.PathLike[str]]] = (),
        advice: Mapping[str, str] | None = None,
    ):
        self.path = os.fspath(path)
        self.overwrite = overwrite
        self.names = tuple(names)
        self.description = description or " ".join(sys.argv)
        self.option = option
        self.inputs = tuple((label, os.fspath(given)) for label, given in inputs)
        self.advice = dict(advice or {})
        self.kept: list[str] = []
        self._owned: set[str] = set()
        self._fd: int | None = None
        self._created = False
        self.committed = False

    # ------------------------------------------------------------ open / close

    def __enter__(self) -> ResultDir:
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def open(self) -> None:
        """Create if needed, lock, and check the directory; raise before any work."""
        path = self.path
        if os.path.exists(path) and not os.path.isdir(path):
            raise InvalidInputError(f"{path}: expected an output directory, but a file of that name exists", path=path)
        if not os.path.isdir(path):
            try:
                os.makedirs(path)
            except FileExistsError:  # made by a concurrent run a moment ago: lock decides
                pass
            except OSError as err:
                raise InvalidInputError(
                    f"{path}: cannot create the output directory ({err.strerror})",
                    path=path,
                ) from None
            else:
                self._created = True
        try:
            self._lock()
            self._check_contents()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Release the lock; remove the directory if this run created it and wrote nothing.

        A signal that quits at once may run it again from inside a close it interrupted
        (the quit cleanup is removed last, so that such a signal still finds it): each
        step may then run twice, and each is harmless twice.
        """
        fd = self._fd
        if fd is not None:
            # Unlink while still holding the lock: a waiting run that opened the old
            # file notices (inode check in _lock) and retries on a fresh one.
            with contextlib.suppress(OSError):
                os.unlink(os.path.join(self.path, _LOCK_NAME))
            # EBADF when a close this one interrupted had closed it already; the
            # process then exits, with no other file opened in between.
            with contextlib.suppress(OSError):
                os.close(fd)
            self._fd = None
        # Also when the lock was never taken: a signal between creating and locking.
        if self._created and not self.committed:
            with contextlib.suppress(OSError):
                os.rmdir(self.path)  # only succeeds if empty: never removes the user's files
        remove_quit_cleanup(self.close)

    def _lock(self) -> None:
        lock_path = os.path.join(self.path, _LOCK_NAME)
        while True:
            try:
                fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as err:
                raise InvalidInputError(
                    f"{self.path}: cannot write to the output directory ({err.strerror})"
                ) from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as err:
                holder = _read_holder(fd)
                os.close(fd)
                if err.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise ResultDirBusy(
                        f"{self.path}: in use by another invsss run ({holder}); wait for it "
                        "to finish or choose another output directory"
                    ) from None
                raise InvalidInputError(f"{self.path}: cannot lock the output directory ({err.strerror})") from None
            # The holder before us may have unlinked the file between our open and
            # our lock; then we hold a lock on a file nobody else will see.
            try:
                same = os.fstat(fd).st_ino == os.stat(lock_path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                # Ours from here: a signal that quits at once releases it (close()).
                self._fd = fd
                add_quit_cleanup(self.close)
                break
            os.close(fd)
        record = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "started": datetime.datetime.now().isoformat(timespec="seconds"),
            "command": self.description,
        }
        try:
            # Written, then cut to length: a full disk fails here, on the write.
            written = os.write(fd, (json.dumps(record) + "\n").encode())
            os.ftruncate(fd, written)
        except OSError as err:
            # A full disk: refused now, before any work, leaving no empty lock
            # file (nor a directory this run made) behind.
            self.close()
            raise InvalidInputError(
                f"{self.path}: cannot write to the output directory ({err.strerror})"
            ) from None

    def _check_contents(self) -> None:
        path = self.path
        state = result_state(path)
        # The files of the result already here: the only ones a run may remove or replace.
        self._owned = set(_result_files(path)) if state is not None else set()
        here = self._inputs_here(self._owned | set(self.names))
        for name in self.names + (MANIFEST_NAME,):
            target = os.path.join(path, name)
            if os.path.lexists(target) and not os.path.isfile(target):
                raise InvalidInputError(
                    f"{target}: is in the way of the result (not a regular file); move it away",
                    field=target,
                )
            refusal = self._refusal(name, here)
            if refusal is not None:
                raise InvalidInputError(refusal)
        self.kept = sorted(name for name in here if name not in self.names)
        if state is not None and not self.overwrite:
            what = {"complete": "a result", "legacy": "a result", "incomplete": "an incomplete result",
                    "damaged": "a result whose manifest is damaged"}
            listed = ", ".join(n for n in _result_files(path) if os.path.exists(os.path.join(path, n)))
            kept = f" ({', '.join(self.kept)}, an input of this run, would stay)" if self.kept else ""
            raise InvalidInputError(
                f"{path}: already holds {what.get(state, 'a result')} ({listed or MANIFEST_NAME}); "
                f"pass {self.option} to replace it{kept}, or choose another output directory",
                path=path,
            )
        # Staging folders of a run that was killed mid-commit: nobody else can own
        # them while we hold the lock.
        for name in os.listdir(path):
            if name.startswith(_STAGING_PREFIX):
                shutil.rmtree(os.path.join(path, name), ignore_errors=True)

    def _inputs_here(self, names: Iterable[str]) -> dict[str, str]:
        """``{name: how the user gave it}`` for each of ``names`` in the directory that is one
        of the run's input files (the same file, through any path or link)."""
        found: dict[str, str] = {}
        for label, given in self.inputs:
            for name in sorted(names):
                if same_file(given, os.path.join(self.path, name)):
                    found.setdefault(name, label)
        return found

    def _refusal(self, name: str, inputs_here: Mapping[str, str]) -> str | None:
        """Why the run may not write file ``name``, in one line, or None: it is one of the
        run's inputs, or a file of the user's (not part of the result already here)."""
        target = os.path.join(self.path, name)
        if name in inputs_here:
            return (f"{target} ({inputs_here[name]}): an input of this run, and the result writes a file of "
                    f"that name; copy it out of {self.path} and give the copy")
        if name != MANIFEST_NAME and name not in self._owned and os.path.isfile(target):
            advice = self.advice.get(name)
            return (f"{target}: not a file of an earlier invsss result in {self.path}, and this run writes a "
                    f"file of that name; move or rename it{f' ({advice})' if advice else ''}, or choose "
                    "another output directory")
        return None

    # ------------------------------------------------------------------ commit

    def commit(
        self, writers: Mapping[str, Callable[[str], object]], info: Mapping | Callable[[], Mapping] | None = None
    ) -> list[str]:
        """Write the result: ``writers[name](path)`` writes file ``name`` at ``path``.

        Every writer runs first, into a staging folder; the directory changes
        only once all have succeeded. ``info`` (JSON-ready) is stored in the
        manifest; it may be a callable, called once after the writers and
        before the manifest is written (a sweep's trial records its timings
        there). Returns the paths of the files now in the directory.

        Raises
        ------
        ResultWriteError
            A writer or a rename failed (the message says which file and why).
        """
        if self._fd is None:
            raise RuntimeError("ResultDir.commit needs an open (locked) directory")
        names = list(writers)
        for name in names:
            if name != os.path.basename(name) or name in (MANIFEST_NAME, _LOCK_NAME):
                raise ValueError(f"result file name {name!r}: expected a plain file name")
        # Names not declared when the directory was opened get the same check now.
        undeclared = [name for name in names if name not in self.names]
        here = self._inputs_here(undeclared)
        for name in undeclared:
            refusal = self._refusal(name, here)
            if refusal is not None:
                raise ResultWriteError(refusal)
        staging = os.path.join(self.path, _STAGING_PREFIX + secrets.token_hex(4))
        try:
            os.mkdir(staging)
            for name, write in writers.items():
                write(os.path.join(staging, name))
        except BaseException as err:
            shutil.rmtree(staging, ignore_errors=True)
            if isinstance(err, (OSError, InvalidInputError)):
                raise ResultWriteError(f"{self.path}: cannot write the result ({_reason(err)})") from None
            raise

        if callable(info):
            info = info()
        manifest_path = os.path.join(self.path, MANIFEST_NAME)
        manifest = {
            "state": "incomplete",
            "run_id": secrets.token_hex(8),
            "written": datetime.datetime.now().isoformat(timespec="seconds"),
            "command": self.description,
            "files": names,
            **({"info": dict(info)} if info else {}),
        }
        try:
            # The previous result's files go, except the inputs of this run among them.
            old = [n for n in _result_files(self.path) if n not in names and n not in self.kept]
            # From here until the last rename the directory mixes two runs: say so
            # first, and list what is on its way in so a later overwrite can clean up.
            _write_json_atomic(manifest_path, {**manifest, "incoming": names})
            _pause_for_tests(0)
            for name in old:
                with contextlib.suppress(FileNotFoundError):
                    os.remove(os.path.join(self.path, name))
            for i, name in enumerate(names):
                os.replace(os.path.join(staging, name), os.path.join(self.path, name))
                if i == 0:
                    _pause_for_tests(1)
            _fsync_directory(self.path)
            _write_json_atomic(manifest_path, {**manifest, "state": "complete"})
            _fsync_directory(self.path)
        except OSError as err:
            raise ResultWriteError(f"{self.path}: cannot write the result ({_reason(err)})") from None
        finally:
            shutil.rmtree(staging, ignore_errors=True)
        self.committed = True
        self._owned = set(names)
        return [os.path.join(self.path, n) for n in names]


def _reason(err: BaseException) -> str:
    """``"fit.exr: File too large"``: which file and why, on one line."""
    text = " ".join(str(getattr(err, "strerror", None) or err).split())
    filename = getattr(err, "filename", None)
    return f"{os.path.basename(filename)}: {text}" if filename else text


def _read_holder(fd: int) -> str:
    """A description of the lock's holder from the lock file's content."""
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        content = json.loads(os.read(fd, 4096).decode() or "{}")
        return (
            f"pid {content.get('pid')} on {content.get('host')}, started {content.get('started')}: "
            f"{content.get('command')}"
        )
    except (OSError, ValueError, AttributeError):
        return "holder unknown"
