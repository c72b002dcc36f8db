"""The fit's progress line on stderr, and the seconds it spent compiling."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

#: Wall-time intervals, by what filled them: "compile" (JAX's compile events) and
#: "trial" (the executable cache trying an entry in a child process).
#: "listening": whether the listener is registered.
_SPANS: dict[str, Any] = {"compile": [], "trial": [], "listening": False}


class ProgressLine:
    """The fit's progress on stderr.

    On a terminal, one line rewritten in place (carriage return), at most ten
    times a second; otherwise (a pipe, a log file) a plain line every few seconds,
    so logs stay short. With ``compile_seconds`` (a callable: seconds spent
    compiling so far in this fit), the first solver step is preceded by one
    permanent line saying how long compilation took (or that the compiled code
    came from the cache); with ``trial_seconds`` as well (seconds spent trying
    cache entries in a child process, :func:`trial_seconds`), that line says
    how long the trials took when there were any.
    """

    def __init__(self, stream, compile_seconds=None, trial_seconds=None):
        self._stream = stream
        self._compile_seconds = compile_seconds
        self._trial_seconds = trial_seconds
        self._tty = bool(getattr(stream, "isatty", lambda: False)())
        self._interval = 0.1 if self._tty else 5.0
        self._last = -np.inf
        self._width = 0

    def show(self, text: str) -> None:
        if self._tty:
            self._stream.write("\r" + text.ljust(self._width))
            self._width = len(text)
        else:
            self._stream.write(text + "\n")
        self._stream.flush()

    def __call__(self, iteration: int, loss: float, stage: str | None = None) -> None:
        """``progress(iteration, loss)`` as the estimator calls it; ``stage`` (e.g.
        ``"start 2/4"``) is shown when given."""
        if self._compile_seconds is not None:
            # Everything the first step needs is compiled once it has run.
            self.close()
            seconds = self._compile_seconds()
            tried = self._trial_seconds() if self._trial_seconds is not None else 0.0
            # A warm cache (invsss.runtime.executable_cache) leaves nothing to compile;
            # its first use here tries each entry in a child process, which the user
            # would otherwise see as an unexplained pause.
            line = (f"fit: compiling ... {seconds:.1f} s" if seconds >= 0.05
                    else "fit: compiled code loaded from the cache")
            if tried >= 0.05:
                line += f" (its first use here: tried in a separate process first, {tried:.1f} s)"
            self._stream.write(line + "\n")
            self._compile_seconds = self._trial_seconds = None
        now = time.monotonic()
        if now - self._last < self._interval:
            return
        self._last = now
        where = f"{stage}  " if stage else ""
        self.show(f"fit: {where}iter {iteration}  loss {loss:.3e}")

    def close(self) -> None:
        """Erase the in-place line, so what follows starts on a clean line."""
        if self._tty and self._width:
            self._stream.write("\r" + " " * self._width + "\r")
            self._stream.flush()
            self._width = 0


def compile_seconds() -> float:
    """Seconds of wall time during which this process was compiling (tracing,
    lowering, XLA; an executable loaded from the persistent cache counts its
    load), from ``jax.monitoring``; the listener is registered on the first call.

    A fit compiles its solver step on a second thread while the start scan's loss
    compiles, so the durations are not summed: each is an interval ending when
    its event arrives, and overlapping intervals count once.
    """
    _listen()
    return covered_seconds(_SPANS["compile"])


def trial_seconds() -> float:
    """Seconds of wall time during which the executable cache was trying entries in a
    child process (:data:`invsss.runtime.executable_entries.TRIAL_EVENT`), counted as
    :func:`compile_seconds` counts compiling; the listener is registered on the first call."""
    _listen()
    return covered_seconds(_SPANS["trial"])


def _listen() -> None:
    if _SPANS["listening"]:
        return
    from jax import monitoring

    from ..runtime.executable_entries import TRIAL_EVENT

    def listen(event: str, duration_secs: float, **_: str | int) -> None:
        kind = "compile" if event.startswith("/jax/core/compile/") else "trial" if event == TRIAL_EVENT else None
        if kind is not None:
            end = time.monotonic()
            _SPANS[kind].append((end - duration_secs, end))  # list.append is atomic

    monitoring.register_event_duration_secs_listener(listen)
    _SPANS["listening"] = True


def covered_seconds(spans) -> float:
    """The length of the union of ``(start, end)`` intervals.

    Examples
    --------
    >>> covered_seconds([(0.0, 2.0), (1.0, 3.0), (5.0, 6.0)])
    4.0
    """
    total, reached = 0.0, -np.inf
    for start, end in sorted(spans):
        if end > reached:
            total += end - max(start, reached)
            reached = end
    return total
