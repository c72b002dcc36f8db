"""A sweep's results store (invsss.sweeps.store): it is checked before anything is
written to it, and a trial left running by a dead sweep reads as interrupted. (A
damaged, rebuilt or full store from the command line: tests/cli/test_sweep_store.py.)"""

from __future__ import annotations

import sqlite3

import pytest

import invsss
from invsss.sweeps.store import DATABASE_NAME, ResultsStore


def test_the_store_is_checked_before_anything_is_written_to_it(tmp_path):
    (tmp_path / DATABASE_NAME).write_bytes(b"not a database at all" * 300)
    with pytest.raises(invsss.InvalidInputError, match="damaged .*--rebuild-store"):
        ResultsStore(tmp_path)
    assert (tmp_path / DATABASE_NAME).read_bytes() == b"not a database at all" * 300
    assert not (tmp_path / f"{DATABASE_NAME}-wal").exists()
    with pytest.raises(sqlite3.DatabaseError):  # (what the check stands in front of)
        sqlite3.connect(tmp_path / DATABASE_NAME).execute("SELECT * FROM sqlite_master").fetchall()


def test_a_trial_left_running_by_a_dead_sweep_reads_as_interrupted(tmp_path):
    from invsss.sweeps.results import flat_rows
    from invsss.sweeps.store import ResultsStore
    from invsss.sweeps.sweep import SweepLock

    with ResultsStore(tmp_path) as store:
        store.add([{"id": "abc", "index": 0, "task": "render", "config": {}, "axes": {"x": 1}}])
        store.mark_running("abc")
    # No sweep holds the folder (killed, or its lock file never made): nothing runs it.
    assert [r["status"] for r in flat_rows(tmp_path)[0]] == ["interrupted"]
    with SweepLock(str(tmp_path)):
        assert [r["status"] for r in flat_rows(tmp_path)[0]] == ["running"]
    assert [r["status"] for r in flat_rows(tmp_path)[0]] == ["interrupted"]
