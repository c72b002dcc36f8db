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

A database that fails SQLite's integrity check, is not a database, or is empty
(0 bytes, or missing) while ``OUT/trials/`` holds trial results, is refused
with :class:`StoreError` (one line naming the file and what to do) before
anything is written to it; so is any SQLite error later (a full disk). Every
done trial's row is also kept in its folder's manifest (:mod:`.runner`), from
which :func:`rebuild` makes the table again.
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import json
import math
import os
import sqlite3
import time

from ..validation import InvalidInputError

__all__ = ["DATABASE_NAME", "ResultsStore", "STATUSES", "StoreError", "rebuild"]

#: The database's file name inside the sweep's output folder.
DATABASE_NAME = "results.sqlite"
#: The file a running sweep holds an exclusive ``flock`` on (:mod:`.sweep`).
LOCK_NAME = ".sweep.lock"

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

#: For tests: a page count at which the database is full (SQLITE_FULL), as on a full disk.
_MAX_PAGES_ENV = "INVSSS_TEST_MAX_DB_PAGES"

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


class StoreError(InvalidInputError):
    """The results database cannot be used: damaged, empty while trial results
    exist, or not writable (a full disk). The message is one line naming the
    file and what to do."""


#: How a message tells the user to rebuild the table from the trial folders.
def _rebuild_hint(directory: str) -> str:
    return (f"rebuild it from {os.path.join(directory, 'trials')} with `invsss sweep EXPERIMENT.toml "
            f"--out {directory} --rebuild-store`")


def _trial_results(directory: str) -> int:
    """How many trial folders under ``directory/trials`` hold a result (a manifest)."""
    trials = os.path.join(directory, "trials")
    try:
        names = os.listdir(trials)
    except OSError:
        return 0
    return sum(os.path.isfile(os.path.join(trials, name, "invsss-manifest.json")) for name in names)


def _store_error(path: str, err: sqlite3.Error) -> StoreError:
    directory = os.path.dirname(path)
    reason = " ".join(str(err).split()) or type(err).__name__
    name = getattr(err, "sqlite_errorname", "")
    if name == "SQLITE_FULL" or (name.startswith("SQLITE_IOERR") and _disk_full(directory)):
        # (On a full disk SQLite often says "disk I/O error": its shared-memory file cannot grow.)
        said = reason if name == "SQLITE_FULL" else f"{reason}: the disk is full"
        return StoreError(f"{path}: cannot write ({said}); free some space, then run the same command "
                          "again to resume")
    if name.startswith("SQLITE_IOERR"):
        return StoreError(f"{path}: cannot read or write ({reason}); once the disk is usable, run the same "
                          "command again to resume")
    if name in ("SQLITE_CORRUPT", "SQLITE_NOTADB") or not isinstance(err, sqlite3.OperationalError):
        return StoreError(f"{path}: damaged ({reason}); {_rebuild_hint(directory)}")
    return StoreError(f"{path}: {reason}")


def _disk_full(directory: str) -> bool:
    try:
        return os.statvfs(directory or ".").f_bavail == 0
    except OSError:
        return False


def _guarded(method):
    """Any SQLite error in ``method`` becomes one :class:`StoreError` line."""

    @functools.wraps(method)
    def guarded(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except sqlite3.Error as err:
            raise _store_error(self.path, err) from None

    return guarded


def sweep_running(out) -> bool:
    """Whether a sweep holds ``out`` now: a trial marked ``running`` without one
    was left so by a sweep that was killed, and runs again when it is resumed."""
    try:
        fd = os.open(os.path.join(os.fspath(out), LOCK_NAME), os.O_RDONLY)
    except OSError:
        return False
    try:
        # A shared lock is refused while the sweep holds its exclusive one; held
        # only for this call, so a sweep starting now is not kept out.
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)
    return False


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

    def __init__(self, directory, *, readonly: bool = False, rebuilding: bool = False):
        self.directory = os.fspath(directory)
        self.path = os.path.join(self.directory, DATABASE_NAME)
        self._db: sqlite3.Connection | None = None
        try:
            self._open(readonly, rebuilding)
        except sqlite3.Error as err:
            self.close()
            raise _store_error(self.path, err) from None
        except StoreError:
            self.close()
            raise

    def _open(self, readonly: bool, rebuilding: bool) -> None:
        existed = os.path.exists(self.path)
        if readonly:
            self._db = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True, timeout=30.0)
        else:
            self._db = sqlite3.connect(self.path, timeout=30.0)
        # Before anything is written: a damaged file is reported, never built upon.
        check = self._db.execute("PRAGMA quick_check").fetchone()[0]
        if check != "ok":
            raise StoreError(f"{self.path}: damaged (fails SQLite's integrity check: "
                             f"{' '.join(check.split())[:80]}); {_rebuild_hint(self.directory)}")
        tables = {row[0] for row in self._db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if "trials" not in tables:
            found = 0 if rebuilding else _trial_results(self.directory)
            if readonly or found:
                what = "empty (no trials table)" if existed else "missing"
                if not existed:
                    self.close()
                    with contextlib.suppress(OSError):
                        os.remove(self.path)  # made by connecting just now
                held = (f", but {os.path.join(self.directory, 'trials')} holds {found} trial results"
                        if found else "")
                raise StoreError(f"{self.path}: {what}{held}; {_rebuild_hint(self.directory)}")
        if not readonly:
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=FULL")
            with self._db:
                self._db.executescript(_SCHEMA)
            pages = os.environ.get(_MAX_PAGES_ENV)
            if pages:  # for tests: a database this many pages long is full
                self._db.execute(f"PRAGMA max_page_count = {int(pages)}")

    def close(self) -> None:
        if self._db is not None:
            self._db.close()
            self._db = None

    @property
    def _open_db(self) -> sqlite3.Connection:
        """The connection; a store is used only between opening and :meth:`close`."""
        assert self._db is not None, f"{self.path}: the results store is closed"
        return self._db

    def __enter__(self) -> ResultsStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @_guarded
    def set_meta(self, **values) -> None:
        with self._open_db:
            self._open_db.executemany(
                "INSERT INTO meta (key, value) VALUES (?, ?) ON CONFLICT(key) DO UPDATE SET value = excluded.value",
                [(k, json.dumps(v)) for k, v in values.items()],
            )

    def meta(self) -> dict:
        try:
            rows = self._open_db.execute("SELECT key, value FROM meta").fetchall()
        except sqlite3.OperationalError:
            return {}
        return {k: json.loads(v) for k, v in rows}

    @_guarded
    def add(self, trials) -> int:
        """Insert trials not in the database yet, as ``pending``; return how many were new.

        ``trials`` are mappings with ``id``, ``index``, ``task``, ``config``, ``axes``.
        Known ids keep their row (and status): that is what resuming means.
        """
        with self._open_db:
            before = self._open_db.total_changes
            self._open_db.executemany(
                "INSERT OR IGNORE INTO trials (id, position, task, config, axes, status) "
                "VALUES (?, ?, ?, ?, ?, 'pending')",
                [(t["id"], t["index"], t["task"], _dumps(t["config"]), _dumps(t["axes"])) for t in trials],
            )
            return self._open_db.total_changes - before

    @_guarded
    def to_run(self, ids) -> list[str]:
        """The ids among ``ids`` that are not ``done``, in the given order."""
        done = {row[0] for row in self._open_db.execute("SELECT id FROM trials WHERE status = 'done'")}
        return [i for i in ids if i not in done]

    @_guarded
    def mark_running(self, trial_id: str) -> int:
        """Mark a trial running; return its attempts so far, this one included."""
        with self._open_db:
            self._open_db.execute(
                "UPDATE trials SET status = 'running', attempts = attempts + 1 WHERE id = ?", (trial_id,)
            )
        row = self._open_db.execute("SELECT attempts FROM trials WHERE id = ?", (trial_id,)).fetchone()
        return row[0] if row else 1

    @_guarded
    def mark_pending(self, trial_ids) -> None:
        """Give abandoned trials back (an interrupted sweep): they run next time."""
        with self._open_db:
            self._open_db.executemany(
                "UPDATE trials SET status = 'pending' WHERE id = ? AND status = 'running'",
                [(i,) for i in trial_ids],
            )

    @_guarded
    def record(self, outcome: dict) -> None:
        """Store a finished trial's outcome (see :func:`.runner.execute`); with
        ``attempts`` in ``outcome``, that count too (a rebuilt row)."""
        with self._open_db:
            self._open_db.execute(
                "UPDATE trials SET status = ?, params = ?, stderr = ?, metrics = ?, warnings = ?, "
                "timings = ?, host = ?, pid = ?, started = ?, finished = ?, error = ?, "
                "attempts = COALESCE(?, attempts) WHERE id = ?",
                (
                    outcome["status"], _dumps(outcome.get("params")), _dumps(outcome.get("stderr")),
                    _dumps(outcome.get("metrics")), _dumps(outcome.get("warnings")),
                    _dumps(outcome.get("timings")), outcome.get("host"), outcome.get("pid"),
                    outcome.get("started"), outcome.get("finished"), outcome.get("error"),
                    outcome.get("attempts"), outcome["id"],
                ),
            )

    @_guarded
    def counts(self, ids=None) -> dict:
        """``{status: count}`` over ``ids`` (default: every row)."""
        rows = self._open_db.execute("SELECT id, status FROM trials").fetchall()
        wanted = None if ids is None else set(ids)
        counts = dict.fromkeys(STATUSES, 0)
        for trial_id, status in rows:
            if wanted is None or trial_id in wanted:
                counts[status] += 1
        return counts

    @_guarded
    def rows(self) -> list[dict]:
        """Every trial as a dict, JSON columns decoded, in expansion order."""
        cursor = self._open_db.execute("SELECT * FROM trials ORDER BY position, id")
        names = [d[0] for d in cursor.description]
        rows = []
        for values in cursor.fetchall():
            row = dict(zip(names, values))
            for key in _JSON_COLUMNS:
                row[key] = None if row[key] is None else json.loads(row[key])
            rows.append(row)
        return rows


def rebuild(directory, experiment=None) -> tuple[int, int]:
    """Make ``directory/results.sqlite`` again from the trial folders ``directory/trials/<id>/``.

    The database now there (damaged, empty or whole) is moved aside to
    ``results.sqlite.damaged-<time>`` (with its ``-wal`` and ``-shm`` files),
    never deleted. Each trial folder whose manifest is complete and holds the
    trial's row (:mod:`.runner` puts it there) becomes a ``done`` row, exactly
    as it was recorded; the trials of ``experiment`` (an
    :class:`~invsss.sweeps.Experiment`) that have no such folder are
    added as ``pending``, as are trials that had failed (they have no files;
    a sweep runs them again either way). The caller holds the sweep's lock.

    Returns
    -------
    (int, int)
        Rows recovered from trial folders, and trial folders left out (no
        complete manifest with a row: an interrupted write, or an invsss older
        than this; their trials run again).
    """
    directory = os.fspath(directory)
    path = os.path.join(directory, DATABASE_NAME)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    for suffix in ("", "-wal", "-shm"):
        if os.path.exists(path + suffix):
            os.replace(path + suffix, f"{path}.damaged-{stamp}{suffix}")
    recovered, left_out = [], 0
    trials = os.path.join(directory, "trials")
    for name in sorted(os.listdir(trials)) if os.path.isdir(trials) else ():
        try:
            with open(os.path.join(trials, name, "invsss-manifest.json"), encoding="utf-8") as file:
                manifest = json.load(file)
            row = manifest["info"]["row"]
            ok = manifest.get("state") == "complete" and row["id"] == name
        except (OSError, ValueError, KeyError, TypeError):
            ok = False
        if ok:
            recovered.append(row)
        elif os.path.isdir(os.path.join(trials, name)):
            left_out += 1
    with ResultsStore(directory, rebuilding=True) as store:
        if experiment is not None:
            store.set_meta(name=experiment.name, task=experiment.task, path=experiment.path,
                           axes=list(experiment.axes), text=experiment.text)
            store.add([{**t.to_dict(), "config": t.config} for t in experiment.trials])
        store.add([{**row, "index": row["position"]} for row in recovered])
        for row in recovered:
            store.record({**row["outcome"], "id": row["id"], "status": "done", "error": None,
                          "attempts": row["attempts"]})
    return len(recovered), left_out
