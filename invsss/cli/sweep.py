"""``invsss sweep`` and ``invsss sweep-report``: experiment files run as resumable sweeps."""

from __future__ import annotations

import argparse
import os
import signal
import sys

from ..runtime.interrupts import StopSignals
from ..validation import InvalidInputError
from .arguments import add_no_cache_argument


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "sweep",
        help="run the trials of an experiment file (batch fits, render matrices, sweeps)",
        description="Expand EXPERIMENT.toml into trials and run those not yet done into DIR: "
        "DIR/results.sqlite (one row per trial) and DIR/trials/<id>/ (its files). Running the "
        "same command again resumes after a crash or Ctrl-C. Then see `invsss sweep-report DIR`.",
    )
    parser.add_argument("experiment", metavar="EXPERIMENT.toml", help="experiment file")
    parser.add_argument("--out", required=True, metavar="DIR", help="results folder (created if missing)")
    parser.add_argument("--executor", choices=("local", "dask"), default="local",
                        help="local: this process or a process pool (default); dask: a Dask cluster")
    parser.add_argument("--jobs", type=int, default=None, metavar="N",
                        help="local worker processes (default 1: this process), or the workers of "
                        "the Dask LocalCluster started without --scheduler (default 2)")
    parser.add_argument("--scheduler", default=None, metavar="ADDR",
                        help="address of a running Dask scheduler (tcp://host:8786)")
    parser.add_argument("--rebuild-store", action="store_true",
                        help="first make DIR/results.sqlite again from the trial folders DIR/trials/<id>/ "
                        "(after it was damaged; the old file is kept as results.sqlite.damaged-<time>), "
                        "then run the trials not done")
    parser.add_argument("--max-trials", type=int, default=None, metavar="N",
                        help="run an experiment of more trials than the limit "
                        "(default 100000; counted before they are expanded)")
    add_no_cache_argument(parser)
    parser.set_defaults(func=run)
    # `invsss sweep-report` is the sweep's other half: registered with it.
    add_report_parser(subparsers)


def run(args: argparse.Namespace, stop: StopSignals) -> int:
    from ..sweeps import load, run
    from ..sweeps.experiment import MAX_TRIALS

    limit = MAX_TRIALS if args.max_trials is None else args.max_trials
    if limit < 1:
        raise InvalidInputError(f"--max-trials: expected a whole number >= 1, got {limit}")
    experiment = load(args.experiment, max_trials=limit)

    def stopping(signum):
        print(f"invsss: {signal.Signals(signum).name}: no new trials will start; a fit running in "
              "this process stops at its next step, trials on workers finish; rerun to resume "
              "(send it again to quit now)", file=sys.stderr, flush=True)

    with stop.deferred(stopping):
        summary = run(experiment, args.out, executor=args.executor, jobs=args.jobs,
                      scheduler=args.scheduler, stop=stop,
                      rebuild_store=args.rebuild_store)
    _print_out(f"sweep: {summary.done} done, {summary.failed} failed, {summary.remaining} not run "
               f"({summary.ran} run now, {summary.seconds:.1f}s); report: invsss sweep-report {args.out}")
    if summary.interrupted:
        return stop.exit_status or 130
    # A script must see that some trials have no result; their errors are in the report.
    return 1 if summary.failed else 0


def add_report_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "sweep-report",
        help="tabulate and plot the results of a sweep",
        description="Print a table of the trials in DIR and write DIR/report/results.csv and "
        "PNG plots (metrics and fitted parameters against each axis; for a render sweep a "
        "contact sheet of the renders).",
    )
    parser.add_argument("out", metavar="DIR", help="a sweep's results folder")
    parser.add_argument("--no-plots", action="store_true", help="only the table and the CSV file")
    parser.add_argument("--parquet", action="store_true",
                        help="also write DIR/report/results.parquet (needs pandas and pyarrow)")
    parser.set_defaults(func=run_report)


def run_report(args: argparse.Namespace, stop: StopSignals) -> int:
    from ..sweeps.report import write_report

    table, written = write_report(args.out, plots=not args.no_plots, parquet=args.parquet)
    _print_out(table)
    _print_out(f"wrote {', '.join(written)}")
    return 0


def _print_out(text: str) -> None:
    """Print ``text`` on stdout; a reader that went away (``| head``) is not an error."""
    try:
        print(text, flush=True)
    except BrokenPipeError:
        # Later writes, and Python's own flush at exit, go nowhere instead of failing.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
