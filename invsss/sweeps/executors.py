"""Where trials run: in this process, in a local process pool, or on Dask.

An executor has one job: start :func:`.runner.execute` for a trial and say
when it has finished. The sweep (:mod:`.sweep`) keeps at most
:attr:`~LocalExecutor.slots` trials in flight, so a stop request takes effect
after the running trials, and the database, which only the sweep's own
process writes, always says what was started.

* :class:`LocalExecutor` with ``jobs=1`` runs each trial in this process (the
  sweep passes its stop request into the fit, so Ctrl-C is quick);
  ``jobs > 1`` uses a :class:`concurrent.futures.ProcessPoolExecutor` started
  with the ``spawn`` method (JAX's runtime threads do not survive ``fork``).
  Worker processes ignore SIGINT: Ctrl-C in a terminal reaches the whole
  process group, and the sweep, not each worker, decides what to stop.
* :class:`DaskExecutor` submits to a ``dask.distributed`` cluster: a
  ``LocalCluster`` of ``jobs`` single-threaded workers when no scheduler
  address is given, else ``Client(address)`` for a cluster started elsewhere.
  Workers must see the data and the output folder at the same paths (a shared
  file system), since each writes its trial's files itself.

Every worker process keeps its compiled JAX functions from one trial to the
next, so a sweep over same-sized pairs compiles once per worker and options;
local and Dask workers also share JAX's on-disk compilation cache
(:mod:`invsss.runtime.compile_cache`) unless the sweep runs with ``--no-cache``.

Running on a cluster (``pip install "invsss[cluster]"`` on every machine):

* by hand: start ``dask scheduler`` on one machine (it prints
  ``tcp://HOST:8786``), ``dask worker tcp://HOST:8786 --nthreads 1`` on each
  compute machine (one thread per worker: JAX already uses the cores), then
  ``invsss sweep EXP.toml --out DIR --executor dask --scheduler tcp://HOST:8786``
  from a machine that sees the same file system;
* on SLURM with ``dask-jobqueue``: in a Python session on the login node,
  ``cluster = dask_jobqueue.SLURMCluster(cores=8, processes=1, memory="16GB",
  walltime="02:00:00"); cluster.scale(jobs=10); print(cluster.scheduler_address)``,
  and pass that address to ``--scheduler`` (or, from Python,
  ``run(experiment, out, executor="dask", scheduler=cluster.scheduler_address)``).

Stopping (Ctrl-C) or killing the sweep leaves the cluster's workers alone; the
trials they were running are rerun on resume.
"""

from __future__ import annotations

import concurrent.futures
import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time
from typing import TYPE_CHECKING

from ..validation import InvalidInputError
from .runner import execute

if TYPE_CHECKING:
    from distributed import Client, LocalCluster

__all__ = ["EXECUTORS", "LocalExecutor", "DaskExecutor", "make_executor"]

_PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>

#: The executor names ``invsss sweep --executor`` accepts.
EXECUTORS = ("local", "dask")


def _worker_start(parent: int) -> None:
    """Set up a pool worker: ignore SIGINT, and die with the sweep's process ``parent``.

    A pool worker blocks reading its task queue, whose write end it holds
    itself; if the sweep is killed (SIGKILL, OOM) nothing would ever wake it,
    and an orphan busy with a trial holds that trial's folder. On Linux the
    kernel kills the worker when its parent dies (``PR_SET_PDEATHSIG``); a
    watchdog thread that notices a new parent process id covers other systems.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:  # died before we could ask
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, name="invsss-parent-watchdog", daemon=True).start()
    # Workers of one sweep share the on-disk compilation cache (off with INVSSS_NO_CACHE=1).
    from ..runtime.compile_cache import enable_compile_cache

    enable_compile_cache()


def _execute_on_dask_worker(trial: dict, out: str, use_cache: bool) -> dict:
    """:func:`.runner.execute` on a Dask worker, with the compilation cache the sweep chose.

    A Dask worker is started by Dask (or by the user's ``dask worker``), not
    by invsss, and does not see the sweep's ``--no-cache``; the sweep's
    choice travels with every trial instead. Enabling is idempotent, so only
    a worker's first trial does any work. The cache lives where
    :func:`~invsss.runtime.compile_cache.cache_directory` says on the worker's machine.
    """
    if use_cache:
        from ..runtime.compile_cache import enable_compile_cache

        enable_compile_cache()
    return execute(trial, out)


def _check_jobs(jobs) -> int:
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise InvalidInputError(f"jobs: expected an integer >= 1, got {jobs!r}")
    return jobs


class LocalExecutor:
    """Trials in this process (``jobs=1``) or in ``jobs`` spawned worker processes.

    Examples
    --------
    >>> with LocalExecutor(jobs=1) as executor:
    ...     executor.in_process, executor.slots
    (True, 1)
    """

    name = "local"

    def __init__(self, jobs: int = 1):
        self.jobs = _check_jobs(jobs)
        self._pool: concurrent.futures.ProcessPoolExecutor | None = None

    @property
    def in_process(self) -> bool:
        return self.jobs == 1

    @property
    def slots(self) -> int:
        """How many trials to keep in flight."""
        return self.jobs

    def __enter__(self) -> LocalExecutor:
        if not self.in_process:
            self._pool = concurrent.futures.ProcessPoolExecutor(
                max_workers=self.jobs, mp_context=multiprocessing.get_context("spawn"),
                initializer=_worker_start, initargs=(os.getpid(),),
            )
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def describe(self) -> str:
        return "in this process" if self.in_process else f"{self.jobs} local worker processes"

    def submit(self, trial: dict, out: str):
        # The sweep submits only to a pool (jobs > 1, inside "with"); jobs=1 runs in process.
        assert self._pool is not None, "LocalExecutor.submit needs jobs > 1 and a 'with' block"
        return self._pool.submit(execute, trial, out)

    def wait(self, futures, timeout: float):
        """The futures among ``futures`` that have finished (waiting up to ``timeout`` s)."""
        done, _ = concurrent.futures.wait(futures, timeout=timeout, return_when=concurrent.futures.FIRST_COMPLETED)
        return done

    @staticmethod
    def outcome(future) -> dict:
        return future.result()


class DaskExecutor:
    """Trials on a ``dask.distributed`` cluster (see the module docstring).

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``); None starts a
        ``LocalCluster``.
    jobs : int
        Workers of the ``LocalCluster``; with a scheduler, how many trials to
        keep in flight (default: the cluster's worker threads).
    processes : bool
        ``LocalCluster`` workers as processes (default) or threads of this process.
    """

    name = "dask"

    def __init__(self, scheduler: str | None = None, jobs: int | None = None, processes: bool = True):
        try:
            import distributed  # noqa: F401
        except ImportError:
            raise InvalidInputError(
                "--executor dask: dask.distributed is not installed; pip install 'invsss[cluster]'"
            ) from None
        self.scheduler = scheduler
        self.jobs = None if jobs is None else _check_jobs(jobs)
        self.processes = processes
        self.in_process = False
        self._client: Client | None = None
        self._cluster: LocalCluster | None = None

    def __enter__(self) -> DaskExecutor:
        from distributed import Client, LocalCluster

        if self.scheduler is None:
            self._cluster = LocalCluster(
                n_workers=self.jobs or 2, threads_per_worker=1, processes=self.processes,
                dashboard_address=None,
            )
            self._client = Client(self._cluster)
        else:
            try:
                self._client = Client(self.scheduler, timeout="20s")
            except (OSError, TimeoutError, ValueError) as err:
                raise InvalidInputError(
                    f"--scheduler {self.scheduler}: cannot connect to the Dask scheduler ({err})"
                ) from None
        return self

    def __exit__(self, *exc) -> None:
        if self._client is not None:
            self._client.close()
        if self._cluster is not None:
            self._cluster.close()
        self._client = self._cluster = None

    @property
    def slots(self) -> int:
        if self.jobs is not None:
            return self.jobs
        threads = sum(self._client.nthreads().values()) if self._client is not None else 0
        return max(threads, 1)

    def describe(self) -> str:
        where = self.scheduler or f"a local Dask cluster ({self.jobs or 2} workers)"
        return f"Dask: {where}"

    def submit(self, trial: dict, out: str):
        from ..runtime.compile_cache import cache_disabled

        assert self._client is not None, "DaskExecutor.submit needs a 'with' block"
        return self._client.submit(
            _execute_on_dask_worker, trial, out, not cache_disabled(),
            key=f"invsss-trial-{trial['id']}", pure=False,
        )

    def wait(self, futures, timeout: float):
        from distributed import wait

        try:
            return wait(list(futures), timeout=timeout, return_when="FIRST_COMPLETED").done
        except TimeoutError:
            return set()

    @staticmethod
    def outcome(future) -> dict:
        return future.result()


def make_executor(executor="local", jobs: int | None = None, scheduler: str | None = None):
    """An executor from its name, or ``executor`` itself if it is one already.

    ``jobs`` defaults to 1 for ``"local"`` (in this process), to 2 workers for a
    Dask ``LocalCluster``, and to the cluster's thread count with ``scheduler``.

    Examples
    --------
    >>> make_executor("local").jobs
    1
    >>> make_executor("slurm")
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: executor: expected one of local, dask, got 'slurm'
    """
    if not isinstance(executor, str):
        return executor
    if executor == "local":
        if scheduler is not None:
            raise InvalidInputError("--scheduler: only used with --executor dask")
        return LocalExecutor(1 if jobs is None else jobs)
    if executor == "dask":
        return DaskExecutor(scheduler, jobs)
    raise InvalidInputError(f"executor: expected one of {', '.join(EXECUTORS)}, got {executor!r}")
