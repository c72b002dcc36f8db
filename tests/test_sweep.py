"""Sweeps from experiment files: errors, resuming after SIGKILL, failing trials, executors.

Everything runs on tiny generated pairs (24x24) so the file stays near a minute:
render trials are cheap after one compilation, and the fit trials share one
compilation across the local and the Dask (threaded) runs of the same process.
"""

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
import invsss.experiments as ex
from invsss import InvalidInputError
from invsss.experiments.report import write_report
from invsss.experiments.runner import trial_folder
from invsss.io.result_dir import result_state

TRUTH = invsss.SSSParams(600.0, 800.0, 0.5, [0.6, 0.4], [0.5, 2.0])
PROFILE = '{weights = [0.5, 0.5], variances = [0.5, 2.0]}'


def _write_pair(folder, seed, size=24):
    os.makedirs(folder, exist_ok=True)
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size]
    source = rng.uniform(0.2, 1.0, (size, size, 3)).astype(np.float32)
    depth = (500.0 + 2.0 * x + rng.uniform(0.0, 1.0, (size, size))).astype(np.float32)
    mask = (((x - size / 2) ** 2 + (y - size / 2) ** 2) < (size * 0.42) ** 2).astype(np.float32)
    target = np.asarray(invsss.render(source, depth, mask, TRUTH))
    grey = target @ np.array([0.6, 0.3, 0.1]) * 0.8 + 0.01  # a NIR-like grey target
    invsss.write_image(os.path.join(folder, "source.exr"), source)
    invsss.write_image(os.path.join(folder, "target.exr"), grey.astype(np.float32))
    invsss.write_image(os.path.join(folder, "depth.exr"), depth)
    invsss.write_image(os.path.join(folder, "mask.png"), mask)


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    """A folder with pairs ``data/a``, ``data/b``, ``data/c`` (experiment files go beside ``data``)."""
    base = tmp_path_factory.mktemp("sweep")
    for seed, name in enumerate("abc"):
        _write_pair(base / "data" / name, seed)
    return base


def _experiment(root, name, text):
    path = root / name
    path.write_text(text)
    return path


RENDER = f"""
name = "matrix"
task = "render"
[data]
pairs = ["data/*/"]
[base]
maxdd = 0.5
profile = {PROFILE}
[grid]
sss_level = [300, 600]
correction = [0, 800]
"""


def _rows(out):
    return {row["id"]: row for row in ex.results(out, frame=False)}


def _check_artefacts_match(out, rows):
    """Every done row has its committed files, whose params.json is the row's; nothing else."""
    folders = set(os.listdir(os.path.join(out, "trials"))) if os.path.isdir(os.path.join(out, "trials")) else set()
    done = {i for i, row in rows.items() if row["status"] == "done"}
    assert folders == done
    for trial_id in done:
        folder = trial_folder(out, trial_id)
        assert result_state(folder) == "complete"
        written = json.load(open(os.path.join(folder, "params.json")))
        for name in ("sss_level", "correction", "maxdd", "weights", "variances"):
            assert written[name] == rows[trial_id][f"param.{name}"]
        assert written["psnr"] == pytest.approx(rows[trial_id]["psnr"], rel=1e-12)


# ------------------------------------------------------------------ bad files


@pytest.mark.parametrize(
    "text, expected",
    [
        ('task = "render"\n[dta]\npairs = ["data/*/"]\n', "unknown key 'dta' (did you mean 'data'?)"),
        ('task = "fit"\n[data]\npairs = ["data/*/"]\n[base]\nn_start = 2\n',
         "unknown key 'base.n_start' (did you mean 'n_starts'?)"),
        ('task = "fit"\n[data]\npairs = ["data/*/"]\n[grid]\nfix.maxd = [0.1, 0.5]\n',
         "unknown key 'grid.fix.maxd' (did you mean 'fix.maxdd'?)"),
        ('task = "render"\n[data]\npairs = ["data/*/"]\n[base]\nmaxdd = 0.5\ncorrection = 0.0\n'
         '[grid]\nsss_levle = [1.0]\n', "unknown key 'grid.sss_levle' (did you mean 'sss_level'?)"),
        # A folder named outright that holds no pair: named as written ('.' before).
        ('task = "render"\n[data]\npairs = ["./"]\n', "data.pairs: './' has no source.exr"),
        # A [base] value that an axis would silently replace in every trial.
        ('task = "render"\n[data]\npairs = ["data/*/"]\n[base]\nmaxdd = 0.5\ncorrection = 0.0\nsss_level = 100.0\n'
         '[grid]\nsss_level = [300.0, 600.0]\n', "grid.sss_level: also set in [base] (base.sss_level)"),
        ('task = "fit"\n[data]\npairs = ["data/*/"]\n[base]\nfix = {maxdd = 0.5, correction = 0.0}\n'
         '[zip]\nfix.maxdd = [0.1, 0.2]\n', "zip.fix.maxdd: also set in [base] (base.fix.maxdd)"),
        # A fit holds a parameter through fix: suggested as such, not the nearest option's name.
        ('task = "fit"\n[data]\npairs = ["data/*/"]\n[grid]\nsss_level = [300.0, 600.0]\n',
         "unknown key 'grid.sss_level' (did you mean 'grid.fix.sss_level'?)"),
        ('task = "render"\n[data]\npairs = ["data/*/"]\n[[data.files]]\nsorce = "x"\n',
         "unknown key 'data.files[0].sorce' (did you mean 'source'?)"),
        ('task = "fitt"\n[data]\npairs = ["data/*/"]\n', "task: input should be 'fit', 'fit-joint' or 'render'"),
        ('task = "fit"\n[data]\npairs = ["nowhere/*/"]\n', "'nowhere/*/' matches no folder"),
        ('task = "fit"\n[data]\npairs = ["data/*/"]\n[grid]\nsolver = ["lm", "adam"]\n',
         "trial 4 (solver='adam', pair='a'): solver: expected one of lm, gauss-newton, bfgs, got 'adam'"),
        ('task = "fit"\n[data]\npairs = ["data/*/"]\n[zip]\nsolver = ["lm", "bfgs"]\nmax_steps = [5]\n',
         "zip: the lists must have one length, but solver has 2, max_steps has 1"),
        ('task = "render"\n[data]\npairs = ["data/*/"]\n[base]\ncorrection = 0.0\nmaxdd = 0.5\n'
         '[grid]\nsss_level = [600.0, -1.0]\n', "trial 4 (sss_level=-1.0, pair='a'): render options: sss_level must be > 0"),
        ('task = "render"\n[data\n', "invalid TOML"),
    ],
)
def test_bad_experiment_files_give_one_line_errors(root, text, expected):
    path = _experiment(root, "bad.toml", text)
    with pytest.raises(InvalidInputError) as caught:
        ex.load(path)
    message = str(caught.value)
    assert expected in message
    assert "\n" not in message and message.startswith(str(path))


def test_bad_file_on_the_command_line_is_one_line_and_status_2(root, capsys):
    path = _experiment(root, "bad_cli.toml", 'task = "render"\n[dta]\n')
    assert invsss.cli.main(["sweep", str(path), "--out", str(root / "never")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "did you mean 'data'?" in err
    assert not os.path.exists(root / "never")


def test_trial_ids_are_stable_and_follow_the_configuration(root):
    first = ex.load(_experiment(root, "ids.toml", RENDER))
    # The same configurations listed in another order get the same ids.
    swapped = RENDER.replace("sss_level = [300, 600]", "sss_level = [600, 300]")
    second = ex.load(_experiment(root, "ids2.toml", swapped))
    assert {t.id for t in first.trials} == {t.id for t in second.trials}
    assert len({t.id for t in first.trials}) == len(first.trials) == 12
    changed = ex.load(_experiment(root, "ids3.toml", RENDER.replace("maxdd = 0.5", "maxdd = 0.25")))
    assert not {t.id for t in first.trials} & {t.id for t in changed.trials}


def test_align_and_vignetting_are_fit_axes_that_keep_older_ids(root):
    from invsss.experiments.trials import trial_id

    text = 'task = "fit"\n[data]\npairs = ["data/a/"]\n[grid]\nvignetting = [false, true]\nalign = ["none", "similarity"]\n'
    experiment = ex.load(_experiment(root, "camera.toml", text))
    assert len({t.id for t in experiment.trials}) == 4
    plain = [t for t in experiment.trials if t.options["align"] == "none" and not t.options["vignetting"]]
    # Options added after the first release do not enter the id at their
    # defaults: a sweep started before they existed resumes with the same ids.
    first_release = ("model", "profile", "fix", "gauge", "solver", "n_starts", "max_steps", "tap_weights", "robust")
    older = {k: plain[0].options[k] for k in first_release}
    # The first release's default gauge was "variances", which "auto" now resolves to for sog.
    assert older["gauge"] == "auto"
    older["gauge"] = "variances"
    assert plain[0].id == trial_id({**plain[0].config, "options": older})
    with pytest.raises(InvalidInputError, match="vignetting"):
        ex.load(_experiment(root, "camera2.toml", text.replace("[false, true]", '["yes"]')))


def test_sobol_and_random_samples_are_seeded_and_in_range(root):
    text = RENDER.split("[grid]")[0] + (
        '[sample]\nmethod = "sobol"\nn = 4\nseed = 3\nlog = ["sss_level"]\n'
        "ranges.sss_level = [100.0, 1000.0]\nranges.correction = [0.0, 900.0]\n"
    )
    a = ex.load(_experiment(root, "sobol.toml", text))
    b = ex.load(_experiment(root, "sobol2.toml", text))
    c = ex.load(_experiment(root, "sobol3.toml", text.replace("seed = 3", "seed = 4")))
    assert [t.id for t in a.trials] == [t.id for t in b.trials]
    assert [t.id for t in a.trials] != [t.id for t in c.trials]
    levels = sorted({t.options["sss_level"] for t in a.trials})
    assert len(levels) == 4 and all(100.0 <= v <= 1000.0 for v in levels)
    random = ex.load(_experiment(root, "random.toml", text.replace('"sobol"', '"random"')))
    assert len(random.trials) == 12 and [t.id for t in random.trials] != [t.id for t in a.trials]


# ------------------------------------------------------------ kill and resume


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
def test_sweep_killed_mid_run_resumes_to_one_done_row_per_trial(root):
    path = _experiment(root, "kill.toml", RENDER)
    out = root / "killed"
    process = _sweep_until(path, out, 3, subprocess.DEVNULL)
    time.sleep(0.5)  # into the next trial's commit
    process.send_signal(signal.SIGKILL)
    process.wait()
    assert process.returncode == -signal.SIGKILL
    before = _rows(out)
    done_before = {i: r for i, r in before.items() if r["status"] == "done"}
    assert 3 <= len(done_before) < 12, "the kill should land mid-sweep"
    # A killed sweep can leave files without a done row, never a done row without files.
    for trial_id in done_before:
        assert result_state(trial_folder(out, trial_id)) == "complete"

    summary = ex.run(path, out, log=None)
    assert (summary.done, summary.failed, summary.remaining) == (12, 0, 0)
    assert summary.ran == 12 - len(done_before)  # exactly the trials not done
    after = _rows(out)
    expected = {t.id for t in ex.load(path).trials}
    assert set(after) == expected and all(r["status"] == "done" for r in after.values())
    with sqlite3.connect(out / "results.sqlite") as db:
        assert db.execute("SELECT COUNT(*), COUNT(DISTINCT id) FROM trials").fetchone() == (12, 12)
        finished = dict(db.execute("SELECT id, finished FROM trials"))
    for trial_id, row in done_before.items():  # not run again
        assert after[trial_id]["attempts"] == 1
    assert all(finished[i] is not None for i in expected)
    _check_artefacts_match(str(out), after)

    # A third run has nothing to do.
    assert ex.run(path, out, log=None).ran == 0


@pytest.mark.slow
def test_ctrl_c_stops_between_trials_and_a_rerun_resumes(root):
    path = _experiment(root, "sigint.toml", RENDER)
    out = root / "sigint"
    process = _sweep_until(path, out, 2, subprocess.PIPE)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130
    assert "run the same command again to resume" in err and "Traceback" not in err
    rows = _rows(out)
    statuses = [r["status"] for r in rows.values()]
    assert 2 <= statuses.count("done") < 12 and set(statuses) == {"done", "pending"}
    _check_artefacts_match(str(out), rows)
    assert invsss.cli.main(["sweep", str(path), "--out", str(out)]) == 0
    assert all(r["status"] == "done" for r in _rows(out).values())


# ------------------------------------------------------------ failing trials


def test_a_failing_trial_is_recorded_and_the_sweep_goes_on(root, capsys):
    # Pair "broken": its target has another size than its source: loading fails.
    broken = root / "broken"
    _write_pair(broken, 7, size=20)
    os.replace(broken / "target.exr", broken / "small_target.exr")
    invsss.write_image(broken / "target.exr", np.ones((18, 18), np.float32))
    text = RENDER.replace('pairs = ["data/*/"]', 'pairs = ["data/a/", "broken/"]')
    path = _experiment(root, "failing.toml", text)
    out = root / "failing"
    assert invsss.cli.main(["sweep", str(path), "--out", str(out)]) == 1  # some trials failed
    err = capsys.readouterr().err
    assert "4 failed" in err and "FAILED" in err
    rows = _rows(out)
    failed = [r for r in rows.values() if r["status"] == "failed"]
    assert len(rows) == 8 and len(failed) == 4
    assert all(r["pair"] == "broken" for r in failed)
    for row in failed:
        assert "target.exr" in row["error"] and "\n" not in row["error"]
        assert row["psnr"] is None
    _check_artefacts_match(str(out), rows)


# ------------------------------------------------------------------ executors


@pytest.mark.slow
def test_process_pool_gives_the_in_process_results(root):
    path = _experiment(root, "pool.toml", RENDER.replace('"data/*/"', '"data/a/"'))
    ex.run(path, root / "inproc", log=None)
    summary = ex.run(path, root / "pool", jobs=2, log=None)
    assert summary.done == 4
    here, pooled = _rows(root / "inproc"), _rows(root / "pool")
    assert set(here) == set(pooled)
    assert os.getpid() not in {r["pid"] for r in pooled.values()}  # ran in the workers
    assert {r["pid"] for r in here.values()} == {os.getpid()}
    for trial_id in here:
        assert pooled[trial_id]["loss"] == pytest.approx(here[trial_id]["loss"], rel=1e-9)
        assert pooled[trial_id]["ssim"] == pytest.approx(here[trial_id]["ssim"], rel=1e-9)
    _check_artefacts_match(str(root / "pool"), pooled)


@pytest.mark.slow
def test_fit_sweep_on_dask_local_cluster_matches_local(root):
    pytest.importorskip("distributed")
    text = f"""
task = "fit"
[data]
pairs = ["data/a/", "data/b/"]
[base]
n_starts = 1
max_steps = 40
robust = "none"
profile = {PROFILE}
"""
    path = _experiment(root, "fit.toml", text)
    local = ex.run(path, root / "fit_local", log=None)
    assert local.done == 2
    # Threads in this process: they reuse the fit compiled by the local run.
    dask = ex.run(path, root / "fit_dask", executor=ex.DaskExecutor(jobs=2, processes=False), log=None)
    assert dask.done == 2
    a, b = _rows(root / "fit_local"), _rows(root / "fit_dask")
    assert set(a) == set(b)
    for trial_id in a:
        for key in ("loss", "psnr", "param.sss_level", "param.correction", "stderr.sss_level"):
            assert b[trial_id][key] == pytest.approx(a[trial_id][key], rel=1e-9), key
        assert a[trial_id]["param.sss_level"] == pytest.approx(600.0, rel=0.05)
        assert os.path.isfile(os.path.join(trial_folder(root / "fit_dask", trial_id), "fit.exr"))
    assert [row["pair"] for row in ex.results(root / "fit_dask", frame=False)] == ["a", "b"]
    pandas = pytest.importorskip("pandas")
    table = ex.results(root / "fit_dask")
    assert isinstance(table, pandas.DataFrame) and list(table["pair"]) == ["a", "b"]


@pytest.mark.slow
def test_dask_worker_processes_use_the_compilation_cache(root, tmp_path, monkeypatch):
    # Dask starts its own worker processes, which never pass through the CLI's
    # cache switch; the sweep's choice must reach them with the trials.
    pytest.importorskip("distributed")
    path = _experiment(root, "cache.toml", RENDER.replace('pairs = ["data/*/"]', 'pairs = ["data/a/"]'))
    cache = tmp_path / "cache"
    monkeypatch.setenv("INVSSS_CACHE_DIR", str(cache))
    summary = ex.run(path, tmp_path / "on", executor=ex.DaskExecutor(jobs=1), log=None)
    assert summary.done == 4
    assert cache.is_dir() and any(cache.iterdir())
    off = tmp_path / "off_cache"
    monkeypatch.setenv("INVSSS_CACHE_DIR", str(off))
    monkeypatch.setenv("INVSSS_NO_CACHE", "1")
    summary = ex.run(path, tmp_path / "off", executor=ex.DaskExecutor(jobs=1), log=None)
    assert summary.done == 4
    assert not off.exists()


def test_pair_axis_per_task(root):
    # fit and render: one trial per pair unless the file names the pairs itself.
    chosen = ex.load(_experiment(root, "pairs.toml", RENDER + 'pair = ["c", "a"]\n'))
    assert len(chosen.trials) == 8 and {t.axes["pair"] for t in chosen.trials} == {"a", "c"}
    assert [p["name"] for p in chosen.trials[0].pairs] == ["c"]
    with pytest.raises(InvalidInputError, match=r"pair 'd' is not one of the data's pairs \(a, b, c\)"):
        ex.load(_experiment(root, "pairs2.toml", RENDER + 'pair = ["d"]\n'))
    # fit-joint: every pair in each trial; the pair is not an axis.
    joint = f'task = "fit-joint"\n[data]\npairs = ["data/*/"]\n[base]\nprofile = {PROFILE}\n[grid]\nfix.maxdd = [0.5, 1.0]\n'
    experiment = ex.load(_experiment(root, "joint.toml", joint))
    assert len(experiment.trials) == 2 and experiment.axes == ("fix.maxdd",)
    assert all([p["name"] for p in t.pairs] == ["a", "b", "c"] for t in experiment.trials)
    assert [t.options["fix"] for t in experiment.trials] == [{"maxdd": 0.5}, {"maxdd": 1.0}]
    with pytest.raises(InvalidInputError, match="unknown key 'grid.pair'"):
        ex.load(_experiment(root, "joint2.toml", joint + 'pair = ["a"]\n'))


def test_sweep_report_table_csv_and_plots(root, capsys):
    import csv

    path = _experiment(root, "report.toml", RENDER.replace('"data/*/"', '"data/a/"'))
    out = root / "report_out"
    ex.run(path, out, log=None)
    assert invsss.cli.main(["sweep-report", str(out)]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split()[:5] == ["id", "status", "sss_level", "correction", "pair"]
    rows = _rows(out)
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
    path = _experiment(root, "parquet.toml", RENDER.replace('"data/*/"', '"data/b/"'))
    out = root / "parquet_out"
    ex.run(path, out, log=None)
    assert invsss.cli.main(["sweep-report", str(out), "--no-plots", "--parquet"]) == 0
    table = pandas.read_parquet(out / "report" / "results.parquet")
    rows = _rows(out)
    assert sorted(table["id"]) == sorted(rows) and len(rows) == 4
    for record in table.to_dict("records"):
        row = rows[record["id"]]
        assert record["psnr"] == pytest.approx(row["psnr"], rel=1e-12)
        assert list(record["param.weights"]) == pytest.approx(row["param.weights"], rel=1e-12)
        assert record["status"] == "done" and record["pair"] == "b"


def test_parquet_keeps_lists_and_writes_mixed_nestings_as_json_text(tmp_path):
    pandas = pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    from invsss.experiments.report import _write_parquet

    # A grey target's weights are a list, an RGB target's a list per Gaussian:
    # pyarrow cannot hold both in one column ("cannot mix list and non-list").
    rows = [{"id": "a", "param.weights": [0.4, 0.6], "param.variances": [1.0, 2.0]},
            {"id": "b", "param.weights": [[0.4, 0.4, 0.4], [0.6, 0.6, 0.6]], "param.variances": [1.0, 2.0]},
            {"id": "c", "param.weights": None, "param.variances": None}]
    _write_parquet(rows, tmp_path / "r.parquet")
    table = pandas.read_parquet(tmp_path / "r.parquet").to_dict("records")
    assert [None if pandas.isna(r["param.weights"]) else json.loads(r["param.weights"]) for r in table] == \
        [row["param.weights"] for row in rows]
    assert list(table[0]["param.variances"]) == [1.0, 2.0]  # one nesting: still a list


def test_report_lines_follow_the_grid_and_sampled_and_text_axes_plot_as_such(root):
    from invsss.experiments.report import _SampleKeys, _plotted_axes, _series

    rows = [{"pair": p, "x": x, "y": y, "model": m, "s": 0.1 * k}
            for k, (p, x, y, m) in enumerate((p, x, y, m) for p in "ab" for x in (1, 2) for y in (5, 6)
                                              for m in ("sog", "thesis"))]
    # Against x: a line per pair and per value of y and model; s (sampled) splits nothing.
    series = _series(rows, "x", ["x", "y", "model", "s", "pair"], sampled={"s"})
    assert len(series) == 8 and ("a", "y=5, model=sog") in series
    assert all(sorted(r["x"] for r in group) == [1, 2] for group in series.values())
    assert _plotted_axes(rows, ["x", "model", "pair"]) == ["x", "model"]
    keys = _SampleKeys.of({"text": '[sample]\nmethod = "sobol"\nn = 4\nlog = ["sss_level"]\n'
                                   'ranges.sss_level = [300.0, 1200.0]\nranges.fix.maxdd = [0.1, 1.0]\n'})
    assert keys.sampled == {"sss_level", "fix.maxdd"} and keys.log == {"sss_level"}
    assert _SampleKeys.of({"text": "not [toml"}) == _SampleKeys()
    # A sampled render sweep: a plot per axis, and no contact sheet of mostly empty panels.
    sample = RENDER.replace('"data/*/"', '"data/a/"').replace(
        "[grid]\nsss_level = [300, 600]\ncorrection = [0, 800]\n",
        '[sample]\nmethod = "sobol"\nn = 4\nlog = ["sss_level"]\nranges.sss_level = [300.0, 1200.0]\n'
        "ranges.correction = [0.0, 800.0]\n")
    out = root / "sampled_out"
    ex.run(_experiment(root, "sampled.toml", sample), out, log=None)
    _, written = write_report(out)
    names = sorted(os.path.basename(w) for w in written)
    assert names == ["metrics_vs_correction.png", "metrics_vs_sss_level.png", "results.csv"]


def test_a_nan_loss_fails_the_trial_and_writes_nothing(root, monkeypatch):
    from invsss.experiments import runner
    from invsss.experiments.tasks import TaskOutput

    def diverged(task, options, pairs, stop=None):
        # What a diverging solver hands back: numbers, but a NaN loss.
        return TaskOutput(params={}, stderr=None, metrics={"loss": float("nan")}, warnings=[],
                          files={"params.json": lambda path: open(path, "w").write("{}")})

    monkeypatch.setattr(runner, "run_task", diverged)
    trial = ex.load(_experiment(root, "nan.toml", RENDER)).trials[0]
    out = root / "nan"
    outcome = runner.execute(trial.to_dict(), str(out))
    assert outcome["status"] == "failed" and "loss is nan" in outcome["error"]
    assert not os.path.exists(trial_folder(out, trial.id))


def test_shipped_experiment_files_load():
    """Every experiment file under experiments/ expands into checked trials (its
    pairs exist, its keys and options are valid, light terms find their buffers)."""
    import glob

    files = sorted(glob.glob(os.path.join(os.path.dirname(__file__), "..", "experiments", "*.toml")))
    assert len(files) >= 4
    for path in files:
        experiment = ex.load(path)
        assert experiment.trials, path


@pytest.mark.slow
def test_a_canvas_fits_pairs_of_two_sizes_as_each_fits_alone(root):
    _write_pair(root / "sized" / "small", 7, size=20)
    _write_pair(root / "sized" / "large", 8, size=24)
    text = (f'task = "fit"\n[data]\npairs = ["sized/*/"]\n[base]\nn_starts = 1\nmax_steps = 40\nrobust = "none"\n'
            f"profile = {PROFILE}\n")
    plain = ex.run(_experiment(root, "sized.toml", text), root / "sized_plain", log=None)
    padded = ex.run(_experiment(root, "sized_canvas.toml", text + "canvas = [28, 28]\n"), root / "sized_canvas",
                    log=None)
    assert plain.done == padded.done == 2
    a = {row["pair"]: row for row in ex.results(root / "sized_plain", frame=False)}
    b = {row["pair"]: row for row in ex.results(root / "sized_canvas", frame=False)}
    for pair in ("small", "large"):
        assert a[pair]["id"] != b[pair]["id"]  # the canvas is part of the trial
        for key in ("loss", "psnr", "param.sss_level", "param.correction", "param.maxdd"):
            assert b[pair][key] == pytest.approx(a[pair][key], rel=1e-6), (pair, key)
    with pytest.raises(InvalidInputError, match="canvas"):
        ex.load(_experiment(root, "sized_bad.toml", text + "canvas = [28]\n"))
