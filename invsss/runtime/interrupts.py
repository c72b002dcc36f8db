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
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
from collections.abc import Callable, Iterator

__all__ = ["Interrupted", "StopSignals"]

_SIGNALS = (signal.SIGINT, signal.SIGTERM)


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

    def __init__(self):
        self.signum: int | None = None
        self._deferring = 0
        self._on_first: Callable[[int], None] | None = None
        self._previous: dict = {}

    def __enter__(self) -> "StopSignals":
        for sig in _SIGNALS:
            self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()

    def __call__(self) -> bool:
        """True once a signal has been received: the ``stop`` callback of long work."""
        return self.signum is not None

    @property
    def exit_status(self) -> int | None:
        """``128 + signal number`` once a signal has been received, else None."""
        return None if self.signum is None else 128 + self.signum

    @contextlib.contextmanager
    def deferred(self, on_first: Callable[[int], None] | None = None) -> Iterator["StopSignals"]:
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
            self.signum = signum
            raise Interrupted(signum)
        if self.signum is not None:
            # The second signal: the user does not want to wait. os._exit skips
            # interpreter teardown, which is where a half-stopped JAX runtime crashes.
            sys.stderr.flush()
            os._exit(128 + signum)
        self.signum = signum
        if self._on_first is not None:
            self._on_first(signum)
