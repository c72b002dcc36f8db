"""The input notices a call raises, as text (the tests of masks and inputs in each layer)."""

from __future__ import annotations

import warnings

import invsss


def input_notices(func) -> list[str]:
    """The messages of the :class:`invsss.InputNotice` warnings ``func()`` raises."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        func()
    return [str(w.message) for w in caught if issubclass(w.category, invsss.InputNotice)]
