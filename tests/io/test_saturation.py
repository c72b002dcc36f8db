"""The clipping level of a file (invsss.clipping_level): the top code of integer files,
as decoded, and none for float files."""

from __future__ import annotations

import numpy as np
import pytest

import invsss


@pytest.mark.filterwarnings("ignore::invsss.InputNotice")
def test_clipping_level_is_the_top_code_of_integer_files_only(tmp_path):
    image = np.full((4, 5), 0.25, np.float32)
    for name, bits in (("a.png", 8), ("b.png", 16), ("c.tif", 8)):
        invsss.write_image(tmp_path / name, image, bits=bits)
        assert invsss.clipping_level(tmp_path / name) == 1.0
        # The level is what the top code decodes to, whatever the decoding.
        invsss.write_image(tmp_path / name, np.ones((4, 5), np.float32), bits=bits)
        assert float(invsss.read_image(tmp_path / name).min()) == invsss.clipping_level(tmp_path / name)
    for name in ("d.exr", "e.tif"):
        invsss.write_image(tmp_path / name, image)
        assert invsss.clipping_level(tmp_path / name) is None
    np.save(tmp_path / "f.npy", image)
    assert invsss.clipping_level(tmp_path / "f.npy") is None
    with pytest.raises(invsss.InvalidInputError, match="g.png: image file not found"):
        invsss.clipping_level(tmp_path / "g.png")
