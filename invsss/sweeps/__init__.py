"""Experiments from files: batch fits, render matrices and hyperparameter sweeps.

An experiment file (TOML) names the data, the task (``fit``, ``fit-joint`` or
``render``), a base configuration and the axes to vary; :func:`load` checks and
expands it into trials with stable ids, :func:`run` runs them (resumably, in
this process, a process pool or on Dask) into a results folder, and
:func:`results` reads that folder back. ``invsss sweep`` and ``invsss
sweep-report`` are the same from the command line.

Example (a notebook)::

    import invsss.sweeps as ex
    experiment = ex.load("experiments/render_matrix.toml")
    ex.run(experiment, "runs/render_matrix", jobs=2)
    table = ex.results("runs/render_matrix")      # a pandas DataFrame

The modules, one idea each:

* :mod:`.schema` -- the file's keys and types (pydantic), one-line errors;
* :mod:`.data` -- locating the pairs (folders, globs, file sets);
* :mod:`.axes` -- grid, zip and Sobol'/random points;
* :mod:`.trials` -- resolved trial configurations and their ids;
* :mod:`.experiment` -- :func:`load`;
* :mod:`.tasks`, :mod:`.scoring` -- what a trial computes;
* :mod:`.runner` -- one trial, start to committed files;
* :mod:`.store` -- the SQLite results database;
* :mod:`.executors` -- local process pool and Dask;
* :mod:`.sweep` -- :func:`run`;
* :mod:`.results` -- :func:`results`;
* :mod:`.report` -- table, CSV and plots of a finished sweep.
"""

from .executors import EXECUTORS, DaskExecutor, LocalExecutor
from .experiment import Experiment, load
from .results import results
from .sweep import SweepSummary, run
from .trials import Trial

__all__ = ["load", "run", "results", "Experiment", "Trial", "SweepSummary", "LocalExecutor",
           "DaskExecutor", "EXECUTORS"]
