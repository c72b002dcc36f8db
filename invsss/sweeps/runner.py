"""One trial from start to finish, in whichever process runs it: :func:`execute`.

The runner reads the pair(s), runs the task (:mod:`.tasks`), refuses a result
whose loss is not finite, and commits the trial's files to ``OUT/trials/<id>/``
through :class:`invsss.io.result_dir.ResultDir` (all files or none). Only then
does it return ``status: "done"``; the sweep marks the trial done in the
database after that, so a done row always has its files. The manifest of
those files holds the row the sweep records (``info.row``: the trial's
position, configuration, axes, attempt and outcome), from which
:func:`invsss.sweeps.store.rebuild` recovers a damaged database.
Any exception becomes ``status: "failed"`` with a one-line message: one bad
trial never ends a sweep.

:func:`execute` takes and returns plain dicts, so it can be sent to a process
pool or a Dask worker as it is. Each worker process keeps JAX's compiled
functions between calls: trials of the same shapes and options compile once
per worker.
"""

from __future__ import annotations

import dataclasses
import math
import os
import socket
import time
import warnings

from ..io.result_dir import ResultDir
from ..validation import error_line
from .tasks import TrialInterrupted, run_task
from .trials import Trial

__all__ = ["execute", "load_trial_pairs", "trial_folder"]


def trial_folder(out: str, trial_id: str) -> str:
    """Where a trial's files go: ``OUT/trials/<id>``."""
    return os.path.join(os.fspath(out), "trials", trial_id)


def load_trial_pairs(trial: Trial) -> list:
    """The trial's pairs read from its data folder: an :class:`~invsss.ImagePair` per
    pair, with the light buffers (normal, light, key, fill_light, thickness,
    key_irradiance) its light terms read."""
    from ..io import load_pair, read_image

    pairs = []
    for pair in trial.pairs:
        source, target, depth, mask = (
            os.path.join(trial.root, pair[role]) for role in ("source", "target", "depth", "mask")
        )
        data = load_pair(source, target, depth, mask, depth_scale=trial.depth_scale, linear_codes=trial.linear_codes)
        if trial.options.get("light_terms"):
            # Only a trial with light terms reads the buffers it uses; the fit checks
            # them. The key light's image is read as the source is (one channel for
            # a grey source stored as RGB, which load_pair read as one).
            grey = data.source.shape[-1] == 1
            read_as_source = ("key", "key_irradiance")
            buffers = {role: read_image(os.path.join(trial.root, pair[role]),
                                        linear=trial.linear_codes if role in read_as_source else True,
                                        grey=(grey and role in read_as_source) or role == "thickness")
                       for role in trial.buffer_roles if role in pair}
            # ImagePair keeps the NumPy arrays as given; its fields are annotated as jax Arrays.
            data = dataclasses.replace(data, **buffers)  # type: ignore[arg-type]
        pairs.append(data)
    return pairs


def _resolved(trial: Trial) -> dict:
    """The trial's options with ``saturation = "auto"`` replaced by its targets' clipping level."""
    if trial.options.get("saturation") != "auto":
        return trial.options
    from ..io import resolved_saturation

    targets = [os.path.join(trial.root, pair["target"]) for pair in trial.pairs]
    return {**trial.options, "saturation": resolved_saturation("auto", targets)}


def execute(trial: dict, out: str, stop=None) -> dict:
    """Run one trial (a :meth:`Trial.to_dict`) and commit its files under ``out``.

    Parameters
    ----------
    trial : dict
    out : str
        The sweep's output folder.
    stop : callable, optional
        Polled by a fit between solver steps; True abandons the trial
        (``status: "interrupted"``, nothing written).

    Returns
    -------
    dict
        ``id``, ``status`` (``"done"``, ``"failed"`` or ``"interrupted"``),
        ``params``, ``stderr``, ``metrics``, ``warnings``, ``error``,
        ``timings`` (seconds: ``load``, ``compute`` (the fit or render),
        ``write``, ``total``), ``host``, ``pid``, ``started``, ``finished``
        (Unix times).
    """
    started = time.time()
    trial = dict(trial)
    attempt = trial.pop("attempt", 1)  # the sweep's count of tries, this one included
    outcome = {
        "id": trial["id"], "status": "failed", "params": None, "stderr": None, "metrics": None,
        "warnings": [], "error": None, "timings": {}, "host": socket.gethostname(),
        "pid": os.getpid(), "started": started,
    }
    clock = time.perf_counter()
    timings = outcome["timings"]
    try:
        spec = Trial.from_dict(trial)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            pairs = load_trial_pairs(spec)
            options = _resolved(spec)
            timings["load"] = time.perf_counter() - clock
            clock = time.perf_counter()
            result = run_task(spec.task, options, pairs, stop)
            timings["compute"] = time.perf_counter() - clock
        notes = [" ".join(str(w.message).split()) for w in caught]
        outcome["warnings"] = list(dict.fromkeys(notes + result.warnings))
        loss = result.metrics.get("loss")
        if loss is None or not math.isfinite(loss):
            raise FloatingPointError(f"the loss is {loss if loss is not None else 'NaN'}; nothing written")
        clock = time.perf_counter()
        folder = trial_folder(out, spec.id)

        def info():
            # Called once the files are staged: the outcome is final, and goes
            # into the manifest as the row the sweep will record.
            timings["write"] = time.perf_counter() - clock
            outcome.update(params=result.params, stderr=result.stderr, metrics=result.metrics,
                           finished=time.time())
            timings["total"] = outcome["finished"] - started
            kept = {k: v for k, v in outcome.items() if k not in ("id", "status", "error")}
            row = {"id": spec.id, "position": spec.index, "task": spec.task, "config": spec.config,
                   "axes": spec.axes, "attempts": attempt, "outcome": kept}
            return {"trial": spec.id, "task": spec.task, "row": row}

        with ResultDir(folder, overwrite=True, names=list(result.files),
                       description=f"invsss sweep trial {spec.id}") as directory:
            directory.commit(result.files, info=info)
        outcome.update(status="done")
    except TrialInterrupted:
        outcome.update(status="interrupted", error="interrupted")
    except Exception as err:  # noqa: BLE001 -- any failure is the trial's, recorded, not raised
        outcome.update(params=None, stderr=None, metrics=None, error=error_line(err))
    if outcome["status"] != "done":  # a done trial's times were fixed when its files were
        outcome["finished"] = time.time()
        timings["total"] = outcome["finished"] - started
    return outcome
