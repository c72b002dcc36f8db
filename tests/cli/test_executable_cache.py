"""An executable-cache entry that crashes its loader is tried in a separate process
first; the time that costs is what the command line's progress reports."""

from __future__ import annotations

import os
import pickle

import pytest

from tests.runtime._executables import Bomb, call, entry_files, sealed
from tests.runtime._executables import cache_dir  # noqa: F401 (fixture)


@pytest.mark.slow
def test_an_entry_that_crashes_its_loader_is_tried_in_a_separate_process_first(cache_dir):
    # Bytes that were wrong when written pass their checksum: such an entry (here
    # a pickle that aborts the process loading it, as a flipped bit in compiled
    # code did) must not take this process down.
    cache = cache_dir()
    call()
    (entry,) = entry_files(cache)
    entry.write_bytes(sealed(pickle.dumps(Bomb(os.abort))))
    out, traces, warned = call()
    assert out == [0.0, 2.0, 4.0, 6.0] and traces == 1
    assert len(warned) == 1, warned
    assert f"executable cache: {entry.name} failed when a separate process tried it" in warned[0]
    assert "SIGABRT" in warned[0]
    # Replaced by the compilation; tried once more in a child, then recorded as tried.
    from invsss.cli.progress import trial_seconds

    before = trial_seconds()
    assert call()[1:] == (0, [])
    assert entry.with_suffix(".verified").is_file()
    tried = trial_seconds() - before
    assert tried > 0.1  # the child's time, as the command line reports it
    assert call()[1:] == (0, [])
    assert trial_seconds() - before == tried  # a verified entry is not tried again
