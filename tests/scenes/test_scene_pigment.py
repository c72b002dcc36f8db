"""The pigment layer of ``invsss scene`` (issue 33): a colour map's contrast on the skin's
surface, carried by the vertices of a finer copy of the mesh, in the path-traced target
(absorbed at each crossing of the surface) and in the Lambertian source (its albedo map)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import invsss
from invsss.scenes import parse_config
from invsss.scenes.config import Pigment
from tests import ROOT

pytest.importorskip("mitsuba")
pytest.importorskip("trimesh")

REPO = ROOT
MESHES = REPO / "experiments" / "scenes" / "meshes"


def _config(strength: float, *, boundary: str = "index-matched", obj: dict | None = None) -> dict:
    return {
        "spp": 8, "geometry_spp": 4, "seed": 2, "max_depth": 32,
        "object": obj or {"mesh": str(MESHES / "LeePerrySmith.glb"), "mm_per_unit": 44.0,
                          "pigment": {"map": str(MESHES / "Map-COL.jpg"), "strength": strength, "subdivide": 0}},
        "camera": {"position": [0.0, 40.0, 600.0], "look_at": [0.0, 40.0, 0.0], "fov": 8.0, "width": 24, "height": 24},
        "lights": [{"type": "directional", "direction": [0.0, 0.0, -1.0], "irradiance": 3.0}],
        "medium": {"preset": "thesis-940", "boundary": boundary},
    }


def test_pigment_needs_a_mesh_and_an_index_matched_boundary():
    with pytest.raises(invsss.InvalidInputError, match="pigment: only for a mesh"):
        parse_config(_config(1.0, obj={"primitive": "sphere", "radius": 40.0,
                                       "pigment": {"map": "x.png"}}), "scene")
    with pytest.raises(invsss.InvalidInputError, match='needs medium.boundary = "index-matched"'):
        parse_config(_config(1.0, boundary="rough-dielectric"), "scene")


def test_the_pigmented_mesh_is_closed_and_holds_the_maps_contrast():
    from invsss.scenes.mitsuba_scene import pigmented_mesh

    pigment = Pigment(map=str(MESHES / "Map-COL.jpg"), strength=1.0, subdivide=1)
    vertices, faces, transmittance, info = pigmented_mesh(str(MESHES / "LeePerrySmith.glb"), pigment)
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert mesh.is_watertight and mesh.volume > 0
    # One split: four times the triangles, the same surface.
    assert len(faces) == 4 * 17684 and info["triangles"] == len(faces)
    assert np.all((transmittance >= 0) & (transmittance <= 1))
    # The map's contrast is there: dark pigment (eyebrows, lips) well below the bright skin.
    assert np.percentile(transmittance, 5) < 0.6 < 0.9 < np.percentile(transmittance, 95)
    # A smaller strength is the same pattern with less contrast: P ** 0.15.
    weak = pigmented_mesh(str(MESHES / "LeePerrySmith.glb"), pigment.model_copy(update={"strength": 0.15}))[2]
    np.testing.assert_allclose(weak, transmittance ** 0.15, rtol=1e-12)


@pytest.mark.slow
def test_the_pigment_darkens_source_and_target_alike_on_a_flat_lit_patch():
    """Rendered with and without contrast (strength 1 and 0), the source's ratio is the
    pigment's transmittance, and the target loses as much on average: the layer absorbs
    on the way in and out."""
    from invsss.scenes.path_tracing import render_scene

    with_pigment = render_scene(parse_config(_config(1.0), "scene"))
    without = render_scene(parse_config(_config(0.0), "scene"))
    skin = with_pigment.mask > 0.5
    source_ratio = (with_pigment.source[..., 0] / np.maximum(without.source[..., 0], 1e-9))[skin]
    target_ratio = (with_pigment.target[..., 0] / np.maximum(without.target[..., 0], 1e-9))[skin]
    assert source_ratio.max() <= 1.0 + 1e-3 and source_ratio.min() < 0.8
    # On average the layer takes as much from the target (t on the way in, t on the way
    # out, at nearby points) as the albedo map takes from the source (t^2 at one point).
    assert np.mean(target_ratio) < 0.95 and np.mean(target_ratio) == pytest.approx(np.mean(source_ratio), abs=0.05)
    assert json.loads(json.dumps(with_pigment.info["mesh"]))["pigment"]["strength"] == 1.0


@pytest.mark.parametrize("half, config_file", [("visible", "face_twowave_visible.toml"), ("nir", "face_twowave_940.toml")])
def test_the_bundled_two_wavelength_pair_is_what_its_scene_files_say(half, config_file, monkeypatch):
    import hashlib

    from invsss.scenes import load_config

    folder = REPO / "data_synthetic" / "twowave_face" / half
    info = json.loads((folder / "scene.json").read_text())
    monkeypatch.chdir(REPO)
    config = load_config(Path("experiments") / "scenes" / config_file).model_dump()
    config["object"]["mesh"] = str(Path(config["object"]["mesh"]).relative_to(REPO))
    config["object"]["pigment"]["map"] = str(Path(config["object"]["pigment"]["map"]).relative_to(REPO))
    assert parse_config(info["config"], "scene.json").model_dump() == config
    assert info["mesh"]["pigment"]["sha256"] == hashlib.sha256((MESHES / "Map-COL.jpg").read_bytes()).hexdigest()
    # One camera: both halves see the same skin on the same pixels.
    other = REPO / "data_synthetic" / "twowave_face" / ("nir" if half == "visible" else "visible")
    np.testing.assert_array_equal(invsss.read_mask(folder / "mask.png"), invsss.read_mask(other / "mask.png"))
    np.testing.assert_array_equal(invsss.read_depth(folder / "depth.exr"), invsss.read_depth(other / "depth.exr"))
    assert info["noise"]["noise_ceiling_db"] > 30.0
