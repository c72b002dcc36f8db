"""The robust loss, not plain least squares, decides between the starts' basins, on a
photograph read from files: an 8-bit JPEG of the bundled fran_front target, on which
plain least squares prefers a basin with sss_level about 43 % high and a negative
weight, and the robust loss the one at the truth. The fit must end at the truth.
"""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

import invsss
from invsss.io import linear_to_srgb, srgb_to_linear
from tests import ROOT

PAIR = ROOT / "data_synthetic" / "fran_front"


def _jpeg(image: np.ndarray, quality: int) -> np.ndarray:
    """8-bit sRGB JPEG of a linear (H, W, 1) image, exposed so its 99.5th percentile is 0.9, decoded back."""
    scale = 0.9 / np.percentile(image, 99.5)
    codes = np.round(255 * linear_to_srgb(np.clip(image * scale, 0.0, 1.0))).astype(np.uint8)
    buffer = io.BytesIO()
    Image.fromarray(codes[..., 0]).save(buffer, format="JPEG", quality=quality)
    decoded = np.asarray(Image.open(io.BytesIO(buffer.getvalue())), np.float64) / 255.0
    return (srgb_to_linear(decoded) / scale)[..., None].astype(np.float32)


@pytest.mark.slow
def test_a_jpeg_photograph_is_fitted_in_the_robust_losss_basin():
    pair = invsss.load_pair(*(PAIR / name for name in ("source.exr", "target.exr", "depth.exr", "mask.png")))
    target = np.asarray(pair.target, np.float64)
    assert target.shape[-1] == 1
    clean = invsss.fit_pair(pair.source, pair.target, pair.depth, pair.mask, n_starts=2)
    photo = invsss.fit_pair(pair.source, _jpeg(target, 90), pair.depth, pair.mask, n_starts=2)
    for name in ("sss_level", "correction"):
        assert float(photo.values[name]) == pytest.approx(float(clean.values[name]), rel=0.05), name
    # The basin least squares preferred was carried through the robust rounds too.
    assert any(label.startswith("start ") and "robust" in label for label in photo.history_by_stage())
