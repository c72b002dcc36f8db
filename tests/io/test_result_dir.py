"""The output-directory protocol (invsss.io.result_dir): locks, overwrite, atomic commits.

The interruption tests run a real writer in a subprocess and kill it with a real
signal at several moments, then look at what is on disk.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from invsss.io.result_dir import MANIFEST_NAME, ResultDir, ResultDirBusy, ResultWriteError, result_state
from invsss.validation import InvalidInputError
from tests.io._earlier_fit import earlier_fit, listed


def _writer(text):
    def write(path):
        with open(path, "w") as f:
            f.write(text)

    return write


def _commit(path, files, **kwargs):
    with ResultDir(path, names=list(files), **kwargs) as rd:
        return rd.commit({name: _writer(text) for name, text in files.items()})


def _contents(path):
    return {
        name: open(os.path.join(path, name)).read()
        for name in sorted(os.listdir(path))
        if name != MANIFEST_NAME
    }


def test_commit_writes_all_files_and_a_complete_manifest(tmp_path):
    out = tmp_path / "run"
    written = _commit(out, {"params.json": "{}", "fit.exr": "pixels"})
    assert sorted(os.path.basename(p) for p in written) == ["fit.exr", "params.json"]
    assert _contents(out) == {"fit.exr": "pixels", "params.json": "{}"}
    manifest = json.loads((out / MANIFEST_NAME).read_text())
    assert manifest["state"] == "complete" and manifest["files"] == ["params.json", "fit.exr"]
    assert result_state(out) == "complete"


def test_a_directory_holding_a_result_is_refused_without_overwrite(tmp_path):
    out = tmp_path / "run"
    _commit(out, {"params.json": "first"})
    before = {p: (out / p).read_bytes() for p in os.listdir(out)}
    with pytest.raises(InvalidInputError, match="--overwrite"):
        ResultDir(out, names=["params.json"]).open()
    assert {p: (out / p).read_bytes() for p in os.listdir(out)} == before


def test_a_legacy_result_without_manifest_is_refused_too(tmp_path):
    (tmp_path / "params.json").write_text("{}")
    with pytest.raises(InvalidInputError, match="already holds a result"):
        ResultDir(tmp_path).open()
    assert result_state(tmp_path) == "legacy"


def test_overwrite_removes_the_old_result_and_keeps_the_users_files(tmp_path):
    out = tmp_path / "run"
    _commit(out, {"params.json": "old", "fit_0.exr": "a", "fit_1.exr": "b", "report.png": "r"})
    (out / "notes.txt").write_text("mine")
    _commit(out, {"params.json": "new", "fit.exr": "c", "report.png": "r2"}, overwrite=True)
    assert _contents(out) == {"fit.exr": "c", "notes.txt": "mine", "params.json": "new", "report.png": "r2"}


def test_overwrite_of_a_legacy_result_removes_its_stale_fit_images(tmp_path):
    for name in ("params.json", "fit_0.exr", "fit_1.exr", "report.png"):
        (tmp_path / name).write_text("old")
    _commit(tmp_path, {"params.json": "new", "fit.exr": "x", "report.png": "y"}, overwrite=True)
    assert _contents(tmp_path) == {"fit.exr": "x", "params.json": "new", "report.png": "y"}


def test_an_empty_existing_directory_is_used_without_overwrite(tmp_path):
    _commit(tmp_path, {"params.json": "x"})
    assert result_state(tmp_path) == "complete"


def test_a_result_name_taken_by_a_directory_is_refused_before_any_work(tmp_path):
    (tmp_path / "params.json").mkdir()
    with pytest.raises(InvalidInputError, match="params.json: is in the way"):
        ResultDir(tmp_path, names=["params.json"], overwrite=True).open()


def test_a_file_where_the_directory_should_be_is_refused(tmp_path):
    (tmp_path / "out").write_text("")
    with pytest.raises(InvalidInputError, match="a file of that name exists"):
        ResultDir(tmp_path / "out").open()


def test_a_directory_it_created_is_removed_when_nothing_was_committed(tmp_path):
    out = tmp_path / "a" / "run"
    with pytest.raises(RuntimeError):
        with ResultDir(out):
            raise RuntimeError("the work failed")
    assert not out.exists()


def test_an_existing_directory_is_kept_when_nothing_was_committed(tmp_path):
    with ResultDir(tmp_path):
        pass
    assert tmp_path.is_dir() and os.listdir(tmp_path) == []


def test_a_failing_writer_leaves_the_previous_result_untouched(tmp_path):
    _commit(tmp_path, {"params.json": "old"})
    before = {p: (tmp_path / p).read_bytes() for p in os.listdir(tmp_path)}

    def fail(path):
        raise OSError(28, "No space left on device", path)

    with ResultDir(tmp_path, overwrite=True) as rd:
        with pytest.raises(ResultWriteError, match="fit.exr: No space left on device"):
            rd.commit({"params.json": _writer("new"), "fit.exr": fail})
    assert {p: (tmp_path / p).read_bytes() for p in os.listdir(tmp_path)} == before


def test_bad_file_names_are_rejected(tmp_path):
    with ResultDir(tmp_path) as rd:
        for name in ("../escape.txt", MANIFEST_NAME):
            with pytest.raises(ValueError, match="plain file name"):
                rd.commit({name: _writer("x")})


# ---------------------------------------------------------------- other processes

_HOLDER = textwrap.dedent(
    """
    import sys, time
    from invsss.io.result_dir import ResultDir
    out, mode = sys.argv[1], sys.argv[2]
    files = {"params.json": "new", "fit.exr": "new pixels", "report.png": "new report"}
    def write(text):
        return lambda path: open(path, "w").write(text)
    with ResultDir(out, overwrite=True, names=list(files), description="test holder") as rd:
        print("locked", flush=True)
        if mode == "hold":
            time.sleep(60)
        rd.commit({name: write(text) for name, text in files.items()})
    print("done", flush=True)
    """
)


def _start_holder(out, mode, env=None):
    proc = subprocess.Popen(
        [sys.executable, "-c", _HOLDER, str(out), mode],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, **(env or {})},
    )
    assert proc.stdout.readline().strip() == "locked"
    return proc


def test_a_second_run_is_refused_while_the_first_holds_the_directory(tmp_path):
    holder = _start_holder(tmp_path / "run", "hold")
    try:
        start = time.monotonic()
        with pytest.raises(ResultDirBusy, match=rf"in use by another invsss run \(pid {holder.pid} .*test holder"):
            ResultDir(tmp_path / "run", overwrite=True).open()
        assert time.monotonic() - start < 5  # refused at once, not after waiting
    finally:
        holder.kill()
        holder.wait()
    # The kernel released the lock with the process: the directory is usable again.
    with ResultDir(tmp_path / "run", overwrite=True):
        pass


def _wait_for_pause(proc):
    for line in proc.stderr:
        if "pausing in the write phase" in line:
            return
    raise AssertionError("the writer never reached the write phase")


@pytest.mark.parametrize("pauses", [1, 2])
def test_sigkill_inside_the_commit_leaves_a_result_marked_incomplete(tmp_path, pauses):
    out = tmp_path / "run"
    _commit(out, {"params.json": "old", "fit.exr": "old pixels", "report.png": "old report"})
    # Sleep only at the pause where the signal is sent.
    pause = "60" if pauses == 1 else "0,60"
    writer = _start_holder(out, "commit", env={"INVSSS_TEST_PAUSE_IN_COMMIT": pause})
    for _ in range(pauses):  # 1: marked incomplete; 2: after the first file moved in
        _wait_for_pause(writer)
    writer.send_signal(signal.SIGKILL)
    writer.wait()
    assert result_state(out) == "incomplete"
    if pauses == 2:
        assert (out / "params.json").read_text() == "new"
    # A later run needs --overwrite, and then cleans up completely.
    with pytest.raises(InvalidInputError, match="an incomplete result"):
        ResultDir(out).open()
    _commit(out, {"params.json": "third"}, overwrite=True)
    assert _contents(out) == {"params.json": "third"}
    assert result_state(out) == "complete"


def test_sigkill_before_the_commit_leaves_the_previous_result_byte_identical(tmp_path):
    out = tmp_path / "run"
    _commit(out, {"params.json": "old", "fit.exr": "old pixels"})
    before = {p: (out / p).read_bytes() for p in os.listdir(out)}
    holder = _start_holder(out, "hold")
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    after = {p: (out / p).read_bytes() for p in os.listdir(out) if p != ".invsss.lock"}
    assert after == before
    assert result_state(out) == "complete"


def test_result_dir_keeps_an_input_among_the_results_files_and_refuses_the_users(tmp_path):
    """The protocol itself (invsss.io.result_dir), for every writer of results."""
    out = tmp_path / "run"
    earlier_fit(out, ("params.json", "fit_0.exr", "fit_1.exr"))
    (out / "notes.txt").write_text("mine")
    # An input among the earlier result's files stays, through any path to it (a link here).
    link = tmp_path / "link.exr"
    link.symlink_to(out / "fit_1.exr")
    with ResultDir(out, overwrite=True, names=["params.json", "fit.exr"], inputs=[("--target", link)]) as folder:
        assert folder.kept == ["fit_1.exr"]
        folder.commit({"params.json": lambda p: Path(p).write_text("new"),
                       "fit.exr": lambda p: Path(p).write_text("new fit")})
    assert sorted(os.listdir(out)) == sorted([MANIFEST_NAME, "fit.exr", "fit_1.exr", "notes.txt", "params.json"])
    assert (out / "fit_1.exr").read_text() == "earlier fit_1.exr" and listed(out) == ["params.json", "fit.exr"]
    # The user's file at a name the run writes: refused when opened, declared or not.
    with pytest.raises(InvalidInputError, match="notes.txt: not a file of an earlier invsss result"):
        ResultDir(out, overwrite=True, names=["notes.txt"]).open()
    with ResultDir(out, overwrite=True) as folder:
        with pytest.raises(ResultWriteError, match="notes.txt: not a file of an earlier invsss result"):
            folder.commit({"params.json": lambda p: Path(p).write_text("newer"),
                           "notes.txt": lambda p: Path(p).write_text("lost")})
    assert (out / "notes.txt").read_text() == "mine" and (out / "params.json").read_text() == "new"
