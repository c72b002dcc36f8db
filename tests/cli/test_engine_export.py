"""What reaches an engine asset (issue 46): nothing the fit did not measure, and the depth unit it was measured in.

A ``burley`` fit's ``variances`` are Burley's ``d_c^2`` in the unit of the fit's depth.
``invsss export --format hdrp|unreal`` must refuse to write a ``d`` the fit held
(its start, a ``--fix``) or left undetermined unless told to mark it as assumed,
and must read the depth unit from the params file; ``render`` converts a depth in
another unit. (The conversion itself: tests/forward/test_engine_export.py.)
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import invsss
from invsss.cli import main
from invsss.io.engine_readings import hdrp_reading, unreal_reading

D = np.array([1.1, 0.55, 0.3])  # mm
BURLEY = {"sss_level": 800.0, "correction": 0.0, "maxdd": 1.0, "weights": [1.0, 1.0, 1.0],
          "variances": (D**2).tolist(), "model": "burley"}


def _file(tmp_path, **report):
    path = tmp_path / "params.json"
    invsss.write_params(path, {**BURLEY, **report})
    return path


def _export(path, *extra):
    return main(["export", str(path), "--format", "hdrp", *extra])


# ------------------------------------------------------------------ nothing unmeasured


@pytest.mark.parametrize("report, named", [
    # The default gauge before issue 46 held every d at the start.
    ({"fixed": {"variances": [0.576, 0.576, 0.576]}, "gauge": "variances", "converged": True},
     "held at 0.759, 0.759, 0.759 mm by the fit (gauge variances)"),
    ({"fixed": {"variances": (D**2).tolist(), "sss_level": 800.0}, "gauge": "sss_level"}, "(--fix)"),
    ({"undetermined": ["variances[2]"], "gauge": "depth",
      "estimate": {k: BURLEY[k] for k in ("sss_level", "correction", "maxdd", "weights", "variances")}},
     "variances[2]) was not determined"),
])
def test_an_unmeasured_distance_is_refused_in_one_line(tmp_path, capsys, report, named):
    path = _file(tmp_path, **report)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # read_params names the filled entries
        assert _export(path, "--out", str(tmp_path / "hdrp.json")) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and named in err and "--accept-assumed" in err
    assert not (tmp_path / "hdrp.json").exists()


def test_accept_assumed_writes_it_marked(tmp_path, capsys):
    path = _file(tmp_path, fixed={"variances": (D**2).tolist()}, gauge="variances")
    for fmt in ("hdrp", "unreal"):
        assert main(["export", str(path), "--format", fmt, "--accept-assumed"]) == 0
        out = json.loads(capsys.readouterr().out)
        assert "variances" in out["assumed"]
        assert any("ASSUMED" in why for why in out["undetermined"].values())


def test_a_measured_distance_exports_without_marks(tmp_path, capsys):
    stderr = {"sss_level": 2.0, "variances": [0.006, 0.001, 0.0004]}
    path = _file(tmp_path, fixed={}, gauge="depth", stderr=stderr, depth_unit="mm")
    assert _export(path) == 0
    out = json.loads(capsys.readouterr().out)
    assert "assumed" not in out
    np.testing.assert_allclose(hdrp_reading(out["fields"]), D, rtol=1e-12)


# ------------------------------------------------------------------ the depth unit


def test_export_reads_the_recorded_unit(tmp_path, capsys):
    # A fit on depth in cm: its d are in cm, and the asset must hold them in mm.
    path = _file(tmp_path, variances=((D / 10.0) ** 2).tolist(), depth_unit="cm")
    assert main(["export", str(path), "--format", "unreal", "--albedo", "0.9/0.5/0.4"]) == 0
    np.testing.assert_allclose(unreal_reading(json.loads(capsys.readouterr().out)["fields"]), D, rtol=1e-9)
    assert _export(path, "--mm-per-unit", "1") == 2
    err = capsys.readouterr().err
    assert "records depth_unit cm" in err and len(err.strip().splitlines()) == 1


def test_a_distance_no_skin_has_is_refused(tmp_path, capsys):
    # A fit on depth in metres that did not say so: d = 0.0011 "mm".
    path = _file(tmp_path, variances=((D / 1000.0) ** 2).tolist())
    assert _export(path) == 2
    err = capsys.readouterr().err
    assert "outside 0.01-50 mm" in err and "--depth-unit" in err


def test_render_converts_a_depth_in_another_unit(tmp_path, capsys):
    rng = np.random.default_rng(1)
    image = rng.uniform(0.1, 1.0, (16, 20, 3)).astype(np.float32)
    depth_mm = (500.0 + 2.0 * np.mgrid[0:16, 0:20][1]).astype(np.float32)
    files = {"image": tmp_path / "image.exr", "mask": tmp_path / "mask.png",
             "mm": tmp_path / "depth_mm.exr", "cm": tmp_path / "depth_cm.exr"}
    invsss.write_image(files["image"], image)
    invsss.write_image(files["mask"], np.ones((16, 20), np.float32))
    invsss.write_image(files["mm"], depth_mm)
    invsss.write_image(files["cm"], depth_mm / 10.0)
    params = tmp_path / "params.json"
    invsss.write_params(params, {"sss_level": 600.0, "correction": 0.0, "maxdd": 1.0, "weights": [1.0],
                                 "variances": [2.0], "depth_unit": "mm"})

    def render(depth, *extra):
        out = tmp_path / "out.exr"
        assert main(["render", "--image", str(files["image"]), "--depth", str(depth), "--mask",
                     str(files["mask"]), "--params", str(params), "--out", str(out), *extra]) == 0
        return invsss.read_image(out)

    reference = render(files["mm"])
    np.testing.assert_allclose(render(files["cm"], "--depth-unit", "cm"), reference, atol=1e-5)
    capsys.readouterr()
    render(files["cm"])  # the unit left out: rendered as mm, with a notice naming cm
    assert "--depth-unit cm" in capsys.readouterr().err


# ------------------------------------------------------------------ transmission (issue 48)


def test_a_fitted_transmission_reaches_hdrp_as_the_term_transmits(tmp_path, capsys):
    from invsss.forward.transmission import burley_transmittance
    from invsss.io.engine_readings import hdrp_transmittance, unreal_transmittance

    grey = {**BURLEY, "variances": [1.0, 1.0, 1.0]}  # d = 1 mm in every channel
    stderr = {"sss_level": 2.0, "variances": [0.01, 0.01, 0.01]}
    terms = {"transmission": [0.6], "thickness_scale": 0.3, "stderr": {"transmission": [0.02],
                                                                       "thickness_scale": 0.01}, "fixed": []}
    path = tmp_path / "params.json"
    invsss.write_params(path, {**grey, "fixed": {}, "gauge": "depth", "stderr": stderr, "depth_unit": "mm",
                               "light_terms": terms})
    assert main(["export", str(path), "--format", "hdrp", "--thickness-map-mm", "8"]) == 0
    out = json.loads(capsys.readouterr().out)
    fields = out["fields"]
    assert fields["transmissionMode"] == "ThinObject" and "transmissionTint" not in out["undetermined"]
    thickness = np.linspace(0.0, 8.0, 9)
    np.testing.assert_allclose(hdrp_transmittance(fields, thickness / 8.0)[:, 0],
                               0.6 * np.asarray(burley_transmittance(0.3 * thickness), np.float64), rtol=1e-6)
    # Without the map's convention, HDRP's default 5 mm, named as assumed.
    assert main(["export", str(path), "--format", "hdrp"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["fields"]["thicknessRemap"] == pytest.approx([0.0, 0.3 * 1.0 * 5.0]) and "thicknessRemap" in out[
        "undetermined"]

    # Unreal: the fields reach its reading as the term transmits where its table can follow
    # (WorldUnitScale 1 starts the table at 0.45 profile mm); the match range is named.
    assert main(["export", str(path), "--format", "unreal", "--world-scale", "1",
                 "--thickness-range-mm", "1,8"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["transmissionMatch"]["thicknessMm"] == [1.0, 8.0] and "TransmissionTintColor" not in out[
        "undetermined"]
    thickness = np.linspace(1.0, 8.0, 8)
    read = unreal_transmittance(out["fields"], thickness)[:, 0]
    np.testing.assert_allclose(read, 0.6 * np.asarray(burley_transmittance(0.3 * thickness)), rtol=0.03)
    # At Unreal's default WorldUnitScale the table starts 4.5 profile mm in: the asset says
    # how much of the fitted light Unreal renders, and that is what it reads.
    assert main(["export", str(path), "--format", "unreal"]) == 0
    out = json.loads(capsys.readouterr().out)
    why = out["undetermined"]["TransmissionTintColor"]
    low = min(lo for lo, _ in out["transmissionMatch"]["renderedOverFitted"])
    assert f"renders {low:.2f} of the fitted" in why and low < 0.5
    thickness = np.linspace(1.0, 10.0, 1000)
    ratio = unreal_transmittance(out["fields"], thickness)[:, 0] / (0.6 * np.asarray(burley_transmittance(
        0.3 * thickness)))
    assert ratio.min() == pytest.approx(low, rel=3e-3)
    assert main(["export", str(path), "--format", "unreal", "--thickness-range-mm", "5,2"]) == 2
    assert "--thickness-range-mm: expected LO,HI" in capsys.readouterr().err
