"""The clipped card of tests/forward/_clipped_card.py as files, for the saturation tests
of the command line and of sweeps."""

from __future__ import annotations

import json

import numpy as np

import invsss
from tests.forward._clipped_card import PROFILE, clipped_card
from tests.io._pair_files import write_pair


def card_on_disk(folder, target_ext: str):
    """The clipped card as files, its target exposed so the clipping level is the top code."""
    source, target, depth, mask, level = clipped_card()
    paths = write_pair(folder, "card", (source, target / level, depth, mask))
    if target_ext != ".exr":
        paths["target"] = folder / f"card_target{target_ext}"
        invsss.write_image(paths["target"], np.asarray(target / level, np.float32), bits=16)
    profile = folder / "profile.json"
    profile.write_text(json.dumps(PROFILE))
    return paths, profile
