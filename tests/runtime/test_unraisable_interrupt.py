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
