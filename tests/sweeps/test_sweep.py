"""Sweeps from experiment files: errors, trial ids and samples, executors, reports.

Everything runs on tiny generated pairs (24x24) so the file stays near a minute:
render trials are cheap after one compilation, and the fit trials share one
compilation across the local and the Dask (threaded) runs of the same process.
(``invsss sweep`` itself, killed, stopped and reporting: tests/cli/test_sweep.py.)
"""

from __future__ import annotations

import json
import os

import pytest

import invsss.sweeps as ex
from invsss import InvalidInputError
from invsss.sweeps.report import write_report
from invsss.sweeps.runner import trial_folder
from tests import ROOT
from tests.sweeps._sweep_files import (
    PROFILE,
    RENDER,
    check_artefacts_match,
    experiment_file,
    rows_by_id,
    write_small_pair,
)
from tests.sweeps._sweep_files import root  # noqa: F401 (fixture)


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
    path = experiment_file(root, "bad.toml", text)
    with pytest.raises(InvalidInputError) as caught:
        ex.load(path)
    message = str(caught.value)
    assert expected in message
    assert "\n" not in message and message.startswith(str(path))


def test_trial_ids_are_stable_and_follow_the_configuration(root):
    first = ex.load(experiment_file(root, "ids.toml", RENDER))
    # The same configurations listed in another order get the same ids.
    swapped = RENDER.replace("sss_level = [300, 600]", "sss_level = [600, 300]")
    second = ex.load(experiment_file(root, "ids2.toml", swapped))
    assert {t.id for t in first.trials} == {t.id for t in second.trials}
    assert len({t.id for t in first.trials}) == len(first.trials) == 12
    changed = ex.load(experiment_file(root, "ids3.toml", RENDER.replace("maxdd = 0.5", "maxdd = 0.25")))
    assert not {t.id for t in first.trials} & {t.id for t in changed.trials}


def test_align_and_vignetting_are_fit_axes_that_keep_older_ids(root):
    from invsss.sweeps.trials import trial_id

    text = 'task = "fit"\n[data]\npairs = ["data/a/"]\n[grid]\nvignetting = [false, true]\nalign = ["none", "similarity"]\n'
    experiment = ex.load(experiment_file(root, "camera.toml", text))
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
        ex.load(experiment_file(root, "camera2.toml", text.replace("[false, true]", '["yes"]')))


def test_sobol_and_random_samples_are_seeded_and_in_range(root):
    text = RENDER.split("[grid]")[0] + (
        '[sample]\nmethod = "sobol"\nn = 4\nseed = 3\nlog = ["sss_level"]\n'
        "ranges.sss_level = [100.0, 1000.0]\nranges.correction = [0.0, 900.0]\n"
    )
    a = ex.load(experiment_file(root, "sobol.toml", text))
    b = ex.load(experiment_file(root, "sobol2.toml", text))
    c = ex.load(experiment_file(root, "sobol3.toml", text.replace("seed = 3", "seed = 4")))
    assert [t.id for t in a.trials] == [t.id for t in b.trials]
    assert [t.id for t in a.trials] != [t.id for t in c.trials]
    levels = sorted({t.options["sss_level"] for t in a.trials})
    assert len(levels) == 4 and all(100.0 <= v <= 1000.0 for v in levels)
    random = ex.load(experiment_file(root, "random.toml", text.replace('"sobol"', '"random"')))
    assert len(random.trials) == 12 and [t.id for t in random.trials] != [t.id for t in a.trials]


# ------------------------------------------------------------------ executors


@pytest.mark.slow
def test_process_pool_gives_the_in_process_results(root):
    path = experiment_file(root, "pool.toml", RENDER.replace('"data/*/"', '"data/a/"'))
    ex.run(path, root / "inproc", log=None)
    summary = ex.run(path, root / "pool", jobs=2, log=None)
    assert summary.done == 4
    here, pooled = rows_by_id(root / "inproc"), rows_by_id(root / "pool")
    assert set(here) == set(pooled)
    assert os.getpid() not in {r["pid"] for r in pooled.values()}  # ran in the workers
    assert {r["pid"] for r in here.values()} == {os.getpid()}
    for trial_id in here:
        assert pooled[trial_id]["loss"] == pytest.approx(here[trial_id]["loss"], rel=1e-9)
        assert pooled[trial_id]["ssim"] == pytest.approx(here[trial_id]["ssim"], rel=1e-9)
    check_artefacts_match(str(root / "pool"), pooled)


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
    path = experiment_file(root, "fit.toml", text)
    local = ex.run(path, root / "fit_local", log=None)
    assert local.done == 2
    # Threads in this process: they reuse the fit compiled by the local run.
    dask = ex.run(path, root / "fit_dask", executor=ex.DaskExecutor(jobs=2, processes=False), log=None)
    assert dask.done == 2
    a, b = rows_by_id(root / "fit_local"), rows_by_id(root / "fit_dask")
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
    path = experiment_file(root, "cache.toml", RENDER.replace('pairs = ["data/*/"]', 'pairs = ["data/a/"]'))
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
    chosen = ex.load(experiment_file(root, "pairs.toml", RENDER + 'pair = ["c", "a"]\n'))
    assert len(chosen.trials) == 8 and {t.axes["pair"] for t in chosen.trials} == {"a", "c"}
    assert [p["name"] for p in chosen.trials[0].pairs] == ["c"]
    with pytest.raises(InvalidInputError, match=r"pair 'd' is not one of the data's pairs \(a, b, c\)"):
        ex.load(experiment_file(root, "pairs2.toml", RENDER + 'pair = ["d"]\n'))
    # fit-joint: every pair in each trial; the pair is not an axis.
    joint = f'task = "fit-joint"\n[data]\npairs = ["data/*/"]\n[base]\nprofile = {PROFILE}\n[grid]\nfix.maxdd = [0.5, 1.0]\n'
    experiment = ex.load(experiment_file(root, "joint.toml", joint))
    assert len(experiment.trials) == 2 and experiment.axes == ("fix.maxdd",)
    assert all([p["name"] for p in t.pairs] == ["a", "b", "c"] for t in experiment.trials)
    assert [t.options["fix"] for t in experiment.trials] == [{"maxdd": 0.5}, {"maxdd": 1.0}]
    with pytest.raises(InvalidInputError, match="unknown key 'grid.pair'"):
        ex.load(experiment_file(root, "joint2.toml", joint + 'pair = ["a"]\n'))


def test_parquet_keeps_lists_and_writes_mixed_nestings_as_json_text(tmp_path):
    pandas = pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    from invsss.sweeps.report import write_parquet

    # A grey target's weights are a list, an RGB target's a list per Gaussian:
    # pyarrow cannot hold both in one column ("cannot mix list and non-list").
    rows = [{"id": "a", "param.weights": [0.4, 0.6], "param.variances": [1.0, 2.0]},
            {"id": "b", "param.weights": [[0.4, 0.4, 0.4], [0.6, 0.6, 0.6]], "param.variances": [1.0, 2.0]},
            {"id": "c", "param.weights": None, "param.variances": None}]
    write_parquet(rows, tmp_path / "r.parquet")
    table = pandas.read_parquet(tmp_path / "r.parquet").to_dict("records")
    assert [None if pandas.isna(r["param.weights"]) else json.loads(r["param.weights"]) for r in table] == \
        [row["param.weights"] for row in rows]
    assert list(table[0]["param.variances"]) == [1.0, 2.0]  # one nesting: still a list


def test_report_lines_follow_the_grid_and_sampled_and_text_axes_plot_as_such(root):
    from invsss.sweeps.report import SampleKeys, plotted_axes, plot_series

    rows = [{"pair": p, "x": x, "y": y, "model": m, "s": 0.1 * k}
            for k, (p, x, y, m) in enumerate((p, x, y, m) for p in "ab" for x in (1, 2) for y in (5, 6)
                                              for m in ("sog", "thesis"))]
    # Against x: a line per pair and per value of y and model; s (sampled) splits nothing.
    series = plot_series(rows, "x", ["x", "y", "model", "s", "pair"], sampled={"s"})
    assert len(series) == 8 and ("a", "y=5, model=sog") in series
    assert all(sorted(r["x"] for r in group) == [1, 2] for group in series.values())
    assert plotted_axes(rows, ["x", "model", "pair"]) == ["x", "model"]
    keys = SampleKeys.of({"text": '[sample]\nmethod = "sobol"\nn = 4\nlog = ["sss_level"]\n'
                                   'ranges.sss_level = [300.0, 1200.0]\nranges.fix.maxdd = [0.1, 1.0]\n'})
    assert keys.sampled == {"sss_level", "fix.maxdd"} and keys.log == {"sss_level"}
    assert SampleKeys.of({"text": "not [toml"}) == SampleKeys()
    # A sampled render sweep: a plot per axis, and no contact sheet of mostly empty panels.
    sample = RENDER.replace('"data/*/"', '"data/a/"').replace(
        "[grid]\nsss_level = [300, 600]\ncorrection = [0, 800]\n",
        '[sample]\nmethod = "sobol"\nn = 4\nlog = ["sss_level"]\nranges.sss_level = [300.0, 1200.0]\n'
        "ranges.correction = [0.0, 800.0]\n")
    out = root / "sampled_out"
    ex.run(experiment_file(root, "sampled.toml", sample), out, log=None)
    _, written = write_report(out)
    names = sorted(os.path.basename(w) for w in written)
    assert names == ["metrics_vs_correction.png", "metrics_vs_sss_level.png", "results.csv"]


def test_a_nan_loss_fails_the_trial_and_writes_nothing(root, monkeypatch):
    from invsss.sweeps import runner
    from invsss.sweeps.tasks import TaskOutput

    def diverged(task, options, pairs, stop=None):
        # What a diverging solver hands back: numbers, but a NaN loss.
        return TaskOutput(params={}, stderr=None, metrics={"loss": float("nan")}, warnings=[],
                          files={"params.json": lambda path: open(path, "w").write("{}")})

    monkeypatch.setattr(runner, "run_task", diverged)
    trial = ex.load(experiment_file(root, "nan.toml", RENDER)).trials[0]
    out = root / "nan"
    outcome = runner.execute(trial.to_dict(), str(out))
    assert outcome["status"] == "failed" and "loss is nan" in outcome["error"]
    assert not os.path.exists(trial_folder(out, trial.id))


def test_shipped_experiment_files_load():
    """Every experiment file under experiments/ expands into checked trials (its
    pairs exist, its keys and options are valid, light terms find their buffers)."""
    import glob

    files = sorted(glob.glob(str(ROOT / "experiments" / "*.toml")))
    assert len(files) >= 4
    for path in files:
        experiment = ex.load(path)
        assert experiment.trials, path


@pytest.mark.slow
def test_a_canvas_fits_pairs_of_two_sizes_as_each_fits_alone(root):
    write_small_pair(root / "sized" / "small", 7, size=20)
    write_small_pair(root / "sized" / "large", 8, size=24)
    text = (f'task = "fit"\n[data]\npairs = ["sized/*/"]\n[base]\nn_starts = 1\nmax_steps = 40\nrobust = "none"\n'
            f"profile = {PROFILE}\n")
    plain = ex.run(experiment_file(root, "sized.toml", text), root / "sized_plain", log=None)
    padded = ex.run(experiment_file(root, "sized_canvas.toml", text + "canvas = [28, 28]\n"), root / "sized_canvas",
                    log=None)
    assert plain.done == padded.done == 2
    a = {row["pair"]: row for row in ex.results(root / "sized_plain", frame=False)}
    b = {row["pair"]: row for row in ex.results(root / "sized_canvas", frame=False)}
    for pair in ("small", "large"):
        assert a[pair]["id"] != b[pair]["id"]  # the canvas is part of the trial
        for key in ("loss", "psnr", "param.sss_level", "param.correction", "param.maxdd"):
            assert b[pair][key] == pytest.approx(a[pair][key], rel=1e-6), (pair, key)
    with pytest.raises(InvalidInputError, match="canvas"):
        ex.load(experiment_file(root, "sized_bad.toml", text + "canvas = [28]\n"))
