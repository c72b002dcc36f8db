"""``invsss.experiments``, the sweep engine's old name, still imports for one
release: the same modules as ``invsss.sweeps``, with a DeprecationWarning."""

from __future__ import annotations

import subprocess
import sys

import pytest

SCRIPT = """
import warnings
warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught:
    import invsss.experiments as old
    from invsss.experiments.store import rebuild
    import invsss.experiments.schema as old_schema
import invsss.sweeps as new
import invsss.sweeps.schema, invsss.sweeps.store
assert old.load is new.load
assert rebuild is invsss.sweeps.store.rebuild
assert old_schema is invsss.sweeps.schema and old_schema.__spec__.name == "invsss.sweeps.schema"
deprecations = [w for w in caught if issubclass(w.category, DeprecationWarning) and "invsss.sweeps" in str(w.message)]
assert len(deprecations) == 1, [str(w.message) for w in caught]
print("ok")
"""


@pytest.mark.slow
def test_the_old_import_path_gives_the_same_modules_with_a_warning():
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ok"
