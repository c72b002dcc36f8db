"""``invsss sweep`` from the command line: a bad experiment file is one line and
status 2, a sweep killed mid-run (SIGKILL) or stopped by Ctrl-C resumes to one done
row per trial, a failing trial is recorded while the sweep goes on, and ``--report``
writes the table, CSV, plots and Parquet."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time

import numpy as np
import pytest

import invsss
import invsss.sweeps as ex
from invsss.io.result_dir import result_state
from invsss.sweeps.runner import trial_folder
from tests.sweeps._sweep_files import RENDER, check_artefacts_match, experiment_file, rows_by_id, write_small_pair
from tests.sweeps._sweep_files import root  # noqa: F401 (fixture)


def test_bad_file_on_the_command_line_is_one_line_and_status_2(root, capsys):
    path = experiment_file(root, "bad_cli.toml", 'task = "render"\n[dta]\n')
    assert invsss.cli.main(["sweep", str(path), "--out", str(root / "never")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "did you mean 'data'?" in err
    assert not os.path.exists(root / "never")


def _done_count(database):
    try:
        with sqlite3.connect(f"file:{database}?mode=ro", uri=True, timeout=5) as db:
            return db.execute("SELECT COUNT(*) FROM trials WHERE status = 'done'").fetchone()[0]
    except sqlite3.OperationalError:
        return 0


def _sweep_until(path, out, done, stdout):
    """``invsss sweep`` in a subprocess, returned once ``done`` trials are done.

    The result protocol's test hook pauses inside every commit, so a signal
    sent next lands while trials are being written.
    """
    env = {**os.environ, "INVSSS_TEST_PAUSE_IN_COMMIT": "0.4"}
    process = subprocess.Popen(
        [sys.executable, "-m", "invsss", "sweep", str(path), "--out", str(out)],
        env=env, stdout=stdout, stderr=subprocess.PIPE, text=True,
    )
    deadline = time.monotonic() + 120
    while _done_count(out / "results.sqlite") < done and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.1)
    return process


@pytest.mark.slow
def test_ctrl_c_stops_between_trials_and_a_rerun_resumes(root):
    path = experiment_file(root, "sigint.toml", RENDER)
    out = root / "sigint"
    process = _sweep_until(path, out, 2, subprocess.PIPE)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130
    assert "run the same command again to resume" in err and "Traceback" not in err
    rows = rows_by_id(out)
    statuses = [r["status"] for r in rows.values()]
    assert 2 <= statuses.count("done") < 12 and set(statuses) == {"done", "pending"}
    check_artefacts_match(str(out), rows)
    assert invsss.cli.main(["sweep", str(path), "--out", str(out)]) == 0
    assert all(r["status"] == "done" for r in rows_by_id(out).values())


def test_a_failing_trial_is_recorded_and_the_sweep_goes_on(root, capsys):
    # Pair "broken": its target has another size than its source: loading fails.
    broken = root / "broken"
    write_small_pair(broken, 7, size=20)
    os.replace(broken / "target.exr", broken / "small_target.exr")
    invsss.write_image(broken / "target.exr", np.ones((18, 18), np.float32))
    text = RENDER.replace('pairs = ["data/*/"]', 'pairs = ["data/a/", "broken/"]')
    path = experiment_file(root, "failing.toml", text)
    out = root / "failing"
    assert invsss.cli.main(["sweep", str(path), "--out", str(out)]) == 1  # some trials failed
    err = capsys.readouterr().err
    assert "4 failed" in err and "FAILED" in err
    rows = rows_by_id(out)
    failed = [r for r in rows.values() if r["status"] == "failed"]
    assert len(rows) == 8 and len(failed) == 4
    assert all(r["pair"] == "broken" for r in failed)
    for row in failed:
        assert "target.exr" in row["error"] and "\n" not in row["error"]
        assert row["psnr"] is None
    check_artefacts_match(str(out), rows)


def test_sweep_report_table_csv_and_plots(root, capsys):
    import csv

    path = experiment_file(root, "report.toml", RENDER.replace('"data/*/"', '"data/a/"'))
    out = root / "report_out"
    ex.run(path, out, log=None)
    assert invsss.cli.main(["sweep-report", str(out)]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split()[:5] == ["id", "status", "sss_level", "correction", "pair"]
    rows = rows_by_id(out)
    with open(out / "report" / "results.csv", newline="") as f:
        written = {r["id"]: r for r in csv.DictReader(f)}
    assert set(written) == set(rows) and len(rows) == 4
    for trial_id, row in rows.items():
        assert float(written[trial_id]["psnr"]) == pytest.approx(row["psnr"], rel=1e-12)
        assert json.loads(written[trial_id]["param.weights"]) == row["param.weights"]
        assert any(line.startswith(trial_id) and " done " in line for line in table)
    for name in ("metrics_vs_sss_level.png", "metrics_vs_correction.png", "contact_a.png"):
        assert os.path.getsize(out / "report" / name) > 1000
    # The render at the parameters the pair was made with scores best.
    best = max(rows.values(), key=lambda r: r["psnr"])
    assert (best["sss_level"], best["correction"]) == (600, 800)


def test_sweep_report_parquet_holds_the_results(root, capsys):
    pandas = pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    path = experiment_file(root, "parquet.toml", RENDER.replace('"data/*/"', '"data/b/"'))
    out = root / "parquet_out"
    ex.run(path, out, log=None)
    assert invsss.cli.main(["sweep-report", str(out), "--no-plots", "--parquet"]) == 0
    table = pandas.read_parquet(out / "report" / "results.parquet")
    rows = rows_by_id(out)
    assert sorted(table["id"]) == sorted(rows) and len(rows) == 4
    for record in table.to_dict("records"):
        row = rows[record["id"]]
        assert record["psnr"] == pytest.approx(row["psnr"], rel=1e-12)
        assert list(record["param.weights"]) == pytest.approx(row["param.weights"], rel=1e-12)
        assert record["status"] == "done" and record["pair"] == "b"


@pytest.mark.slow
def test_sweep_killed_mid_run_resumes_to_one_done_row_per_trial(root):
    path = experiment_file(root, "kill.toml", RENDER)
    out = root / "killed"
    process = _sweep_until(path, out, 3, subprocess.DEVNULL)
    time.sleep(0.5)  # into the next trial's commit
    process.send_signal(signal.SIGKILL)
    process.wait()
    assert process.returncode == -signal.SIGKILL
    before = rows_by_id(out)
    done_before = {i: r for i, r in before.items() if r["status"] == "done"}
    assert 3 <= len(done_before) < 12, "the kill should land mid-sweep"
    # A killed sweep can leave files without a done row, never a done row without files.
    for trial_id in done_before:
        assert result_state(trial_folder(out, trial_id)) == "complete"

    summary = ex.run(path, out, log=None)
    assert (summary.done, summary.failed, summary.remaining) == (12, 0, 0)
    assert summary.ran == 12 - len(done_before)  # exactly the trials not done
    after = rows_by_id(out)
    expected = {t.id for t in ex.load(path).trials}
    assert set(after) == expected and all(r["status"] == "done" for r in after.values())
    with sqlite3.connect(out / "results.sqlite") as db:
        assert db.execute("SELECT COUNT(*), COUNT(DISTINCT id) FROM trials").fetchone() == (12, 12)
        finished = dict(db.execute("SELECT id, finished FROM trials"))
    for trial_id, row in done_before.items():  # not run again
        assert after[trial_id]["attempts"] == 1
    assert all(finished[i] is not None for i in expected)
    check_artefacts_match(str(out), after)

    # A third run has nothing to do.
    assert ex.run(path, out, log=None).ran == 0
