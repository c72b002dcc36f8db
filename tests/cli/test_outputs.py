"""`invsss fit` after the door: output directories, signals and write failures.

Each test runs the real command in a subprocess (or in-process where no signal is
involved) and asserts on what is on disk afterwards. The long-running fits use
the bundled `data_synthetic/fran_front` pair, big enough that a fit is still
running when the test sends its signal.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import jax
import numpy as np
import pytest

import invsss
from invsss.cli import main
from invsss.io.result_dir import MANIFEST_NAME, ResultDir, result_state
from tests.io._pair_files import pair_args
from tests import ROOT

FRAN = ROOT / "data_synthetic" / "fran_front"
SIZE = 32
FAST = ["--starts", "1", "--max-steps", "8", "--fix", "maxdd=0.7"]


FRAN_ARGS = pair_args({k: FRAN / f"{k}.{'png' if k == 'mask' else 'exr'}" for k in ("source", "target", "depth", "mask")})


@pytest.fixture(scope="module")
def small_pair(tmp_path_factory):
    """A 32x32 pair rendered with known parameters: a fit takes seconds."""
    folder = tmp_path_factory.mktemp("small_pair")
    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:SIZE, 0:SIZE].astype(np.float64)
    depth = 500.0 + 3.0 * np.sin(x / 3.0) + 2.0 * np.cos(y / 4.0)
    mask = np.zeros((SIZE, SIZE))
    mask[4:-4, 4:-4] = 1.0
    source = rng.uniform(0.2, 1.0, (SIZE, SIZE))
    truth = invsss.SSSParams(700.0, 100.0, 0.7, [0.3, 0.7], [0.5, 2.0])
    with jax.enable_x64(True):
        target = np.asarray(invsss.render(source, depth, mask, truth))
    paths = {}
    for key, array in (("source", source), ("target", target), ("depth", depth), ("mask", mask)):
        paths[key] = folder / f"{key}.exr"
        invsss.write_image(paths[key], np.asarray(array, np.float32))
    profile = folder / "profile.json"
    profile.write_text(json.dumps({"weights": [0.5, 0.5], "variances": [0.5, 2.0]}))
    return [*pair_args(paths), "--profile", str(profile), *FAST]


def _snapshot(folder):
    return {p.name: p.read_bytes() for p in sorted(Path(folder).iterdir())}


def _one_error_line(capsys, code):
    err = capsys.readouterr().err.strip()
    assert code == 2 and "Traceback" not in err
    lines = [line for line in err.splitlines() if line.startswith("invsss: error:")]
    assert len(lines) == 1, err
    return lines[0]


def _fake_result(folder):
    with ResultDir(folder, names=["params.json"]) as rd:
        rd.commit({"params.json": lambda p: Path(p).write_text('{"sss_level": 1}')})


def _start(args, env=None, **kwargs):
    return subprocess.Popen(
        [sys.executable, "-m", "invsss", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env={**os.environ, **(env or {})},
        **kwargs,
    )


def _wait_for(proc, text, seen):
    """Read stderr lines until one contains ``text``; keep them all in ``seen``."""
    for line in proc.stderr:
        seen.append(line)
        if text in line:
            return
    raise AssertionError(f"{text!r} never appeared; stderr was:\n{''.join(seen)}")


def _finish(proc, seen, timeout=300):
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, "".join(seen) + err


# ------------------------------------------------------------- output directories


def test_a_rerun_into_a_finished_result_is_refused_and_leaves_it_untouched(small_pair, tmp_path, capsys):
    out = tmp_path / "run"
    _fake_result(out)
    before = _snapshot(out)
    start = time.monotonic()
    code = main(["fit", *small_pair, "--out", str(out)])
    line = _one_error_line(capsys, code)
    assert "already holds a result" in line and "--overwrite" in line
    assert time.monotonic() - start < 10  # before reading or fitting anything
    assert _snapshot(out) == before


@pytest.mark.slow
def test_overwrite_replaces_the_result_and_its_stale_files_but_keeps_the_users(small_pair, tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    for name in ("params.json", "fit_0.exr", "fit_1.exr", "report.png"):  # an older multi-pair fit
        (out / name).write_text("old")
    (out / "notes.txt").write_text("mine")
    assert main(["fit", *small_pair, "--out", str(out), "--overwrite"]) == 0
    assert sorted(os.listdir(out)) == ["fit.exr", MANIFEST_NAME, "notes.txt", "params.json", "report.png"]
    params = json.loads((out / "params.json").read_text())
    assert params["interrupted"] is False and params["sss_level"] > 0
    assert result_state(out) == "complete"


@pytest.mark.slow
def test_a_fit_starts_no_daemon_threads(small_pair, tmp_path, capsys):
    # A daemon thread still inside compiled code when the interpreter shuts down
    # (a fit interrupted at once) can abort the process in C++: CI once saw exit
    # status -6 instead of 130. Every thread the fit starts must be joinable.
    started = []

    def record(frame, event, arg):
        sys.setprofile(None)  # runs first thing in each new thread; one call is enough
        started.append(threading.current_thread())

    threading.setprofile(record)
    try:
        code = main(["fit", *small_pair, "--out", str(tmp_path / "run")])
    finally:
        threading.setprofile(None)
    assert code == 0, capsys.readouterr().err
    names = {thread.name for thread in started}
    assert "invsss-import-report" in names and "invsss-compile-solver" in names, names
    assert [thread.name for thread in started if thread.daemon] == []


def test_an_input_error_leaves_no_output_directory(small_pair, tmp_path, capsys):
    args = list(small_pair)
    args[args.index("--target") + 1] = str(tmp_path / "missing.exr")
    out = tmp_path / "run"
    code = main(["fit", *args, "--out", str(out)])
    assert "missing.exr" in _one_error_line(capsys, code)
    assert not out.exists()


def test_a_result_name_taken_by_a_directory_is_refused_before_the_fit(small_pair, tmp_path, capsys):
    (tmp_path / "params.json").mkdir()
    code = main(["fit", *small_pair, "--out", str(tmp_path)])
    assert "params.json: is in the way" in _one_error_line(capsys, code)


@pytest.mark.slow
def test_a_second_fit_into_a_busy_directory_is_refused_while_the_first_finishes(small_pair, tmp_path):
    out = tmp_path / "run"
    first = _start(["fit", *small_pair, "--out", str(out)])
    seen = []
    _wait_for(first, "searching starting points", seen)
    # Paused while it holds the directory: with a warm compilation cache the whole
    # fit can end before a second interpreter has even started.
    first.send_signal(signal.SIGSTOP)
    try:
        second = subprocess.run(
            [sys.executable, "-m", "invsss", "fit", *small_pair, "--out", str(out)],
            capture_output=True, text=True, cwd=ROOT, timeout=300,
        )
    finally:
        first.send_signal(signal.SIGCONT)
    assert second.returncode == 2
    assert f"in use by another invsss run (pid {first.pid}" in second.stderr
    assert "Traceback" not in second.stderr
    code, _, err = _finish(first, seen)
    assert code == 0, err
    assert result_state(out) == "complete"


# ------------------------------------------------------------------------ signals


@pytest.mark.slow
@pytest.mark.parametrize("sig, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_during_the_fit_saves_the_best_estimate_and_exits_cleanly(tmp_path, sig, status):
    out = tmp_path / "run"
    proc = _start(["fit", *FRAN_ARGS, "--out", str(out)])
    seen = []
    _wait_for(proc, " iter ", seen)  # at least one solver step has finished
    proc.send_signal(sig)
    code, _, err = _finish(proc, seen)
    assert code == status, err
    assert "Traceback" not in err
    assert "interrupted after" in err
    params = json.loads((out / "params.json").read_text())
    assert params["interrupted"] is True and params["converged"] is False
    assert params["sss_level"] is None or params["sss_level"] > 0
    assert result_state(out) == "complete"
    # The saved estimate is usable: render takes it.
    rendered = tmp_path / "r.exr"
    assert main(["render", "--image", str(FRAN / "source.exr"), "--depth", str(FRAN / "depth.exr"),
                 "--mask", str(FRAN / "mask.png"), "--params", str(out / "params.json"),
                 "--out", str(rendered)]) == 0


@pytest.mark.slow
def test_a_signal_before_any_solver_step_leaves_nothing_behind(small_pair, tmp_path):
    out = tmp_path / "run"
    proc = _start(["fit", *small_pair, "--out", str(out)])
    seen = []
    _wait_for(proc, "searching starting points", seen)
    proc.send_signal(signal.SIGINT)
    code, _, err = _finish(proc, seen)
    assert code == 130, err
    assert "Traceback" not in err
    if "nothing written" in err:
        assert not out.exists()
    else:  # the first step finished before the signal was seen: then it was saved
        assert json.loads((out / "params.json").read_text())["interrupted"] is True


@pytest.mark.slow
def test_sigkill_in_the_write_phase_leaves_a_result_that_render_refuses(small_pair, tmp_path, capsys):
    out = tmp_path / "run"
    _fake_result(out)
    proc = _start(["fit", *small_pair, "--out", str(out), "--overwrite"],
                  env={"INVSSS_TEST_PAUSE_IN_COMMIT": "0,60"})
    seen = []
    _wait_for(proc, "pausing in the write phase", seen)  # marked incomplete, old files going
    _wait_for(proc, "pausing in the write phase", seen)  # the new params.json is in place
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert result_state(out) == "incomplete"
    code = main(["render", "--image", str(tmp_path / "x.exr"), "--depth", str(tmp_path / "x.exr"),
                 "--mask", str(tmp_path / "x.exr"), "--params", str(out / "params.json"),
                 "--out", str(tmp_path / "r.exr")])
    assert "incomplete" in _one_error_line(capsys, code)


# ----------------------------------------------------------------- write failures


# `python -m invsss` in a process that cannot write files larger than 64 KiB (as on
# a full disk): params.json fits, fit.exr does not. Python ignores SIGXFSZ, so
# writes fail with EFBIG. Set in the child itself: a preexec_fn would fork a
# multithreaded (JAX) process.
_SMALL_FILES_ONLY = (
    "import resource, runpy, sys; "
    "resource.setrlimit(resource.RLIMIT_FSIZE, (64 * 1024, 64 * 1024)); "
    "sys.argv[0] = 'invsss'; runpy.run_module('invsss', run_name='__main__')"
)


@pytest.mark.slow
def test_a_write_failure_after_the_fit_keeps_the_estimate(small_pair, tmp_path):
    out = tmp_path / "run"
    env = {"TMPDIR": str(tmp_path)}
    result = subprocess.run(
        [sys.executable, "-c", _SMALL_FILES_ONLY, "fit", *small_pair, "--out", str(out)],
        capture_output=True, text=True, cwd=ROOT, env={**os.environ, **env}, timeout=300,
    )
    assert result.returncode == 1, result.stderr
    assert "Traceback" not in result.stderr
    error = [line for line in result.stderr.splitlines() if line.startswith("invsss: error:")]
    assert len(error) == 1 and "cannot write the result" in error[0]
    saved = Path(error[0].rsplit("saved to ", 1)[1])
    assert saved.parent == tmp_path
    params = json.loads(saved.read_text())
    assert params["sss_level"] > 0 and params["converged"] in (True, False)
    assert not out.exists()  # created for this run, nothing committed: removed again
