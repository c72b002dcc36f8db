"""One-line errors that name the file (issue 30, case 8): a result whose manifest is
garbled is damaged, not interrupted; `invsss profile` names the images it was given."""

from __future__ import annotations

import pytest

import invsss
from invsss.io.result_dir import MANIFEST_NAME, result_state
from invsss.validation import InvalidInputError
from tests.io._damaged_result import damaged_result


@pytest.fixture
def damaged(tmp_path):
    """A committed result whose manifest was then overwritten with text that is not JSON."""
    return damaged_result(tmp_path)


def test_a_garbled_manifest_is_damaged_not_interrupted(damaged):
    assert result_state(damaged) == "damaged"
    with pytest.raises(InvalidInputError) as caught:
        invsss.read_params(damaged / "params.json")
    message = str(caught.value)
    assert message == (f"{damaged / 'params.json'}: its result's manifest {damaged / MANIFEST_NAME} is "
                       "damaged (not a JSON object), so whether the result is whole is unknown; re-run it")
    assert "interrupted" not in message and "incomplete" not in message
