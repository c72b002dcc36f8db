"""Running a sweep: :func:`run`.

``run(experiment, OUT)`` records every trial of the experiment in
``OUT/results.sqlite`` (:mod:`.store`), then runs those not ``done`` yet on the
chosen executor (:mod:`.executors`), recording each outcome as it arrives.
Running the same experiment into the same folder again therefore resumes: a
sweep killed at any point, by Ctrl-C, SIGTERM, SIGKILL or a power cut, loses
at most the trials that were running.

A damaged or empty ``results.sqlite`` (while ``OUT/trials/`` holds results) is
refused with one line; ``rebuild_store=True`` (``invsss sweep --rebuild-store``)
moves it aside and makes the table again from the trial folders
(:func:`.store.rebuild`), then runs what is not done. A full disk ends the
run with one line (:class:`.store.StoreError`); the same command resumes once
there is room.

One sweep at a time per folder: ``OUT/.sweep.lock`` is held (``fcntl.flock``,
released by the kernel if the process dies) for the whole run, and a second
sweep into the folder is refused with the first one's pid and host.

A ``stop`` callable (:class:`invsss.runtime.interrupts.StopSignals`), polled between
trials, ends the sweep early: no new trial starts, the running ones finish (a
fit running in this process is abandoned at its next solver step) and
:func:`run` returns with ``interrupted=True``; rerunning resumes.

Progress goes to ``log`` (stderr by default), one line per finished trial:
done / failed / remaining, and an estimate of the time left from this run's
pace.
"""

from __future__ import annotations

import contextlib
import dataclasses
import fcntl
import os
import shutil
import socket
import sys
import time

from ..validation import InvalidInputError, error_line
from .executors import make_executor
from .experiment import Experiment, load
from .runner import execute, trial_folder
from .store import LOCK_NAME, ResultsStore, StoreError, rebuild

__all__ = ["SweepLock", "SweepSummary", "run"]

_POLL_SECONDS = 0.2


@dataclasses.dataclass(frozen=True)
class SweepSummary:
    """What :func:`run` did.

    Attributes
    ----------
    trials : int
        Trials in the experiment.
    done, failed, remaining : int
        Their state in the database when the run ended (``remaining``: not run,
        or abandoned by a stop).
    ran : int
        Trials this run finished (done or failed).
    seconds : float
        Wall time of this run.
    interrupted : bool
        Whether ``stop`` ended the run early.
    out : str
        The output folder.
    """

    trials: int
    done: int
    failed: int
    remaining: int
    ran: int
    seconds: float
    interrupted: bool
    out: str


class SweepLock:
    """An exclusive ``flock`` on ``OUT/.sweep.lock`` for the duration of a run."""

    def __init__(self, out: str):
        self.path = os.path.join(out, LOCK_NAME)
        self._fd: int | None = None

    def __enter__(self) -> SweepLock:
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.read(fd, 4096).decode(errors="replace").strip() or "holder unknown"
            os.close(fd)
            raise InvalidInputError(
                f"{os.path.dirname(self.path)}: another sweep is running into this folder ({holder}); "
                "wait for it or choose another --out"
            ) from None
        try:
            os.ftruncate(fd, os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}\n".encode(), 0))
        except OSError as err:  # a full disk: nothing could be recorded either
            os.close(fd)
            raise InvalidInputError(
                f"{os.path.dirname(self.path)}: cannot write to the output folder ({err.strerror}); "
                "free some space, then run the same command again to resume"
            ) from None
        self._fd = fd
        return self

    def __exit__(self, *exc) -> None:
        if self._fd is not None:
            os.close(self._fd)  # releases the lock; the file stays, harmlessly
            self._fd = None


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds}s"
    if seconds < 3600:
        return f"{seconds // 60}m{seconds % 60:02d}s"
    return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m"


class _Progress:
    """``sweep: 5/12 done, 1 failed, 6 remaining, ETA 2m10s`` lines on ``log``."""

    def __init__(self, log, total: int, done: int, failed: int):
        self.log, self.total, self.done, self.failed = log, total, done, failed
        self.ran = 0
        self.first_finished = time.monotonic()

    def say(self, text: str) -> None:
        if self.log is None:
            return
        try:
            print(f"sweep: {text}", file=self.log, flush=True)
        except (BrokenPipeError, ValueError):
            # A reader that went away (`invsss sweep ... 2>&1 | head`) or a closed
            # file ends the progress lines, not the sweep: its trials go on.
            self.log = None

    def finished(self, outcome: dict, previous: str, axes: dict | None = None) -> None:
        self.ran += 1
        if outcome["status"] == "done":
            self.done += 1
        else:
            self.failed += 1
        if previous == "failed":  # a failed trial from an earlier run, now run again
            self.failed -= 1
        remaining = self.total - self.done - self.failed
        now = time.monotonic()
        if self.ran == 1:
            # The first trial's time is mostly compiling: the rate is counted from its end.
            self.first_finished = now
        rate = (now - self.first_finished) / (self.ran - 1) if self.ran > 1 else None
        eta = f", ETA {_duration(rate * remaining)}" if remaining and rate is not None else ""
        what = "done" if outcome["status"] == "done" else f"FAILED: {outcome['error']}"
        seconds = outcome.get("timings", {}).get("total", 0.0)
        # What the trial was, not only its id: the values of its axes.
        values = ", ".join(f"{k}={v}" for k, v in (axes or {}).items())
        label = f"trial {outcome['id']}" + (f" ({values})" if values else "")
        self.say(
            f"{self.done}/{self.total} done, {self.failed} failed, {remaining} remaining{eta} "
            f"({label} {what}, {seconds:.1f}s)"
        )


def _trial_rows(experiment: Experiment) -> list[dict]:
    return [{**t.to_dict(), "config": t.config} for t in experiment.trials]


def _record(store: ResultsStore, out: str, outcome: dict) -> None:
    store.record(outcome)
    if outcome["status"] != "done":
        # A folder left by an earlier attempt of this trial would not match its
        # row any more; only done rows have files.
        shutil.rmtree(trial_folder(out, outcome["id"]), ignore_errors=True)


def run(
    experiment,
    out,
    *,
    executor="local",
    jobs: int | None = None,
    scheduler: str | None = None,
    stop=None,
    log="stderr",
    rebuild_store: bool = False,
) -> SweepSummary:
    """Run the trials of ``experiment`` not yet done in ``out`` (see the module docstring).

    Parameters
    ----------
    experiment : Experiment or path
        From :func:`invsss.sweeps.load`, or the path of an experiment file.
    out : str or os.PathLike
        The sweep's folder (created if missing): ``results.sqlite`` and
        ``trials/<id>/``.
    executor : {"local", "dask"} or an executor object
        See :mod:`invsss.sweeps.executors`.
    jobs : int, optional
        Local worker processes (default 1: this process), or the workers of a
        Dask ``LocalCluster`` (default 2).
    scheduler : str, optional
        A Dask scheduler's address (``executor="dask"`` only).
    stop : callable, optional
        ``stop() -> bool``, polled between trials; True ends the run early.
    log : file, "stderr" or None
        Where progress lines go: a file, ``sys.stderr`` as it is when the run
        starts (default), or nowhere. If it is closed under the run (a pipe whose
        reader left), the lines stop and the trials go on.
    rebuild_store : bool
        First make ``results.sqlite`` again from the trial folders (the old
        file is moved aside to ``results.sqlite.damaged-<time>``); see
        :func:`invsss.sweeps.store.rebuild`.

    Returns
    -------
    SweepSummary

    Raises
    ------
    InvalidInputError
        A bad experiment file, an unusable output folder, another sweep running
        into it, a bad executor choice; :class:`~invsss.sweeps.store.StoreError`
        (a subclass) for a damaged or empty results database, or one that
        cannot be written (a full disk).

    Examples
    --------
    A render matrix on one generated pair, run twice: the second run has nothing to do.

    >>> import os, tempfile, numpy as np, invsss, invsss.sweeps as ex
    >>> root = tempfile.mkdtemp(); pair = os.path.join(root, "pair"); os.mkdir(pair)
    >>> rng = np.random.default_rng(0)
    >>> for name, image in [("source.exr", rng.uniform(0.2, 1, (16, 16, 3))), ("target.exr",
    ...         rng.uniform(0.2, 1, (16, 16))), ("depth.exr", np.full((16, 16), 500.0)),
    ...         ("mask.png", np.ones((16, 16)))]:
    ...     invsss.write_image(os.path.join(pair, name), image.astype(np.float32))
    >>> with open(os.path.join(root, "e.toml"), "w") as f:
    ...     _ = f.write('task = "render"\\n[data]\\npairs = ["pair/"]\\n[base]\\nmaxdd = 0.5\\n'
    ...                 '[grid]\\nsss_level = [300, 600]\\ncorrection = [0, 800]\\n')
    >>> out = os.path.join(root, "out")
    >>> summary = ex.run(os.path.join(root, "e.toml"), out, log=None)
    >>> summary.done, summary.failed, summary.ran
    (4, 0, 4)
    >>> ex.run(os.path.join(root, "e.toml"), out, log=None).ran
    0
    >>> sorted(os.listdir(os.path.join(out, "trials", ex.results(out, frame=False)[0]["id"])))
    ['invsss-manifest.json', 'params.json', 'render.exr']
    """
    if not isinstance(experiment, Experiment):
        experiment = load(experiment)
    out = os.fspath(out)
    if os.path.exists(out) and not os.path.isdir(out):
        raise InvalidInputError(f"{out}: expected an output folder, but a file of that name exists")
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as err:
        raise InvalidInputError(f"{out}: cannot create the output folder ({err.strerror})") from None
    stop = stop or (lambda: False)
    log = sys.stderr if log == "stderr" else log
    chosen = make_executor(executor, jobs, scheduler)
    start = time.monotonic()
    with SweepLock(out):
        if rebuild_store:
            recovered, left_out = rebuild(out, experiment)
            _Progress(log, 0, 0, 0).say(
                f"rebuilt {os.path.join(out, 'results.sqlite')} from {recovered} trial folder(s)"
                + (f"; {left_out} folder(s) without a recorded row left out (they run again)" if left_out else ""))
        with ResultsStore(out) as store:
            return _run_in(store, experiment, out, chosen, stop, log, start)


def _run_in(store, experiment, out, chosen, stop, log, start) -> SweepSummary:
    """:func:`run`'s work, with the lock held and the database open."""
    store.set_meta(name=experiment.name, task=experiment.task, path=experiment.path,
                   axes=list(experiment.axes), text=experiment.text)
    store.add(_trial_rows(experiment))
    ids = [t.id for t in experiment.trials]
    todo = store.to_run(ids)
    counts = store.counts(ids)
    statuses = {row["id"]: row["status"] for row in store.rows()}
    by_id = {t.id: t.to_dict() for t in experiment.trials}
    stale = sum(store.counts().values()) - len(ids)
    progress = _Progress(log, len(ids), counts["done"], counts["failed"])
    progress.say(
        f"{experiment.name}: {len(ids)} trials, {counts['done']} already done, {len(todo)} to run"
        + (f" ({stale} older trials in {out} kept)" if stale > 0 else "")
    )
    running: list[str] = []
    interrupted = False
    try:
        if todo:
            with chosen:
                progress.say(f"running {chosen.describe()}")
                interrupted = _drive(chosen, store, out, [by_id[i] for i in todo], statuses, stop,
                                     progress, running)
    finally:
        # Also after a store error (a full disk), when this may fail as well:
        # rows left running are run again next time all the same.
        with contextlib.suppress(StoreError):
            store.mark_pending(running)
    counts = store.counts(ids)
    summary = SweepSummary(
        trials=len(ids), done=counts["done"], failed=counts["failed"],
        remaining=len(ids) - counts["done"] - counts["failed"], ran=progress.ran,
        seconds=time.monotonic() - start, interrupted=interrupted, out=out,
    )
    if interrupted:
        progress.say(f"stopped: {summary.done} done, {summary.failed} failed, {summary.remaining} not run; "
                     "run the same command again to resume")
    return summary


def _drive(executor, store, out, queue, statuses, stop, progress, running) -> bool:
    """Run ``queue`` (trial dicts); return True if ``stop`` ended it early."""
    if executor.in_process:
        for trial in queue:
            if stop():
                return True
            attempt = store.mark_running(trial["id"])
            running.append(trial["id"])
            outcome = execute({**trial, "attempt": attempt}, out, stop)
            if outcome["status"] == "interrupted":
                return True
            _record(store, out, outcome)
            running.remove(trial["id"])
            progress.finished(outcome, statuses.get(trial["id"]), trial.get("axes"))
        return False
    queue = list(queue)
    in_flight: dict[object, dict] = {}  # the executor's future -> its trial
    told = False
    while queue or in_flight:
        while queue and len(in_flight) < executor.slots and not stop():
            trial = queue.pop(0)
            attempt = store.mark_running(trial["id"])
            running.append(trial["id"])
            in_flight[executor.submit({**trial, "attempt": attempt}, out)] = trial
        if stop() and not told:
            told = True
            progress.say(f"stopping: waiting for the {len(in_flight)} running trial(s) "
                         "(send the signal again to quit now)")
        if stop() and not in_flight:
            break
        for future in executor.wait(list(in_flight), _POLL_SECONDS):
            trial = in_flight.pop(future)
            trial_id = trial["id"]
            try:
                outcome = executor.outcome(future)
            except Exception as err:  # noqa: BLE001 -- a lost worker fails its trial, not the sweep
                outcome = {"id": trial_id, "status": "failed", "error": f"worker: {error_line(err)}",
                           "timings": {}, "finished": time.time()}
            _record(store, out, outcome)
            running.remove(trial_id)
            progress.finished(outcome, statuses.get(trial_id), trial.get("axes"))
    return bool(stop())
