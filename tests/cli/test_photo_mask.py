"""The face mask of a photograph from the command line: ``invsss fit`` makes it and
says so, never makes a silent estimate from a mask that is mostly background, and the
report draws the mask's note under the source."""

from __future__ import annotations

import io
import json
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest

import invsss
from invsss.cli import main
from invsss.io.skin_mask import skin_mask_from_pair
from tests.io._portraits import ASTRONAUT_FACE, astronaut, face_mask, iou


# The command line on a small crop of the astronaut: rows 0-320, columns 60-380, halved
# (160 x 160, the face about 45 px wide), the green channel as the source and the red
# one as the target.
CROP = (slice(0, 320), slice(60, 380))


@pytest.fixture(scope="module")
def crop_files(tmp_path_factory):
    from skimage.transform import downscale_local_mean

    folder = tmp_path_factory.mktemp("astronaut_crop")
    small = downscale_local_mean(astronaut()[CROP], (2, 2, 1)).astype(np.float32)
    files = {"green": folder / "green.exr", "red": folder / "red.exr"}
    invsss.write_image(files["green"], small[..., 1])
    invsss.write_image(files["red"], small[..., 0])
    old = skin_mask_from_pair(small[..., 1], small[..., 0])
    files["old"] = folder / "old.png"
    invsss.write_image(files["old"], old)
    most = np.zeros(small.shape[:2], np.float32)
    most[16:, :] = 1  # 90 % of the frame
    files["most"] = folder / "most.png"
    invsss.write_image(files["most"], most)
    files["truth"] = face_mask(ASTRONAUT_FACE, small.shape[:2], 0.5, (CROP[0].start, CROP[1].start))
    return files


def _fit(files, out, *extra):
    err = io.StringIO()
    with redirect_stderr(err), redirect_stdout(io.StringIO()):
        code = main(["fit", "--source", str(files["green"]), "--target", str(files["red"]),
                                "--distance", "600", "--starts", "1", *extra, "--out", str(out), "--no-cache"])
    assert code == 0, err.getvalue()
    return json.loads((out / "params.json").read_text()), err.getvalue()


@pytest.mark.slow
def test_the_command_line_makes_the_face_mask_of_a_photograph(crop_files, tmp_path):
    content, _ = _fit(crop_files, tmp_path / "o")
    record = content["inputs"]["pairs"][0]["mask"]
    assert record["method"] == "face" and record["checks"]["passed"] and record["notices"] == []
    made = invsss.read_mask(tmp_path / "o" / "mask_used.png")
    assert iou(made, crop_files["truth"]) >= 0.8
    assert not any("mask_used.png" in w for w in content["warnings"])


@pytest.mark.slow
@pytest.mark.parametrize("mask", ["old", "most"])
def test_a_mask_that_is_mostly_background_is_never_a_silent_estimate(crop_files, tmp_path, mask):
    """The dark-background rule's mask (97 % of this crop) and a mask of 90 % of the frame,
    given with --mask: whatever the fit determines, params.json's warnings, the mask's
    record and the command line all carry the notices."""
    content, err = _fit(crop_files, tmp_path / "o", "--mask", str(crop_files[mask]))
    record = content["inputs"]["pairs"][0]["mask"]
    assert not record["checks"]["passed"] and record["checks"]["skin_share"] < 0.5
    name = str(crop_files[mask])
    expected = [f"covers {record['checks']['coverage']:.0%} of the frame", "passes the skin test"]
    for phrase in expected:
        notice = [w for w in content["warnings"] if w.startswith(name) and phrase in w]
        assert len(notice) == 1, (phrase, content["warnings"])
        assert notice[0] in record["notices"] and f"invsss: warning: {notice[0]}" in err


@pytest.mark.slow
def test_the_report_draws_the_mask_note_under_the_source():
    from invsss.cli.report import report_figure

    rows, cols = np.mgrid[0:24, 0:24]
    source = 0.5 + 0.3 * np.sin(cols / 2.0) * np.cos(rows / 3.0)
    depth, mask = np.full((24, 24), 600.0), np.zeros((24, 24))
    mask[3:21, 3:21] = 1
    target = np.asarray(invsss.render(source, depth, mask, invsss.SSSParams(900.0, 0.0, 1.0, [1.0], [1.0])))
    fit = invsss.fit_pair(source, target, depth, mask, fix={"variances": [1.0]}, n_starts=1, max_steps=5)
    note = "mask: covers 95% of the frame, 12% skin"
    texts = [t.get_text() for ax in report_figure(fit, [(source, target, depth, mask)], [note]).axes
             for t in ax.texts]
    assert note in texts
    plain = [t.get_text() for ax in report_figure(fit, [(source, target, depth, mask)]).axes for t in ax.texts]
    assert not any(t.startswith("mask:") for t in plain)
