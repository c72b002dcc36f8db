"""The fit's blur width from the command line: a real photograph's channel pair, whose
blur is under a pixel, says so at full and at half resolution."""

from __future__ import annotations

import io
import json
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest

from invsss.cli import main
from invsss.estimator.blur_width import RESOLVED_PX
from tests.io._pair_files import write_pair


def _half(a):
    return 0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2])


def _portrait(scale):
    """A real photograph (NASA's public-domain portrait in scikit-image) as a channel pair:
    green as the source, red as the target, with a face ellipse drawn by hand."""
    from skimage import data

    from invsss.io.colour import srgb_to_linear

    rgb = srgb_to_linear(data.astronaut()[30:230, 120:320].astype(np.float64) / 255.0)
    yy, xx = np.mgrid[0:200, 0:200]
    mask = (((xx - 102) / 45.0) ** 2 + ((yy - 95) / 58.0) ** 2 <= 1.0).astype(np.float64)
    source, target = rgb[..., 1:2], rgb[..., 0:1]
    for _ in range(scale // 2):
        source, target, mask = _half(source), _half(target), _half(mask)
    return source[..., 0], target[..., 0], mask


@pytest.mark.slow
def test_a_portraits_sub_pixel_blur_says_so_at_both_resolutions(tmp_path):
    # The photo route's defaults (one Gaussian): at 1.4 mm per pixel the extra red blur
    # is a third of a pixel; both fits must say it is not resolved.
    records = []
    for scale in (1, 2):
        source, target, mask = _portrait(scale)
        paths = write_pair(tmp_path, f"portrait{scale}", (source, target, np.full(mask.shape, 600.0), mask))
        out = tmp_path / f"fit{scale}"
        with redirect_stderr(io.StringIO()), redirect_stdout(io.StringIO()) as printed:
            code = main(["fit", "--source", str(paths["source"]), "--target", str(paths["target"]),
                         "--mask", str(paths["mask"]), "--distance", "600", "--starts", "2", "--out", str(out)])
        assert code == 0
        result = json.loads((out / "params.json").read_text())
        assert result["profile"] == "single" and "under a pixel" in printed.getvalue()
        assert any(w.startswith("blur:") and "under a pixel" in w for w in result["warnings"])
        records.append(result["blur"])
    assert all(not r["resolved"] and max(r["sigma_px"]) < RESOLVED_PX for r in records)
