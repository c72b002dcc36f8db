"""The bundled path-traced pairs (data_synthetic/pt_*) are what their scene files say.

These pairs are the project's stand-in for real photographs: targets made by a
volumetric path tracer, not by invsss's model. The tests check that each folder is
reproducible from its shipped scene description, that its noise is low enough to
measure the model against, that data_synthetic/SPLIT.toml puts each pair in the
tuning or the held-out part as docs/scenes.md says, that the set varies what it
claims to vary, and that a fit on one beats both the unscattered source and the
thesis's hand-set values (issue 7; the full table is experiments/fidelity.py).
"""

import json
import os

import numpy as np
import pytest

import invsss
from invsss.estimator.diagnostics import masked_psnr
from invsss.scenes import load_config, parse_config
from invsss.scenes.path_tracing import SCENE_FILES, light_directions
from invsss.scenes.split import read_split
from invsss.scenes.transmission import TRANSMISSION_FILES
from tests import ROOT

REPO = ROOT
DATA = REPO / "data_synthetic"
PAIRS = sorted(p.name for p in DATA.iterdir() if (p / "scene.json").is_file())
#: Folder name -> the scene description it was rendered from (experiments/make_synthetic.py).
CONFIGS = {"pt_face_940": "face_940.toml", "pt_face_940_turned": "face_940_turned.toml",
           "pt_face_skin1": "face_skin1.toml", "pt_proc_area_940": "proc_area_940.toml",
           "pt_face_ear_backlit_940": "face_ear_backlit_940.toml",
           "pt_fran_dir_940": "fran_dir_940.toml", "pt_fran_dir_rough_940": "fran_dir_rough_940.toml",
           "pt_proc_lowpoly_dir_940": "proc_lowpoly_dir_940.toml",
           "pt_face_rough_area_940": "face_rough_area_940.toml",
           "pt_fran_point_fill_940": "fran_point_fill_940.toml", "pt_proc_dir_fill_940": "proc_dir_fill_940.toml",
           "pt_proc_lowpoly_smooth_dir_940": "proc_lowpoly_smooth_dir_940.toml",
           "pt_fran_smooth_point_fill_940": "fran_smooth_point_fill_940.toml",
           "pt_face_rough_940": "face_rough_940.toml",
           "pt_face_ear_glow_940": "face_ear_glow_940.toml", "pt_proc_ear_glow_940": "proc_ear_glow_940.toml",
           "pt_face_nose_sidelit_940": "face_nose_sidelit_940.toml",
           "pt_face_nose_backlit_940": "face_nose_backlit_940.toml"}
#: The pairs bundled before the split (issue 29): every one of them is a tuning pair.
FIRST_PAIRS = ("pt_face_940", "pt_face_940_turned", "pt_face_skin1")
#: Each pair folder stays about as small as the first ones (about 500 KB; 800 KB at most,
#: raised from 600 KB when every folder gained fill_light.exr, a 3-channel float buffer of
#: about 110 KB, for the fill term; 1 MB at most, raised from 800 KB when the pairs rendered
#: for the transmission term gained thickness.exr, thickness_normal.exr and
#: key_irradiance.exr, three float buffers of about 165 KB together in pt_face_nose_sidelit_940,
#: which is 917 KB).
MAX_FOLDER_BYTES = 1_000_000
#: The lowest noise ceiling a rough-dielectric target may have: at 16384 spp about 28 dB
#: (docs/scenes.md); the first renders, at 2048 spp (21.4 and 21.7 dB), would fail.
ROUGH_MIN_CEILING_DB = 26.0
#: The same for an index-matched target (32 dB for pt_proc_area_940 at 1024 spp, 38-43 dB for the others).
INDEX_MATCHED_MIN_CEILING_DB = 30.0
#: The median skin value over the target's per-pixel noise, at least (either boundary).
MIN_MEDIAN_TO_NOISE = 8.0
#: Pairs made to show light that crossed a thin part (issue 48): most of their frame is lit
#: by the fill alone, darker than this allows (the median skin pixel 1.7, 3.4 and 6.5 times
#: the noise), so the median is taken where the key light arrives through at most
#: THIN_PART_MM of skin, the light those pairs are for (12, 45 and 10 times the noise).
TRANSMISSION_PAIRS = ("pt_face_ear_glow_940", "pt_proc_ear_glow_940", "pt_face_nose_backlit_940")
THIN_PART_MM = 10.0


def _info(name: str) -> dict:
    return json.loads((DATA / name / "scene.json").read_text())


def test_the_documented_path_traced_pairs_are_bundled():
    assert set(PAIRS) == set(CONFIGS)
    readme = (DATA / "README.md").read_text()
    docs = (REPO / "docs" / "scenes.md").read_text()
    split = read_split(DATA / "SPLIT.toml")
    for name in PAIRS:
        assert f"`{name}`" in readme and f"`{name}`" in docs
        # The README's table row names the pair's part of the split.
        row = next(line for line in readme.splitlines() if line.startswith(f"| `{name}` |"))
        assert row.split("|")[2].strip() == split[name]
    # One command remakes every pair: make_synthetic.py knows each of them.
    assert _make_synthetic().PATH_TRACED == CONFIGS


def _make_synthetic():
    """experiments/make_synthetic.py as a module."""
    import importlib.util
    import sys

    spec = importlib.util.spec_from_file_location("make_synthetic", REPO / "experiments" / "make_synthetic.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up while it loads
    try:
        spec.loader.exec_module(module)
    finally:
        del sys.modules[spec.name]
    return module


def test_split_puts_every_pair_in_one_part_and_holds_out_the_most_different():
    split = read_split(DATA / "SPLIT.toml")
    assert set(split) == set(PAIRS)
    tuning = [n for n in PAIRS if split[n] == "tuning"]
    held_out = [n for n in PAIRS if split[n] == "held-out"]
    assert all(split[n] == "tuning" for n in FIRST_PAIRS)
    assert len(held_out) >= 3 and len(PAIRS) >= 8

    def kinds(names, what):
        return {what(_info(n)) for n in names}

    key = lambda info: info["config"]["lights"][0]["type"]  # noqa: E731
    boundary = lambda info: info["medium"]["boundary"]  # noqa: E731
    shape = lambda info: (info["mesh"].get("file") or info["mesh"].get("procedural"))  # noqa: E731
    # The held-out part has what no tuning pair has: another face and a directional key;
    # and its rough dielectrics (tuned on since pt_face_rough_940) come with a face or key
    # light that no tuning pair has with that boundary.
    assert kinds(held_out, shape) - kinds(tuning, shape)
    assert "directional" in kinds(held_out, key) - kinds(tuning, key)
    tuned = {(shape(_info(n)), key(_info(n)), boundary(_info(n))) for n in tuning}
    rough = [n for n in held_out if boundary(_info(n)) == "rough-dielectric"]
    assert len(rough) >= 2 and all((shape(_info(n)), key(_info(n)), "rough-dielectric") not in tuned for n in rough)
    # And the whole set has point, area and directional keys, both boundaries, a procedural head.
    assert {"point", "area", "directional"} <= kinds(PAIRS, key)
    assert {"index-matched", "rough-dielectric"} <= kinds(PAIRS, boundary)
    assert "face" in kinds(PAIRS, shape)


def test_the_set_has_low_poly_normals_facing_away_and_a_backlit_thin_part():
    # A low-poly head: its smoothed normals disagree with its flat triangles.
    low = _info("pt_proc_lowpoly_dir_940")["mesh"]
    assert low["procedural"] == "face" and low["triangles"] < 10000
    # Pixels whose shading normal faces away from the camera, on the mask, in the set.
    facing_away = 0
    for name in PAIRS:
        normal = invsss.read_image(DATA / name / "normal.exr")
        facing_away += int(np.count_nonzero(normal[..., 2][invsss.read_mask(DATA / name / "mask.png") > 0] <= 0.0))
    assert facing_away >= 10
    # The backlit ear: the key light is behind the head (further from the camera than the head's centre).
    info = _info("pt_face_ear_backlit_940")
    key = np.asarray(info["config"]["lights"][0]["position"])
    camera = np.asarray(info["config"]["camera"]["position"])
    assert np.linalg.norm(key - camera) > np.linalg.norm(camera) + 200.0


def test_make_synthetic_writes_the_bundled_readme_again():
    # Rendering one pair again rewrites data_synthetic/README.md from the files on disk:
    # it must give back the README as bundled, the sections written by hand included.
    make_synthetic = _make_synthetic()
    truths = {name: json.loads((DATA / name / "truth.json").read_text()) for name in make_synthetic.SCENES}
    assert make_synthetic.readme_text(DATA, truths) == (DATA / "README.md").read_text()


@pytest.mark.parametrize("name", PAIRS)
def test_pair_folder_is_small(name):
    size = sum(f.stat().st_size for f in (DATA / name).iterdir())
    assert size < MAX_FOLDER_BYTES, f"{name}: {size} bytes"


@pytest.mark.parametrize("name", PAIRS)
def test_pair_is_reproducible_from_its_scene_description(name, monkeypatch):
    folder = DATA / name
    # The transmission term's buffers came after the bundled pairs were rendered (issue 48).
    assert all((folder / f).is_file() for f in SCENE_FILES if f not in ("fill_light.exr", *TRANSMISSION_FILES))
    info = json.loads((folder / "scene.json").read_text())
    # The config recorded at render time is the shipped one, mesh path relative to
    # the repository (where make_synthetic runs) and mesh bytes pinned by hash.
    monkeypatch.chdir(REPO)
    config = load_config(os.path.join("experiments", "scenes", CONFIGS[name])).model_dump()
    if config["object"]["mesh"] is not None:
        config["object"]["mesh"] = os.path.relpath(config["object"]["mesh"])
    # Read back with today's parser: a key added since, at its default, is no difference.
    assert parse_config(info["config"], "scene.json").model_dump() == config
    import hashlib

    if config["object"]["mesh"] is not None:
        mesh_bytes = (REPO / config["object"]["mesh"]).read_bytes()
        assert info["mesh"]["sha256"] == hashlib.sha256(mesh_bytes).hexdigest()
    else:
        # A procedural head: today's code must still make the mesh it was rendered with.
        import tempfile

        from invsss.scenes.procedural import write_face_ply

        obj = parse_config(info["config"], "scene.json").object
        with tempfile.TemporaryDirectory() as folder:
            _, record = write_face_ply(obj, folder)
            # And the renderer's coarser head, where the buffers come from one.
            coarse = None if obj.buffers_cell is None else write_face_ply(
                obj.model_copy(update={"cell": obj.buffers_cell}), folder)[1]
        assert record == info["mesh"] and coarse == info.get("buffers_mesh")


@pytest.mark.parametrize("name", PAIRS)
def test_pair_images_agree_with_scene_json(name):
    folder = DATA / name
    info = json.loads((folder / "scene.json").read_text())
    source = invsss.read_image(folder / "source.exr")
    target = invsss.read_image(folder / "target.exr")
    depth = invsss.read_depth(folder / "depth.exr")
    mask = invsss.read_mask(folder / "mask.png")
    camera = info["config"]["camera"]
    assert source.shape == target.shape == (camera["height"], camera["width"], info["channels"])
    assert int(mask.sum()) == info["skin_pixels"]
    skin = mask > 0
    # Renderer-style depth: eye z in mm on the head, 0 elsewhere.
    assert np.all(depth[skin] > 0) and np.all(depth[~skin & (depth > 0)] > 0)
    assert 500.0 < float(np.median(depth[skin])) < 900.0
    # A usable reference: the Monte Carlo noise of the target is well below the
    # differences the table measures (the plain fits miss the target by 10 dB and more).
    # A rough dielectric converges far more slowly: its ceiling is lower (docs/scenes.md).
    rough = info["medium"]["boundary"] == "rough-dielectric"
    assert info["noise"]["noise_ceiling_db"] > (ROUGH_MIN_CEILING_DB if rough else INDEX_MATCHED_MIN_CEILING_DB)
    # And per pixel: the median skin pixel stands above the noise (index-matched: 10 times in
    # pt_face_ear_backlit_940, whose face has the weak fill light only, 20-50 times in the
    # others; rough dielectric: 11 and 16 times at 16384 spp, 4-5 times at 2048).
    floor = MIN_MEDIAN_TO_NOISE * info["noise"]["noise_rms"]
    measured = skin
    if name in TRANSMISSION_PAIRS:
        thickness = invsss.read_image(folder / "thickness.exr")[..., 0]
        measured = skin & (thickness > 0.0) & (thickness <= THIN_PART_MM)
        assert measured.sum() >= 200  # a thin part, not a few stray pixels
    assert np.all(np.isfinite(target)) and float(np.median(target[measured])) > floor
    # Small renders, every file a renderer's buffer of the same size.
    assert max(camera["width"], camera["height"]) <= 160
    for buffer in ("normal.exr", "light.exr"):
        vectors = invsss.read_image(folder / buffer)
        assert vectors.shape == (camera["height"], camera["width"], 3)
        np.testing.assert_allclose(np.linalg.norm(vectors[skin], axis=-1), 1.0, atol=1e-3)
    assert invsss.read_image(folder / "key.exr").shape == source.shape
    # The fill term's buffer: the directions towards the second light, as the scene file places it.
    config = parse_config(info["config"], "scene.json")
    assert (folder / "fill_light.exr").is_file() == (len(config.lights) > 1)
    if len(config.lights) > 1:
        fill = invsss.read_image(folder / "fill_light.exr")
        depth = invsss.read_image(folder / "depth.exr")[..., 0]
        np.testing.assert_allclose(fill[skin], light_directions(config, depth, light=1)[skin], atol=1e-5)
    coverage = invsss.read_image(folder / "coverage.exr")[..., 0]
    np.testing.assert_array_equal(coverage >= 0.5, skin)
    for name in TRANSMISSION_FILES:  # in the pairs rendered since they exist
        if (folder / name).is_file():
            channels = info["channels"] if name == "key_irradiance.exr" else 1
            assert invsss.read_image(folder / name).shape == (camera["height"], camera["width"], channels)


@pytest.mark.slow
def test_fit_on_a_path_traced_pair_beats_source_and_thesis_values():
    folder = DATA / "pt_face_940"
    pair = invsss.load_pair(*(folder / f for f in ("source.exr", "target.exr", "depth.exr", "mask.png")))
    fit = invsss.fit_pair(pair.source, pair.target, pair.depth, pair.mask, n_starts=1)
    mask = pair.mask

    def matched_psnr(prediction):
        # The fit's own photometric freedom (gain and offset), given to the others too.
        p = np.asarray(prediction, np.float64)[..., 0][mask > 0]
        design = np.stack([p, np.ones_like(p)], axis=1)
        coef, *_ = np.linalg.lstsq(design, pair.target[..., 0][mask > 0], rcond=None)
        full = coef[0] * np.asarray(prediction, np.float64) + coef[1]
        return masked_psnr(full, pair.target, mask)

    fitted = masked_psnr(np.asarray(fit.fitted[0], np.float64), pair.target, mask)
    source = matched_psnr(pair.source)
    thesis = [
        matched_psnr(invsss.render(pair.source, pair.depth, mask, invsss.SSSParams(
            sss_level=1000.0 * level, correction=correction, maxdd=1000.0,
            weights=list(invsss.THESIS_NIR_940["weights"]),
            variances=list(invsss.THESIS_NIR_940["variances"])), model="thesis"))
        for level, correction in ((0.5, 2000.0), (0.7, 7500.0), (0.4, 4500.0))
    ]
    assert fitted > source + 1.0
    assert fitted > max(thesis) + 0.3
