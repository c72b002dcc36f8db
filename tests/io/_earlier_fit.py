"""An earlier fit's result folder and the disc mask of its photographs, for the tests of
the inputs a result keeps (tests/cli/test_photo_inputs_kept.py) and of the protocol itself
(tests/io/test_result_dir.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

import invsss
from invsss.io.photo_pair import MASK_FILE
from invsss.io.result_dir import MANIFEST_NAME, ResultDir

SIZE = 48
FIT_FILES = ("params.json", "fit.exr", "report.png")


def disc_mask() -> np.ndarray:
    """A face-sized ellipse of ones in a SIZE x SIZE frame."""
    y, x = np.mgrid[0:SIZE, 0:SIZE].astype(np.float64)
    return (((x - 23.5) / 18.0) ** 2 + ((y - 24.0) / 20.0) ** 2 < 1.0).astype(np.float64)


def earlier_fit(out: Path, files=FIT_FILES + (MASK_FILE,)) -> None:
    """A folder holding an earlier fit's result: its files, committed as `invsss fit` commits them."""
    def writer(name):
        if name == MASK_FILE:
            return lambda path: invsss.write_image(path, disc_mask().astype(np.float32))
        return lambda path: Path(path).write_text(f"earlier {name}")

    with ResultDir(out, names=files) as folder:
        folder.commit({name: writer(name) for name in files}, {"command": "fit"})


def listed(out: Path) -> list[str]:
    """The files the result's manifest lists."""
    return json.loads((out / MANIFEST_NAME).read_text())["files"]
