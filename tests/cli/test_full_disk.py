"""A full disk (0 bytes free): ``fit``, ``fit --overwrite`` and ``sweep`` end in one
line, leave no empty lock file behind, and the sweep resumes once there is room.

Two ways to a genuine "No space left on device": a small tmpfs filled to the last
byte (needs root and a kernel that lets this process mount; skipped, saying why,
where it cannot), and, everywhere, a lock file that is ``/dev/full``, whose
writes fail with ENOSPC. (tests/cli/test_sweep_store.py fills the results database
itself to SQLite's page limit: SQLITE_FULL.)
"""

from __future__ import annotations

import errno
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import invsss
from invsss.cli import main
from invsss.io.result_dir import ResultDir
from tests.io._pair_files import pair_args, write_pair

RENDER = """
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


def _pair(folder: Path) -> dict:
    rng = np.random.default_rng(1)
    arrays = (rng.uniform(0.2, 1, (16, 16, 3)), rng.uniform(0.2, 1, (16, 16)), np.full((16, 16), 500.0),
              np.ones((16, 16)))
    folder.mkdir(parents=True, exist_ok=True)
    return write_pair(folder, "p", arrays)


def _one_error_line(capsys) -> str:
    captured = capsys.readouterr()
    lines = [line for line in captured.err.strip().splitlines() if not line.startswith("sweep: ")]
    assert "Traceback" not in captured.err and len(lines) == 1, captured.err
    return lines[0]


# ------------------------------------------------------------------ everywhere: /dev/full

needs_dev_full = pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full on this system")


@needs_dev_full
def test_fit_whose_lock_cannot_be_written_is_one_line_and_leaves_no_lock(tmp_path, capsys):
    pair = _pair(tmp_path / "in")
    out = tmp_path / "run"
    out.mkdir()
    (out / ".invsss.lock").symlink_to("/dev/full")  # every write: ENOSPC
    assert main(["fit", *pair_args(pair), "--out", str(out)]) == 2
    assert _one_error_line(capsys) == f"invsss: error: {out}: cannot write to the output directory (No space left on device)"
    assert not os.path.lexists(out / ".invsss.lock")


@needs_dev_full
def test_sweep_whose_lock_cannot_be_written_is_one_line(tmp_path, capsys):
    _pair(tmp_path / "data" / "a")
    for role in ("source", "target", "depth"):
        os.replace(tmp_path / "data" / "a" / f"p_{role}.exr", tmp_path / "data" / "a" / f"{role}.exr")
    os.replace(tmp_path / "data" / "a" / "p_mask.png", tmp_path / "data" / "a" / "mask.png")
    (tmp_path / "e.toml").write_text(RENDER)
    out = tmp_path / "out"
    out.mkdir()
    (out / ".sweep.lock").symlink_to("/dev/full")
    assert main(["sweep", str(tmp_path / "e.toml"), "--out", str(out)]) == 2
    line = _one_error_line(capsys)
    assert line == (f"invsss: error: {out}: cannot write to the output folder (No space left on device); "
                    "free some space, then run the same command again to resume")
    assert not (out / "results.sqlite").exists()


# ------------------------------------------------------------------ a full tmpfs (root)


@pytest.fixture
def full_disk(tmp_path):
    """``(mount point, fill, free)``: a 2 MiB tmpfs; ``fill()`` takes its last byte, ``free()`` gives it back."""
    where = tmp_path / "disk"
    where.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(where)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip() or done.returncode}")
    filler = where / "filler"

    def fill():
        with open(filler, "ab", buffering=0) as file:
            try:
                while True:
                    file.write(b"\0" * 4096)
            except OSError as err:
                assert err.errno == errno.ENOSPC
        assert os.statvfs(where).f_bavail == 0

    yield where, fill, lambda: filler.unlink()
    subprocess.run(["umount", "-l", str(where)], capture_output=True)


def test_fit_on_a_full_disk_is_one_line_and_leaves_nothing(tmp_path, full_disk, capsys):
    disk, fill, _ = full_disk
    pair = _pair(tmp_path / "in")
    earlier = disk / "earlier"
    with ResultDir(earlier) as directory:  # a result to --overwrite
        directory.commit({"params.json": lambda path: Path(path).write_text('{"sss_level": 1.0}\n')})
    before = {p.name: p.read_bytes() for p in earlier.iterdir()}
    fill()
    new = disk / "new"
    assert main(["fit", *pair_args(pair), "--out", str(new)]) == 2
    assert _one_error_line(capsys) == f"invsss: error: {new}: cannot write to the output directory (No space left on device)"
    assert not new.exists()
    assert main(["fit", *pair_args(pair), "--out", str(earlier), "--overwrite"]) == 2
    assert _one_error_line(capsys) == (f"invsss: error: {earlier}: cannot write to the output directory "
                                       "(No space left on device)")
    assert {p.name: p.read_bytes() for p in earlier.iterdir()} == before  # no lock file, nothing changed


def test_sweep_on_a_full_disk_is_one_line_and_resumes_once_there_is_room(tmp_path, full_disk, capsys):
    disk, fill, free = full_disk
    data = tmp_path / "data" / "a"
    _pair(data)
    for name in os.listdir(data):
        os.replace(data / name, data / name.removeprefix("p_"))
    (tmp_path / "first.toml").write_text(RENDER)
    (tmp_path / "second.toml").write_text(RENDER.replace("[300, 600]", "[400, 500]"))
    out = disk / "out"
    assert main(["sweep", str(tmp_path / "first.toml"), "--out", str(out)]) == 0
    reference = tmp_path / "reference"
    assert main(["sweep", str(tmp_path / "second.toml"), "--out", str(reference)]) == 0
    capsys.readouterr()
    fill()
    assert main(["sweep", str(tmp_path / "second.toml"), "--out", str(out)]) == 2
    line = _one_error_line(capsys)
    assert line.startswith(f"invsss: error: {out}") and "free some space, then run the same command again" in line
    free()
    assert main(["sweep", str(tmp_path / "second.toml"), "--out", str(out)]) == 0
    rows = {row["id"]: row for row in invsss.sweeps.results(out, frame=False)}
    expected = {row["id"]: row for row in invsss.sweeps.results(reference, frame=False)}
    assert len(rows) == 8 and all(row["status"] == "done" for row in rows.values())
    for trial_id, row in expected.items():
        assert rows[trial_id]["loss"] == row["loss"] and rows[trial_id]["param.sss_level"] == row["param.sss_level"]
