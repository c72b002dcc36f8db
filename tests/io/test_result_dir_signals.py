"""A signal that ends the command at once leaves no output directory behind.

The command line ends with ``os._exit`` on a second Ctrl-C, and on a Ctrl-C whose
``Interrupted`` is raised where Python cannot propagate it (JAX's garbage-collection
callback, while the fit reads its inputs). ``os._exit`` runs no ``finally``: before the
quit cleanups, a folder the run had created stayed behind holding only its lock file,
under a message that said nothing was written (seen in CI, the Ctrl-C test of
tests/cli/test_photo_inputs_kept.py). Each test here reaches one of those ways out
deterministically, in a child process, and looks at the disk afterwards.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from invsss.io.result_dir import result_state
from tests import ROOT

OPEN_THEN = textwrap.dedent("""
    import os, signal, sys, time
    from invsss.io.result_dir import ResultDir
    from invsss.runtime.interrupts import StopSignals

    class Dropped:
        def __del__(self):  # a finaliser, as JAX's gc callback is: an exception here is unraisable
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.5)  # the handler runs here and raises Interrupted

    with StopSignals() as stop, ResultDir(sys.argv[1], names=["params.json"]) as out:
        if sys.argv[3] == "committed":
            out.commit({"params.json": lambda path: open(path, "w").write("{}")})
        if sys.argv[2] == "unraisable":
            Dropped()  # freed at once (no reference is kept), which runs __del__
        else:  # a second signal while the fit runs: quit without saving
            with stop.deferred():
                os.kill(os.getpid(), signal.SIGINT)
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.5)
        print("carried on", flush=True)
""")


def _quit_inside(out, how, when="before the commit"):
    done = subprocess.run([sys.executable, "-c", OPEN_THEN, str(out), how, when.split()[0]], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 130 and "carried on" not in done.stdout, done
    return done


@pytest.mark.parametrize("how", ["unraisable", "second signal"])
def test_a_folder_the_run_made_is_gone_after_a_signal_that_quits_at_once(tmp_path, how):
    out = tmp_path / "made" / "run"
    _quit_inside(out, how)
    assert not out.exists(), os.listdir(out)
    assert os.listdir(tmp_path / "made") == []  # the parent makedirs made is left, empty


@pytest.mark.parametrize("how", ["unraisable", "second signal"])
def test_a_folder_of_the_users_keeps_its_files_and_loses_the_lock(tmp_path, how):
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    _quit_inside(out, how)
    assert sorted(os.listdir(out)) == ["notes.txt"]
    assert (out / "notes.txt").read_text() == "mine"


@pytest.mark.parametrize("how", ["unraisable", "second signal"])
def test_a_result_committed_before_the_signal_stays_whole(tmp_path, how):
    """The cleanup releases the lock of a committed result and removes nothing of it."""
    out = tmp_path / "run"
    _quit_inside(out, how, "committed")
    assert sorted(os.listdir(out)) == ["invsss-manifest.json", "params.json"]
    assert result_state(out) == "complete"
