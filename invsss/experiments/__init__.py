"""The old name of :mod:`invsss.sweeps`, kept working for one release.

``import invsss.experiments`` and ``from invsss.experiments.store import
rebuild`` give the modules of :mod:`invsss.sweeps` themselves (the same module
objects, so their classes and results are the same), with a
:class:`DeprecationWarning` at the first import. The name clashed with the
repository's ``experiments/`` folder of scripts.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

warnings.warn(
    "invsss.experiments is now invsss.sweeps; the old name will be removed in the next release",
    DeprecationWarning,
    stacklevel=2,
)

from ..sweeps import *  # noqa: E402, F403 - the old name's public names
from ..sweeps import __all__  # noqa: E402, F401

_NEW = "invsss.sweeps"


class _Alias(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports ``invsss.experiments.X`` as the module ``invsss.sweeps.X``."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname.startswith(__name__ + "."):
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def __init__(self):
        self.specs = {}

    def create_module(self, spec):
        module = importlib.import_module(_NEW + spec.name[len(__name__):])
        self.specs[spec.name] = module.__spec__
        return module

    def exec_module(self, module):
        # The import system gave the module the alias's spec; it keeps its own.
        module.__spec__ = self.specs.pop(module.__spec__.name)


if not any(isinstance(finder, _Alias) for finder in sys.meta_path):
    sys.meta_path.insert(0, _Alias())
