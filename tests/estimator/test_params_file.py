"""Text for a number is refused in memory as a params file refuses it: by SSSParams
and by FitOptions, each in one line."""

from __future__ import annotations

import pytest

import invsss
from invsss.validation import InvalidInputError


def test_text_for_a_number_is_refused_in_memory_as_in_a_file():
    # NumPy reads "600" as 600.0; a params file refuses text, and so do the objects.
    with pytest.raises(InvalidInputError, match=r"^sss_level: expected numbers, got the text '600'$"):
        invsss.SSSParams("600", 800.0, 0.5, [1.0], [1.0])
    with pytest.raises(InvalidInputError, match=r"^variances: expected numbers, got the text \['1'\]$"):
        invsss.SSSParams(600.0, 800.0, 0.5, [1.0], ["1"])
    with pytest.raises(InvalidInputError, match=r"^fix\['maxdd'\]: expected numbers, got the text '0.5'$"):
        invsss.FitOptions(fix={"maxdd": "0.5"})
    assert float(invsss.SSSParams(600, 800, 0.5, [1], [1]).sss_level) == 600.0  # integers are numbers
