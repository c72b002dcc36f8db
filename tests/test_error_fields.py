"""Errors carry the input they are about (``InvalidInputError.field``), and the
command line shows a flag or a file's path through that field, not the text."""

from __future__ import annotations

import numpy as np
import pytest

from invsss.cli import build_parser
from invsss.cli.fit import fit_options_from
from invsss.estimator.options import FitOptions
from invsss.validation import InvalidInputError, check_depth, check_mask, check_pair


@pytest.mark.parametrize("field, value", [
    ("saturation", -1.0), ("solver", "adam"), ("n_starts", 0), ("max_steps", True), ("canvas", (4,)),
    ("gauge", "nowhere"), ("focal_px", -3.0), ("pigment", 7), ("align", "warp"), ("vignetting", "yes"),
])
def test_each_bad_option_names_its_field(field, value):
    with pytest.raises(InvalidInputError) as caught:
        FitOptions(**{field: value})
    assert caught.value.field == field
    assert str(caught.value).startswith(field)


def test_pair_checks_name_the_role_in_the_field():
    with pytest.raises(InvalidInputError) as caught:
        check_mask(np.zeros((4, 4)), (4, 4), name="pairs[1].mask")
    assert caught.value.field == "pairs[1].mask"
    with pytest.raises(InvalidInputError) as caught:
        check_depth(np.full((4, 4), np.nan), (4, 4), name="depth")
    assert caught.value.field == "depth"
    image = np.ones((4, 4, 3))
    with pytest.raises(InvalidInputError) as caught:
        check_pair(image, np.ones((4, 5, 3)), np.ones((4, 4)), None, {"source": "source", "target": "target",
                                                                     "depth": "depth", "mask": "mask"})
    assert caught.value.field == "target"


def test_the_command_line_shows_the_flag_whatever_the_wording():
    args = build_parser().parse_args(["fit", "--source", "s.exr", "--target", "t.exr", "--depth", "d.exr",
                                     "--saturation", "-2", "--out", "x"])
    with pytest.raises(InvalidInputError) as caught:
        fit_options_from(args)
    assert str(caught.value).startswith("--saturation: ")
    assert caught.value.field == "saturation"
    # A message reworded so that it no longer starts with its field is still shown under the flag.
    reworded = InvalidInputError("the level must be above zero", field="saturation")
    assert str(reworded.named("--saturation")) == "--saturation: the level must be above zero"


def test_an_error_without_a_field_is_left_as_it_is():
    err = InvalidInputError("saturation: looks like a field but is not marked as one")
    assert err.named("--saturation") is err
    assert isinstance(err, ValueError)



def test_an_error_about_a_file_carries_its_path(tmp_path):
    from invsss.io import write_image

    missing = tmp_path / "no_such_folder" / "out.exr"
    with pytest.raises(InvalidInputError) as caught:
        write_image(str(missing), np.zeros((2, 2, 3), np.float32))
    assert caught.value.path == str(missing)
