"""A signal whose Interrupted is raised where Python cannot propagate it (a garbage-collection
callback such as JAX's, a __del__) ends the command in one line with 128 + signal, instead
of Python's "Exception ignored in ..." traceback and carrying on (issue 47: Ctrl-C at any
moment; seen in CI with JAX's _xla_gc_callback)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

from tests import ROOT

CHILD = textwrap.dedent("""
    import gc, os, signal, sys, time
    from invsss.runtime.interrupts import StopSignals

    class Collected:
        def __del__(self):  # runs inside the collector: an exception here is unraisable
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.5)  # the handler runs here and raises Interrupted

    with StopSignals() as stop:
        Collected()
        gc.collect()
        print("carried on", flush=True)
""")


def _run(code):
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)


def test_an_unraisable_interrupt_ends_the_command_in_one_line():
    done = _run(CHILD)
    assert done.returncode == 130, done
    assert done.stderr.strip() == "invsss: interrupted (SIGINT); nothing written", done.stderr
    assert "carried on" not in done.stdout


OTHER = textwrap.dedent("""
    import gc
    from invsss.runtime.interrupts import StopSignals

    class Collected:
        def __del__(self):
            raise ValueError("not a signal")

    with StopSignals() as stop:
        Collected()
        gc.collect()
        print("carried on", flush=True)
""")


def test_other_unraisable_exceptions_still_reach_pythons_hook():
    done = _run(OTHER)
    assert done.returncode == 0 and "carried on" in done.stdout
    assert "ValueError: not a signal" in done.stderr


CLEANUPS = textwrap.dedent("""
    import os, signal, time
    from invsss.runtime.interrupts import StopSignals, add_quit_cleanup, remove_quit_cleanup

    def failing():
        raise OSError("a cleanup that fails")

    def forgotten():
        print("forgotten ran", flush=True)

    add_quit_cleanup(lambda: print("first added", flush=True))
    add_quit_cleanup(failing)
    add_quit_cleanup(forgotten)
    add_quit_cleanup(lambda: print("last added", flush=True))
    remove_quit_cleanup(forgotten)
    with StopSignals() as stop, stop.deferred():
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGINT)  # the second: quit at once
        time.sleep(0.5)
    print("carried on", flush=True)
""")


def test_a_quit_runs_the_cleanups_last_added_first_past_one_that_fails():
    done = _run(CLEANUPS)
    assert done.returncode == 130, done
    assert done.stdout.splitlines() == ["last added", "first added"], done
