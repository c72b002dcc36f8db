"""SIGINT (Ctrl-C) and SIGTERM (what schedulers send) as a request to stop cleanly.

Python turns Ctrl-C into a ``KeyboardInterrupt`` raised wherever the main thread
happens to be. Inside a JAX call that is the middle of a compiled computation
or of equinox's machinery: the user gets a long traceback, the work done so far
is lost, and the interpreter can crash on the way out (segmentation faults were
seen). :class:`StopSignals` handles both signals instead:

* outside :meth:`StopSignals.deferred` a signal raises :class:`Interrupted`
  at once (reading inputs, say, where there is nothing to keep);
* inside it, the first signal is only recorded: long work polls the instance
  (it is a ``() -> bool`` callable, the ``stop=`` of :func:`invsss.fit_pair`)
  between steps and stops with what it has; a second signal ends the process
  immediately with the conventional status ``128 + signal number``, for a user
  who does not want to wait.

The exit status of an interrupted command is 130 for SIGINT and 143 for SIGTERM.
A signal whose :class:`Interrupted` is raised where Python cannot propagate it (a
garbage-collection callback, such as JAX's, or a ``__del__``) would be printed as
"Exception ignored" with a traceback and then forgotten; while :class:`StopSignals`
is installed its unraisable hook ends the command in one line instead.

Before :class:`StopSignals` is installed the command is still importing (JAX and
its libraries take a second or more) and parsing its arguments; after it, the
process may wait for a thread on its way out. There a ``KeyboardInterrupt`` would
end in a traceback, or, raised inside a C extension's initialisation, in an
unrelated ``ImportError``. :func:`guard_command_line`, called first thing by
``import invsss`` and acting only in the ``invsss`` command's own process, makes a
signal there end the process at once with one line and the same exit status.
Nothing can be done earlier than that: a signal while Python itself starts (its
``site`` module, the first 0.02-0.1 s) is Python's own affair.

Each of those ways out ends the process with ``os._exit``, which runs no ``finally``
block and no ``atexit`` function. Work that must be undone however the process ends
(an output directory opened and not yet written, :class:`invsss.io.ResultDir`)
registers its undoing with :func:`add_quit_cleanup`; every one of them runs first.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
from collections.abc import Callable, Iterator

__all__ = [
    "Interrupted",
    "StopSignals",
    "add_quit_cleanup",
    "command_finished",
    "guard_command_line",
    "is_command_line",
    "remove_quit_cleanup",
]

_SIGNALS = (signal.SIGINT, signal.SIGTERM)

#: What the command is doing while :func:`guard_command_line`'s handler is in place.
_phase = "while starting; nothing written"

#: What to undo before a signal ends the process at once (:func:`add_quit_cleanup`).
_quit_cleanups: list[Callable[[], object]] = []
# A child made by fork did not take the parent's locks: quitting, it must not release them.
os.register_at_fork(after_in_child=_quit_cleanups.clear)


def add_quit_cleanup(cleanup: Callable[[], object]) -> None:
    """Call ``cleanup()`` if a signal ends this process at once, before it exits.

    The ways out of this module (a signal while starting or exiting, a second signal,
    a signal raised where Python cannot propagate it) use ``os._exit``, which skips
    ``finally`` blocks and ``atexit``. Cleanups run last-added first; one that fails
    does not stop the others. Remove it with :func:`remove_quit_cleanup` once the
    work it undoes is done or undone another way.

    Examples
    --------
    >>> def undo():
    ...     print("undone")
    >>> add_quit_cleanup(undo)
    >>> remove_quit_cleanup(undo)
    """
    _quit_cleanups.append(cleanup)


def remove_quit_cleanup(cleanup: Callable[[], object]) -> None:
    """Forget a cleanup given to :func:`add_quit_cleanup` (no error if it is not there)."""
    with contextlib.suppress(ValueError):
        _quit_cleanups.remove(cleanup)


def _exit_now(status: int) -> None:
    """Run the quit cleanups, then end the process with ``status`` at once."""
    # A further signal must not cut a cleanup short (its handler would raise into it,
    # or quit again): from here on both are ignored.
    for sig in _SIGNALS:
        with contextlib.suppress(ValueError, OSError):  # not the main thread: leave them
            signal.signal(sig, signal.SIG_IGN)
    while _quit_cleanups:
        cleanup = _quit_cleanups.pop()
        try:
            cleanup()
        except BaseException:  # noqa: BLE001 -- on the way out: the other cleanups must still run
            pass
    os._exit(status)


def is_command_line() -> bool:
    """Whether this process is the ``invsss`` command: its console script, or
    ``python -m invsss`` while the package is being imported to run it.

    A pool worker spawned by a sweep, or a script that imports invsss, is not.

    Examples
    --------
    >>> is_command_line()  # the test runner
    False
    """
    main = sys.modules.get("__main__")
    script = getattr(main, "__file__", None) or ""
    name = os.path.basename(script)
    if name == "__main__.py":  # a zipped launcher (Windows' invsss.exe)
        name = os.path.basename(os.path.dirname(script))
    if name.split(".")[0] in ("invsss", "invsss-script"):
        return True
    # python -m invsss: while the module is being found, sys.argv[0] is "-m".
    if sys.argv[:1] != ["-m"]:
        return False
    words = list(getattr(sys, "orig_argv", ()))[1:]
    for i, word in enumerate(words):
        if word.startswith("-m"):
            module = word[2:] or (words[i + 1] if i + 1 < len(words) else "")
            return module in ("invsss", "invsss.cli")
    return False


def guard_command_line() -> bool:
    """In the ``invsss`` command's process, end it at SIGINT or SIGTERM with one line
    (``invsss: interrupted (SIGINT) while starting; nothing written``) and status
    ``128 + signal number``, until :class:`StopSignals` takes over, and again once it
    has let go (:func:`command_finished`). Returns whether it did anything: not in
    any other process, nor where the signal is ignored (a background job).

    Examples
    --------
    >>> guard_command_line()  # the test runner is not the command
    False
    """
    installed = False
    try:
        if not is_command_line():
            return False
        for sig in _SIGNALS:
            try:
                if signal.getsignal(sig) is not signal.SIG_IGN:
                    signal.signal(sig, _quit)
                    installed = True
            except (ValueError, OSError):  # not the main thread: leave the signals alone
                pass
    except KeyboardInterrupt:  # Ctrl-C while the guard was being put in place
        if is_command_line():
            _quit(signal.SIGINT, None)
        raise
    return installed


def command_finished() -> None:
    """Say, from here on, that a signal came after the command's work was done."""
    global _phase
    _phase = "while exiting"


def _quit(signum, frame) -> None:
    # Nothing to keep yet (or nothing left to do): one line and out. os.write and
    # os._exit, not print and sys.exit: no exception may reach the code that was
    # running (an import of a C extension would turn it into an ImportError).
    try:
        sys.stdout.flush()
    except Exception:  # noqa: BLE001 -- a stream in use or closed: its text is lost either way
        pass
    line = f"invsss: interrupted ({signal.Signals(signum).name}) {_phase}\n"
    try:
        os.write(2, line.encode())
    except OSError:
        pass
    _exit_now(128 + signum)


class Interrupted(BaseException):
    """Raised by :class:`StopSignals` for a signal outside a deferred section.

    A ``BaseException``, like ``KeyboardInterrupt``, so that ``except Exception``
    clauses in between do not swallow it.
    """

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def exit_status(self) -> int:
        return 128 + self.signum


class StopSignals:
    """Install handlers for SIGINT and SIGTERM for the duration of a ``with`` block.

    Examples
    --------
    >>> import os, signal
    >>> with StopSignals() as stop:
    ...     with stop.deferred():
    ...         os.kill(os.getpid(), signal.SIGTERM)
    ...         requested = stop()
    >>> requested, stop.exit_status
    (True, 143)
    """

    def __init__(self) -> None:
        self.signum: int | None = None
        #: Whether a signal raised :class:`Interrupted` (outside :meth:`deferred`).
        self.raised = False
        self._deferring = 0
        self._on_first: Callable[[int], None] | None = None
        self._previous: dict = {}
        self._previous_hook = sys.unraisablehook

    def __enter__(self) -> StopSignals:
        for sig in _SIGNALS:
            self._previous[sig] = signal.signal(sig, self._handle)
        self._previous_hook = sys.unraisablehook
        sys.unraisablehook = self._unraisable
        return self

    def __exit__(self, *exc) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()
        sys.unraisablehook = self._previous_hook

    def _unraisable(self, unraisable) -> None:
        # Interrupted raised while the main thread ran a callback Python cannot
        # propagate from (JAX's garbage-collection callback, a __del__): Python
        # would print "Exception ignored in ..." with a traceback and carry on as if
        # no signal had come. Outside a deferred section there is nothing to keep,
        # so end the command as the signal asked, in one line.
        if isinstance(unraisable.exc_value, Interrupted) and self.signum is not None:
            try:
                sys.stdout.flush()
            except Exception:  # noqa: BLE001 -- a stream in use or closed: its text is lost either way
                pass
            try:
                os.write(2, f"invsss: interrupted ({signal.Signals(self.signum).name}); nothing written\n".encode())
            except OSError:
                pass
            _exit_now(128 + self.signum)
        self._previous_hook(unraisable)

    def __call__(self) -> bool:
        """True once a signal has been received: the ``stop`` callback of long work."""
        return self.signum is not None

    @property
    def exit_status(self) -> int | None:
        """``128 + signal number`` once a signal has been received, else None."""
        return None if self.signum is None else 128 + self.signum

    @contextlib.contextmanager
    def deferred(self, on_first: Callable[[int], None] | None = None) -> Iterator[StopSignals]:
        """Record the first signal instead of raising; ``on_first(signum)`` is told of it."""
        self._deferring += 1
        previous, self._on_first = self._on_first, on_first
        try:
            yield self
        finally:
            self._deferring -= 1
            self._on_first = previous

    def _handle(self, signum, frame) -> None:
        if not self._deferring:
            self.signum, self.raised = signum, True
            raise Interrupted(signum)
        if self.signum is not None:
            # The second signal: the user does not want to wait. os._exit skips
            # interpreter teardown, which is where a half-stopped JAX runtime crashes.
            sys.stderr.flush()
            _exit_now(128 + signum)
        self.signum = signum
        if self._on_first is not None:
            self._on_first(signum)
