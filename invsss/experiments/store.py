"""The results database of a sweep: ``OUT/results.sqlite``.

One table, ``trials``, one row per trial id (the primary key, so a trial can
never appear twice), holding its configuration (JSON), the values it varies,
its status and, once it has run, the fitted parameters, standard errors,
metrics, warnings, timings, host, process id and, for a failed trial, the
error. A ``meta`` table keeps the experiment file's text and name.

Statuses: ``pending`` (not run yet, or abandoned by an interrupted sweep),
``running``, ``done`` and ``failed``. A sweep runs every trial that is not
``done``: a trial left ``running`` by a killed sweep, or ``failed`` by an
earlier one, runs again. The sweep writes a row ``done`` only after the
trial's files are committed (:mod:`.runner`), so a killed sweep can leave
files without a done row (rerun and overwritten), never a done row without
files.

SQLite runs in WAL mode with full synchronisation: a reader (``invsss
sweep-report`` while a sweep runs) never blocks the sweep, and a committed
row survives the process being killed. Only the process that drives the sweep
writes; workers return their results to it.
"""

from __future__ import annotations

import json
import math
import os
import sqlite3

__all__ = ["DATABASE_NAME", "ResultsStore", "STATUSES"]

#: The database's file name inside the sweep's output folder.
DATABASE_NAME = "results.sqlite"

#: The statuses a trial can have.
STATUSES = ("pending", "running", "done", "failed")

_SCHEMA = """
CREATE TABLE IF NOT EXISTS trials (
    id TEXT PRIMARY KEY,
    position INTEGER NOT NULL,
    task TEXT NOT NULL,
    config TEXT NOT NULL,
    axes TEXT NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('pending', 'running', 'done', 'failed')),
    params TEXT,
    stderr TEXT,
    metrics TEXT,
    warnings TEXT,
    timings TEXT,
    host TEXT,
    pid INTEGER,
    started REAL,
    finished REAL,
    error TEXT,
    attempts INTEGER NOT NULL DEFAULT 0
);
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
"""

_JSON_COLUMNS = ("config", "axes", "params", "stderr", "metrics", "warnings", "timings")


def _finite(value):
    """``value`` with NaN and infinities as None: JSON has no such numbers (a perfect
    match's PSNR is infinite, the SSIM of a flat image undefined)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def _dumps(value) -> str | None:
    return None if value is None else json.dumps(_finite(value), sort_keys=True, allow_nan=False)


class ResultsStore:
    """The sweep's SQLite database (see the module docstring).

    Examples
    --------
    >>> import tempfile
    >>> store = ResultsStore(tempfile.mkdtemp())
    >>> store.add([{"id": "abc", "index": 0, "task": "render", "config": {}, "axes": {"x": 1}}])
    1
    >>> store.to_run(["abc"])
    ['abc']
    >>> store.record({"id": "abc", "status": "done", "metrics": {"loss": 0.5}})
    >>> store.to_run(["abc"]), store.rows()[0]["metrics"]
    ([], {'loss': 0.5})
    >>> store.close()
    """

    def __init__(self, directory, *, readonly: bool = False):
        self.path = os.path.join(os.fspath(directory), DATABASE_NAME)
        if readonly:
            self._db = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True, timeout=30.0)
        else:
            self._db = sqlite3.connect(self.path, timeout=30.0)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=FULL")
            with self._db:
                self._db.executescript(_SCHEMA)

    def close(self) -> None:
        self._db.close()

    def __enter__(self) -> "ResultsStore":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def set_meta(self, **values) -> None:
        with self._db:
            self._db.executemany(
                "INSERT INTO meta (key, value) VALUES (?, ?) ON CONFLICT(key) DO UPDATE SET value = excluded.value",
                [(k, json.dumps(v)) for k, v in values.items()],
            )

    def meta(self) -> dict:
        try:
            rows = self._db.execute("SELECT key, value FROM meta").fetchall()
        except sqlite3.OperationalError:
            return {}
        return {k: json.loads(v) for k, v in rows}

    def add(self, trials) -> int:
        """Insert trials not in the database yet, as ``pending``; return how many were new.

        ``trials`` are mappings with ``id``, ``index``, ``task``, ``config``, ``axes``.
        Known ids keep their row (and status): that is what resuming means.
        """
        with self._db:
            before = self._db.total_changes
            self._db.executemany(
                "INSERT OR IGNORE INTO trials (id, position, task, config, axes, status) "
                "VALUES (?, ?, ?, ?, ?, 'pending')",
                [(t["id"], t["index"], t["task"], _dumps(t["config"]), _dumps(t["axes"])) for t in trials],
            )
            return self._db.total_changes - before

    def to_run(self, ids) -> list[str]:
        """The ids among ``ids`` that are not ``done``, in the given order."""
        done = {row[0] for row in self._db.execute("SELECT id FROM trials WHERE status = 'done'")}
        return [i for i in ids if i not in done]

    def mark_running(self, trial_id: str) -> None:
        with self._db:
            self._db.execute(
                "UPDATE trials SET status = 'running', attempts = attempts + 1 WHERE id = ?", (trial_id,)
            )

    def mark_pending(self, trial_ids) -> None:
        """Give abandoned trials back (an interrupted sweep): they run next time."""
        with self._db:
            self._db.executemany(
                "UPDATE trials SET status = 'pending' WHERE id = ? AND status = 'running'",
                [(i,) for i in trial_ids],
            )

    def record(self, outcome: dict) -> None:
        """Store a finished trial's outcome (see :func:`.runner.execute`)."""
        with self._db:
            self._db.execute(
                "UPDATE trials SET status = ?, params = ?, stderr = ?, metrics = ?, warnings = ?, "
                "timings = ?, host = ?, pid = ?, started = ?, finished = ?, error = ? WHERE id = ?",
                (
                    outcome["status"], _dumps(outcome.get("params")), _dumps(outcome.get("stderr")),
                    _dumps(outcome.get("metrics")), _dumps(outcome.get("warnings")),
                    _dumps(outcome.get("timings")), outcome.get("host"), outcome.get("pid"),
                    outcome.get("started"), outcome.get("finished"), outcome.get("error"), outcome["id"],
                ),
            )

    def counts(self, ids=None) -> dict:
        """``{status: count}`` over ``ids`` (default: every row)."""
        rows = self._db.execute("SELECT id, status FROM trials").fetchall()
        wanted = None if ids is None else set(ids)
        counts = dict.fromkeys(STATUSES, 0)
        for trial_id, status in rows:
            if wanted is None or trial_id in wanted:
                counts[status] += 1
        return counts

    def rows(self) -> list[dict]:
        """Every trial as a dict, JSON columns decoded, in expansion order."""
        cursor = self._db.execute("SELECT * FROM trials ORDER BY position, id")
        names = [d[0] for d in cursor.description]
        rows = []
        for values in cursor.fetchall():
            row = dict(zip(names, values))
            for key in _JSON_COLUMNS:
                row[key] = None if row[key] is None else json.loads(row[key])
            rows.append(row)
        return rows
