"""The limits of ``invsss sweep`` from the command line: a huge experiment is refused
before it is expanded, ``--max-trials`` sets the limit, a sweep whose trials failed
exits 1, a closed stdout and stderr do not stop it, and the report separates the tasks
of one folder."""

from __future__ import annotations

import csv
import os
import re
import subprocess
import sys
import time

import numpy as np
import pytest

import invsss
import invsss.sweeps as ex
from invsss import InvalidInputError
from invsss.cli import main

TRUTH = invsss.SSSParams(600.0, 800.0, 0.5, [0.6, 0.4], [0.5, 2.0])


PROFILE = "{weights = [0.5, 0.5], variances = [0.5, 2.0]}"


RENDER = f"""task = "render"
[data]
pairs = ["data/a/"]
[base]
maxdd = 0.5
profile = {PROFILE}
[grid]
sss_level = [300, 600]
correction = [0, 800]
"""


def _write_pair(folder, seed, size=16):
    os.makedirs(folder, exist_ok=True)
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size]
    source = rng.uniform(0.2, 1.0, (size, size, 3)).astype(np.float32)
    depth = (500.0 + 2.0 * x + rng.uniform(0.0, 1.0, (size, size))).astype(np.float32)
    mask = (((x - size / 2) ** 2 + (y - size / 2) ** 2) < (size * 0.42) ** 2).astype(np.float32)
    target = np.asarray(invsss.render(source, depth, mask, TRUTH)) @ np.array([0.6, 0.3, 0.1])
    for name, image in (("source", source), ("target", target), ("depth", depth)):
        invsss.write_image(os.path.join(folder, f"{name}.exr"), np.asarray(image, np.float32))
    invsss.write_image(os.path.join(folder, "mask.png"), mask)


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    base = tmp_path_factory.mktemp("limits")
    for seed, name in enumerate("ab"):
        _write_pair(base / "data" / name, seed)
    return base


def _experiment(root, name, text):
    path = root / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("table, count, factors", [
    ("[grid]\nsss_level = [{values}]\ncorrection = [{values}]\n", "2,000,000",
     "grid 1000 x 1000 x 2 pair(s)"),
    ("[sample]\nn = 1000000\nranges = {{sss_level = [100.0, 1000.0]}}\n", "2,000,000",
     "sample 1000000 x 2 pair(s)"),
])
def test_a_huge_experiment_is_refused_before_it_is_expanded(root, capsys, table, count, factors):
    values = ", ".join(str(float(v)) for v in range(1, 1001))
    # correction in [base] only where no axis sets it (that is refused on its own).
    held = "" if "correction" in table else "correction = 0.0\n"
    text = (f'task = "render"\n[data]\npairs = ["data/*/"]\n[base]\nmaxdd = 0.5\n{held}'
            f"profile = {PROFILE}\n" + table.format(values=values))
    path = _experiment(root, "huge.toml", text)
    start = time.perf_counter()
    with pytest.raises(InvalidInputError) as caught:
        ex.load(path)
    assert time.perf_counter() - start < 5.0  # expanding took about 1 ms a trial: half an hour
    message = str(caught.value)
    assert message == (f"{path}: {count} trials ({factors}), more than the limit of 100,000; vary fewer "
                       f"values, or raise the limit with --max-trials {count.replace(',', '')} "
                       "(max_trials= in load)")
    out = root / "huge_out"
    assert main(["sweep", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"invsss: error: {message}"
    assert not os.path.exists(out)


def test_max_trials_sets_the_limit(root, capsys):
    path = _experiment(root, "four.toml", RENDER)
    with pytest.raises(InvalidInputError, match=r"4 trials \(grid 2 x 2 x 1 pair\(s\)\), more than the limit of 3"):
        ex.load(path, max_trials=3)
    assert len(ex.load(path, max_trials=4).trials) == 4
    # A file that names its pairs as an axis counts them once.
    named = _experiment(root, "named.toml", RENDER.replace('"data/a/"', '"data/*/"') + 'pair = ["a", "b"]\n')
    with pytest.raises(InvalidInputError, match=r"8 trials \(grid 2 x 2 x 2\), more than the limit of 7"):
        ex.load(named, max_trials=7)
    out = root / "four_out"
    assert main(["sweep", str(path), "--out", str(out), "--max-trials", "3"]) == 2
    assert "raise the limit with --max-trials 4" in capsys.readouterr().err
    assert main(["sweep", str(path), "--out", str(out), "--max-trials", "0"]) == 2
    assert "--max-trials: expected a whole number >= 1, got 0" in capsys.readouterr().err
    assert main(["sweep", str(path), "--out", str(out), "--max-trials", "4"]) == 0
    assert len(ex.results(out, frame=False)) == 4


def test_a_sweep_whose_trials_failed_exits_1(root, capsys):
    broken = root / "broken"
    _write_pair(broken, 7)
    invsss.write_image(broken / "target.exr", np.ones((10, 10), np.float32))  # another size
    path = _experiment(root, "failing.toml", RENDER.replace('"data/a/"', '"data/a/", "broken/"'))
    out = root / "failing_out"
    assert main(["sweep", str(path), "--out", str(out)]) == 1
    captured = capsys.readouterr()
    assert "sweep: 4 done, 4 failed, 0 not run" in captured.out
    # Each progress line says which trial it was, not only its id.
    assert re.search(r"\(trial \w+ \(sss_level=\d+, correction=\d+, pair=broken\) FAILED: ", captured.err)
    # Rerun: the failed trials run again and fail again; still 1.
    assert main(["sweep", str(path), "--out", str(out)]) == 1


@pytest.mark.slow
def test_a_closed_stdout_and_stderr_do_not_stop_the_sweep(root):
    """`invsss sweep ... 2>&1 | head -1`: the reader leaves after the first line."""
    path = _experiment(root, "piped.toml", RENDER)
    out = root / "piped_out"
    process = subprocess.Popen([sys.executable, "-m", "invsss", "sweep", str(path), "--out", str(out)],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    first = process.stdout.readline()
    process.stdout.close()  # as head does once it has its line
    assert first.startswith(b"sweep: ")
    assert process.wait(timeout=300) == 0
    rows = ex.results(out, frame=False)
    assert len(rows) == 4 and all(row["status"] == "done" for row in rows)


@pytest.mark.slow  # two fit trials: 35 s on two cores, mostly compiling the fit
def test_the_report_separates_the_tasks_of_one_folder(root, capsys):
    out = root / "mixed"
    render = _experiment(root, "mixed_render.toml", RENDER)
    fit = _experiment(root, "mixed_fit.toml", f'task = "fit"\n[data]\npairs = ["data/a/"]\n[base]\n'
                      f'profile = {PROFILE}\nn_starts = 1\nrobust = "none"\nmax_steps = 3\n'
                      '[grid]\nfix.maxdd = [0.5, 1.0]\n')
    assert main(["sweep", str(render), "--out", str(out)]) == 0
    # A report of the render alone draws its plots at the top of report/ ...
    assert main(["sweep-report", str(out)]) == 0
    assert os.path.isfile(out / "report" / "contact_a.png")
    assert main(["sweep", str(fit), "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["sweep-report", str(out)]) == 0
    # ... which a report of both tasks moves into report/render/, leaving no stale copy.
    assert sorted(p.name for p in (out / "report").glob("*.png")) == []
    printed = capsys.readouterr().out
    assert printed.splitlines()[-1].startswith("wrote ")
    render_part, fit_part = printed.rsplit("\nwrote ", 1)[0].split("\n\n")
    assert render_part.splitlines()[0] == "task render: 4 trial(s)"
    columns = render_part.splitlines()[1].split()
    assert columns[:2] == ["id", "status"] and set(columns[2:5]) == {"sss_level", "correction", "pair"}
    assert columns[5] == "loss"
    assert len(render_part.splitlines()) == 2 + 4
    assert fit_part.splitlines()[0] == "task fit: 2 trial(s)"
    fit_columns = fit_part.splitlines()[1].split()
    assert fit_columns[:5] == ["id", "status", "fix.maxdd", "pair", "loss"]
    # A fit's table shows its estimates; a render's has none to show.
    assert fit_columns[7:10] == ["param.sss_level", "param.correction", "param.maxdd"]
    assert not any(c.startswith("param.") for c in columns)
    assert len(fit_part.splitlines()) == 2 + 2
    with open(out / "report" / "results.csv", newline="") as f:
        tasks = [row["task"] for row in csv.DictReader(f)]
    assert sorted(tasks) == ["fit"] * 2 + ["render"] * 4
    # Each task's plots in its own folder: a contact sheet for the renders, parameters for the fits.
    assert os.path.isfile(out / "report" / "render" / "contact_a.png")
    assert os.path.isfile(out / "report" / "fit" / "params_vs_fix.maxdd.png")
