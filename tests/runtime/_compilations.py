"""Counting XLA compilations of jitted functions by name, for tests that check
what a fit compiles (jax.monitoring events, from whichever thread compiles)."""

from __future__ import annotations

import threading

from jax import monitoring


class Compilations:
    """XLA compilations of the named jitted functions while the block runs, with
    the thread each ran on: ``with Compilations("_step") as seen: ...`` then
    ``seen.count("_step")``."""

    active = None

    def __init__(self, *names):
        self.names = {f"jit({name})" for name in names}
        self.seen: list[tuple[str, str]] = []

    def __enter__(self):
        Compilations.active = self
        return self

    def __exit__(self, *exc):
        Compilations.active = None

    def count(self, name=None) -> int:
        return sum(1 for fun, _ in self.seen if name is None or fun == f"jit({name})")

    @staticmethod
    def listen(event, duration, fun_name="", **_):
        counter = Compilations.active
        if counter is not None and event == "/jax/core/compile/backend_compile_duration" and fun_name in counter.names:
            counter.seen.append((fun_name, threading.current_thread().name))


monitoring.register_event_duration_secs_listener(Compilations.listen)
