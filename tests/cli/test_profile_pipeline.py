"""``invsss profile`` from spot photographs feeds ``invsss fit``: the profile file it
writes is one the fit takes."""

from __future__ import annotations

import json

import numpy as np
import pytest

import invsss
from invsss.cli import main
from tests.forward._spot_slab import MEDIA, PITCH, spot_images


@pytest.mark.slow
def test_cli_profile_feeds_fit(tmp_path, capsys):
    skin, reference = spot_images(*MEDIA[0])
    invsss.write_image(tmp_path / "skin.exr", skin.astype(np.float32))
    invsss.write_image(tmp_path / "ref.exr", reference.astype(np.float32))
    out = tmp_path / "profile.json"
    code = main(["profile", str(tmp_path / "skin.exr"), str(tmp_path / "ref.exr"),
                 "--mm-per-pixel", str(PITCH), "--filter-factor", "1", "--max-radius-mm", "8",
                 "--lit-radius-mm", "1.5",
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    written = json.loads(out.read_text())
    dipole = written["fit"]["dipole"]
    # One channel (read_image gives (H, W, 1)): one value per channel.
    assert abs(dipole["sigma_s_prime"][0] / MEDIA[0][0] - 1) < 0.10
    assert abs(dipole["sigma_a"][0] / MEDIA[0][1] - 1) < 0.10
    profile = invsss.load_profile(out)  # what `invsss fit --profile` reads
    assert profile.num_gaussians == 3
    # The profile's total reflectance is the dipole's (the measurement is absolute).
    total = float(np.sum(profile.total_reflectance()))
    expected = float(invsss.jensen_dipole_total(*MEDIA[0]))
    assert abs(total / expected - 1) < 0.15

    # A second run into the same file is refused without --overwrite, and replaces it with it.
    again = [str(tmp_path / "skin.exr"), str(tmp_path / "ref.exr"), "--mm-per-pixel", str(PITCH),
             "--filter-factor", "1", "--max-radius-mm", "8", "--lit-radius-mm", "1.5", "--out", str(out)]
    out.write_text("{}")
    assert main(["profile", *again]) == 2
    assert "already exists; pass --overwrite to replace it" in capsys.readouterr().err
    assert main(["profile", *again, "--overwrite"]) == 0
    assert json.loads(out.read_text())["fit"]["dipole"] == dipole
    # A missing file is one line naming it.
    assert main(["profile", str(tmp_path / "nope.exr"), str(tmp_path / "ref.exr"),
                 "--mm-per-pixel", "0.1", "--out", str(tmp_path / "p2.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert "nope.exr" in err and "\n" not in err


@pytest.mark.parametrize("case", ["exists", "an input", "a folder"])
def test_profile_refuses_an_out_it_may_not_write_before_reading(tmp_path, capsys, case):
    skin = tmp_path / "skin.exr"
    skin.write_text("not read: the refusal comes first")
    out = {"exists": tmp_path / "p.json", "an input": skin, "a folder": tmp_path}[case]
    if case == "exists":
        out.write_text("{}")
    extra = ["--overwrite"] if case == "a folder" else []  # an input is refused with or without it
    assert main(["profile", str(skin), str(tmp_path / "ref.exr"), "--mm-per-pixel", "0.1", "--out", str(out),
                 *extra]) == 2
    err = capsys.readouterr().err.strip()
    expected = {"exists": "already exists; pass --overwrite to replace it",
                "an input": "is the input SKIN of this run; choose another --out",
                "a folder": "is a folder, in the way of the profile JSON"}[case]
    assert err.startswith(f"invsss: error: {out}: ") and expected in err and "\n" not in err, err
