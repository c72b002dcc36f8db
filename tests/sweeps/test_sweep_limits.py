"""A sweep's progress line (issue 30, case 8): its ETA leaves out the first trial, which
compiles. (Sweeps at their edges from the command line, experiments too large to
expand, exit status, closed output and reports: tests/cli/test_sweep_limits.py.)"""

from __future__ import annotations


def test_the_eta_leaves_out_the_first_trial_which_compiles(monkeypatch):
    import io

    from invsss.sweeps import sweep

    clock = iter([0.0, 30.0, 32.0, 34.0])  # the start, then three trials: 30 s (compiling), 2 s, 2 s
    monkeypatch.setattr(sweep.time, "monotonic", lambda: next(clock))
    log = io.StringIO()
    progress = sweep._Progress(log, total=10, done=0, failed=0)
    for k in range(3):
        progress.finished({"id": f"t{k}", "status": "done", "timings": {"total": 2.0}}, "pending", {"x": k})
    lines = log.getvalue().splitlines()
    assert "ETA" not in lines[0] and "(trial t0 (x=0) done, 2.0s)" in lines[0]
    # 2 s a trial after the first, 8 and 7 to go: not 30 s a trial.
    assert ", ETA 16s " in lines[1] and ", ETA 14s " in lines[2]
