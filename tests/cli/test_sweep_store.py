"""A sweep's results database when it goes wrong, from the command line: damaged or
emptied (one line naming the file and what to do, never a traceback nor a silent
rerun), rebuilt from the trial folders (the same rows), and full (one line; the same
command resumes once there is room)."""

from __future__ import annotations

import shutil
import sqlite3

import numpy as np
import pytest

import invsss
from invsss.cli import main
from invsss.sweeps.store import DATABASE_NAME, ResultsStore

RENDER = """
name = "matrix"
task = "render"
[data]
pairs = ["data/a/"]
[base]
maxdd = 0.5
profile = {weights = [0.5, 0.5], variances = [0.5, 2.0]}
[grid]
sss_level = [300, 600]
correction = [0, 800]
"""


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """A finished four-trial render sweep, its experiment file and its rows."""
    root = tmp_path_factory.mktemp("store")
    folder = root / "data" / "a"
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    for name, image in [("source.exr", rng.uniform(0.2, 1, (16, 16, 3))), ("target.exr", rng.uniform(0.2, 1, (16, 16))),
                        ("depth.exr", np.full((16, 16), 500.0)), ("mask.png", np.ones((16, 16)))]:
        invsss.write_image(folder / name, image.astype(np.float32))
    experiment = root / "e.toml"
    experiment.write_text(RENDER)
    out = root / "out"
    assert main(["sweep", str(experiment), "--out", str(out)]) == 0
    return root, experiment, out, _stored_rows(out)


def _stored_rows(out) -> list[dict]:
    with ResultsStore(out, readonly=True) as store:
        return store.rows()


def _copy(swept, tmp_path):
    root, experiment, out, rows = swept
    copy = tmp_path / "out"
    shutil.copytree(out, copy)
    return experiment, copy, rows


def _trial_files(out) -> dict:
    """Every file under the trial folders with its modification time (a rerun changes them)."""
    return {str(p.relative_to(out)): p.stat().st_mtime_ns for p in (out / "trials").rglob("*") if p.is_file()}


def _damage(path, how: str) -> None:
    data = path.read_bytes()
    assert len(data) >= 3 * 4096, len(data)  # pages to damage
    if how == "truncated":
        path.write_bytes(data[: len(data) // 2 + 100])
    elif how == "overwritten":
        path.write_bytes(b"these are not the results you are looking for\n" * 200)
    elif how == "garbage in the middle":
        middle = len(data) // 4096 // 2 * 4096
        path.write_bytes(data[:middle] + bytes(range(256)) * 16 + data[middle + 4096:])
    elif how == "0 bytes":
        path.write_bytes(b"")
    elif how == "missing":
        path.unlink()


def _one_error_line(capsys) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert "Traceback" not in captured.err and len(lines) == 1, captured.err
    return lines[0]


@pytest.mark.parametrize("how", ["truncated", "overwritten", "garbage in the middle", "0 bytes", "missing"])
def test_a_damaged_store_is_one_line_and_the_rebuilt_one_has_the_same_rows(swept, tmp_path, capsys, how):
    experiment, out, rows = _copy(swept, tmp_path)
    database = out / DATABASE_NAME
    _damage(database, how)
    before = _trial_files(out)
    capsys.readouterr()

    assert main(["sweep", str(experiment), "--out", str(out)]) == 2
    line = _one_error_line(capsys)
    assert line.startswith(f"invsss: error: {database}: ")
    assert f"--out {out} --rebuild-store" in line
    assert _trial_files(out) == before  # nothing was run again

    if how != "missing":  # (then sweep-report finds no sweep here, as before)
        assert main(["sweep-report", str(out), "--no-plots"]) == 2
        line = _one_error_line(capsys)
        assert line.startswith(f"invsss: error: {database}: ") and "--rebuild-store" in line

    assert main(["sweep", str(experiment), "--out", str(out), "--rebuild-store"]) == 0
    captured = capsys.readouterr()
    assert "rebuilt" in captured.err and "4 done, 0 failed, 0 not run (0 run now" in captured.out + captured.err
    assert _trial_files(out) == before
    assert _stored_rows(out) == rows  # every column of every row
    if how != "missing":
        kept = [p.name for p in out.iterdir() if p.name.startswith(f"{DATABASE_NAME}.damaged-")]
        assert kept, "the damaged file is kept"
    assert main(["sweep-report", str(out), "--no-plots"]) == 0


def test_a_store_filled_to_its_limit_is_one_line_and_the_sweep_resumes(swept, tmp_path, capsys, monkeypatch):
    # SQLite's own "database or disk is full" (SQLITE_FULL), as on a full disk:
    # the database may not grow past the pages the first trials need.
    root = swept[0]
    experiment = root / "sixteen.toml"  # rows enough to need pages beyond the schema's
    experiment.write_text(RENDER.replace("[300, 600]", "[300, 450, 600, 750]").replace("[0, 800]", "[0, 300, 500, 800]"))
    reference = tmp_path / "reference"
    assert main(["sweep", str(experiment), "--out", str(reference)]) == 0
    rows = _stored_rows(reference)
    out = tmp_path / "out"
    with sqlite3.connect(reference / DATABASE_NAME) as finished:  # the pages a whole sweep takes
        pages = finished.execute("PRAGMA page_count").fetchone()[0]
    monkeypatch.setenv("INVSSS_TEST_MAX_DB_PAGES", str(pages - 2))
    capsys.readouterr()
    assert main(["sweep", str(experiment), "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    errors = [line for line in captured.err.splitlines() if line.startswith("invsss: error:")]
    assert errors == [f"invsss: error: {out / DATABASE_NAME}: cannot write (database or disk is full); "
                      "free some space, then run the same command again to resume"]
    monkeypatch.delenv("INVSSS_TEST_MAX_DB_PAGES")
    assert main(["sweep", str(experiment), "--out", str(out)]) == 0
    resumed = {row["id"]: row for row in _stored_rows(out)}
    assert all(row["status"] == "done" for row in resumed.values()) and len(resumed) == len(rows)
    for row in rows:  # the same renders as an uninterrupted sweep
        assert resumed[row["id"]]["metrics"] == row["metrics"] and resumed[row["id"]]["params"] == row["params"]
