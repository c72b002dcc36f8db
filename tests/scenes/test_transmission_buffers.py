"""The transmission term's buffers of ``invsss scene`` (issue 48): ``thickness.exr``,
``thickness_normal.exr`` and ``key_irradiance.exr``.

The thicknesses are checked against a sphere's chords, computed here without Mitsuba:
the sphere's points seen through an 8 x 8 grid in each pixel (``pixel_rays``),
averaged as the skin-only pass averages its samples, and the chord from that point.
The key light's irradiance is checked against the key light's own render, and against
Mitsuba's emitters.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

import invsss
from invsss.scenes import parse_config
from tests import ROOT

pytest.importorskip("mitsuba", reason='the scene tests need pip install "invsss[scenes]"')
from invsss.scenes import render_scene, write_scene  # noqa: E402  (needs Mitsuba)
from invsss.scenes.mitsuba_scene import import_mitsuba, scene_dict  # noqa: E402
from invsss.scenes.path_tracing import SCENE_FILES  # noqa: E402
from invsss.scenes.transmission import (  # noqa: E402
    THICKNESS_NO_EXIT_MM,
    TRANSMISSION_FILES,
    facing_irradiance,
    transmission_buffers,
)
from tests.scenes._scene_configs import CAMERA, POINT_LIGHT, pixel_rays, sphere_config  # noqa: E402

RADIUS = 40.0  # sphere_config's
#: Behind the sphere and to its right: the camera sees points the light reaches only
#: through the sphere, and on the right a crescent that faces it.
BACK_LIGHT = {"type": "point", "position": [250.0, 0.0, -150.0], "intensity": 1e5}
SMALL = {**CAMERA, "width": 24, "height": 24}


@pytest.fixture(scope="module")
def backlit():
    config = sphere_config(camera=SMALL, lights=[BACK_LIGHT])
    return config, render_scene(config, target=False)


def _sphere_points(config):
    """Per pixel, the sphere's points (H, W, 8, 8, 3) seen through an 8 x 8 grid, where
    each of those rays hits it ((H, W, 8, 8) bool), and their mean (H, W, 3)."""
    origin, directions, _ = pixel_rays(config)
    unit = directions / np.linalg.norm(directions, axis=-1, keepdims=True)
    along = -(unit @ origin)
    squared = along**2 - (origin @ origin - RADIUS**2)
    hits = squared > 0
    points = origin + (along - np.sqrt(np.where(hits, squared, 0.0)))[..., None] * unit
    mean = np.where(hits[..., None], points, 0.0).sum(axis=(2, 3)) / np.maximum(hits.sum(axis=(2, 3)), 1)[..., None]
    return points, hits, mean


def _exit_along(points, directions):
    """The distance from points inside the sphere along unit ``directions`` to its surface."""
    along = np.sum(points * directions, axis=-1)
    return -along + np.sqrt(along**2 - np.sum(points**2, axis=-1) + RADIUS**2)


def test_thickness_is_the_chord_towards_the_key_light(backlit):
    config, result = backlit
    thickness = result.transmission["thickness.exr"]
    points, hits, mean = _sphere_points(config)
    inner = hits.all(axis=(2, 3)) & (result.coverage == 1.0)
    # The averaged point is inside the sphere (the mean of points on it); its ray towards
    # the light leaves the sphere where the chord from it ends. 0 where it faces the light
    # (its averaged normal, the direction of the mean point, towards the light).
    towards = np.asarray(BACK_LIGHT["position"]) - mean
    towards /= np.linalg.norm(towards, axis=-1, keepdims=True)
    facing = np.sum(mean * towards, axis=-1) / np.maximum(np.linalg.norm(mean, axis=-1), 1e-9)
    expected = np.where(facing >= 0.0, 0.0, _exit_along(mean, towards))
    # Mitsuba's mean of 64 jittered samples is not the grid's: allow a small part of how
    # much the chord varies over the pixel (2 R max(-n . l, 0) at each grid point). The
    # differences seen were at most 1.5 % of it (scalar_rgb and llvm_ad_rgb), 0.2 mm.
    light = np.asarray(BACK_LIGHT["position"]) - points
    light /= np.linalg.norm(light, axis=-1, keepdims=True)
    chords = 2.0 * RADIUS * np.clip(-np.sum(points * light, axis=-1) / RADIUS, 0.0, None)
    spread = np.ptp(np.where(hits, chords, 0.0), axis=(2, 3))
    error = np.abs(thickness - expected)[inner]
    assert np.all(error <= 0.02 + 0.03 * spread[inner]), error.max()
    # Through the sphere the chords run up to its diameter; where the light falls on the
    # point, 0 (away from the terminator, where the pixel's samples could fall either side).
    assert 70.0 < thickness[inner].max() <= 2 * RADIUS
    lit, dark = inner & (facing > 0.02), inner & (facing < -0.02)
    assert lit.sum() >= 10 and dark.sum() >= 100
    assert np.all(thickness[lit] == 0.0) and np.all(thickness[dark] > 0.0)
    assert np.all(thickness[result.coverage == 0.0] == 0.0)


def test_thickness_along_the_normal_is_the_diameter(backlit):
    config, result = backlit
    along_normal = result.transmission["thickness_normal.exr"]
    _, hits, mean = _sphere_points(config)
    inner = hits.all(axis=(2, 3)) & (result.coverage == 1.0)
    # The sphere's averaged normal points away from its centre: the chord runs through it,
    # from the averaged point, a fraction of a mm below the surface, to the far side.
    np.testing.assert_allclose(along_normal[inner], RADIUS + np.linalg.norm(mean, axis=-1)[inner], atol=0.05)
    np.testing.assert_allclose(along_normal[inner], 2 * RADIUS, atol=0.3)
    # Every seen pixel has one, whatever the light (the silhouette's averaged points are
    # deeper inside); none off the skin.
    seen = result.depth > 0
    assert np.all((along_normal[seen] > 2 * RADIUS - 10.0) & (along_normal[seen] <= 2 * RADIUS + 1e-3))
    assert np.all(along_normal[~seen] == 0.0)


def test_the_key_light_is_the_key_irradiance_times_the_cosine():
    # A coloured key (an RGB pair of the grey medium) and a fill.
    key = {**POINT_LIGHT, "intensity": [1e5, 6e4, 3e4]}
    fill = {**POINT_LIGHT, "position": [-200.0, -50.0, 250.0], "intensity": 6e4}
    result = render_scene(sphere_config(camera=SMALL, lights=[key, fill], spp=64), target=False)
    irradiance = result.transmission["key_irradiance.exr"]
    assert irradiance.shape == result.key.shape == (24, 24, 3)
    cosine = np.clip(np.sum(result.normal * result.light, axis=-1), 0.0, None)
    # A sphere alone: every point that faces the light sees it. Left out: the silhouette,
    # and the pixels near the terminator, whose 64 samples spread over cosines from 0 up.
    lit = (result.coverage == 1.0) & (cosine > 0.3)
    ratio = result.key[lit] / (irradiance[lit] * cosine[lit][:, None])
    # Seen at 64 spp: within 2.5 % per pixel (the key's samples over the pixel), 0.2 % in the median.
    assert lit.sum() > 100 and np.abs(ratio - 1.0).max() < 0.05 and abs(np.median(ratio) - 1.0) < 0.01
    # The key light's, not the source's: the fill adds light the buffer does not hold.
    assert np.median(result.source[lit] / (irradiance[lit] * cosine[lit][:, None])) > 1.05
    assert np.all(irradiance[result.depth == 0] == 0.0)


@pytest.mark.parametrize("light", [
    {"type": "point", "position": [30.0, -20.0, 400.0], "intensity": [1e5, 2e5, 5e4]},
    {"type": "spot", "position": [0.0, 0.0, 400.0], "look_at": [0.0, 0.0, 0.0], "intensity": 3e5,
     "cutoff": 20.0, "beam_width": 8.0},
    {"type": "spot", "position": [0.0, 0.0, 400.0], "look_at": [0.0, 0.0, 0.0], "intensity": 3e5, "cutoff": 15.0},
    {"type": "area", "center": [50.0, 80.0, 300.0], "look_at": [0.0, 0.0, 0.0], "width": 40.0, "height": 20.0,
     "radiance": [2.0, 1.0, 0.5]},
    {"type": "directional", "direction": [0.2, -0.3, -1.0], "irradiance": 2.5},
], ids=["point", "spot", "spot-default-beam", "area", "directional"])
def test_facing_irradiance_is_what_mitsubas_emitter_gives(light):
    mi = import_mitsuba("scalar_rgb")
    config = sphere_config(lights=[light])
    scene = mi.load_dict(scene_dict(mi, config, "source", albedo=0.5))  # the emitters need their scene
    emitter = scene.emitters()[0]
    # Points inside a spot's beam, in its falloff and outside its cone (at 400 mm, 8, 15
    # and 20 degrees are 56, 107 and 146 mm off the axis), and behind the area light's plane.
    points = np.array([[0.0, 0.0, 0.0], [30.0, 0.0, 0.0], [0.0, 80.0, 10.0], [-100.0, 30.0, 50.0],
                       [130.0, -40.0, 0.0], [200.0, 0.0, -20.0], [60.0, 100.0, 320.0]])
    ours = facing_irradiance(config.lights[0], points, 3)
    for point, value in zip(points, ours, strict=True):
        interaction = mi.Interaction3f()
        interaction.p = mi.Point3f(*point)
        # The sample (0.5, 0.5) is the area light's centre, where ours puts its power.
        _, weight = emitter.sample_direction(interaction, mi.Point2f(0.5, 0.5))
        np.testing.assert_allclose(value, np.asarray(weight, np.float64), rtol=1e-4, atol=1e-12)
    if light["type"] == "spot":
        assert ours[:, 0].max() > 0 and np.sum(ours[:, 0] == 0) >= 2  # some inside the cone, some outside


def test_a_ray_that_finds_no_way_out_gives_the_no_exit_thickness():
    # An open surface (a square at z = 0, facing +z) with three seen pixels on it and one
    # off the skin: no ray into it leaves it again.
    mi = import_mitsuba("scalar_rgb")
    scene = {"type": "scene", "object": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale(100.0)}}
    coverage = np.array([[1.0, 1.0], [0.5, 0.0]])[..., None].repeat(3, axis=-1)
    points = np.array([[[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]], [[0.0, 10.0, 0.0], [0.0, 0.0, 0.0]]])
    aovs = {"cov": coverage, "pos": points * coverage, "nn": np.broadcast_to([0.0, 0.0, 1.0], (2, 2, 3)) * coverage}
    behind = sphere_config(lights=[{**POINT_LIGHT, "position": [0.0, 0.0, -100.0]}])
    buffers = transmission_buffers(mi, behind, scene, aovs, [0.5], 1)
    expected = np.array([[1.0, 1.0], [1.0, 0.0]]) * THICKNESS_NO_EXIT_MM
    np.testing.assert_array_equal(buffers["thickness.exr"], expected)
    np.testing.assert_array_equal(buffers["thickness_normal.exr"], expected)
    # In front: the light enters right there, however thin the skin below.
    front = transmission_buffers(mi, sphere_config(), scene, aovs, [0.5], 1)
    np.testing.assert_array_equal(front["thickness.exr"], 0.0)
    np.testing.assert_array_equal(front["thickness_normal.exr"], expected)


def test_a_one_light_scene_writes_the_buffers(backlit, tmp_path):
    config, result = backlit
    assert set(TRANSMISSION_FILES) <= set(SCENE_FILES)
    written = [os.path.basename(p) for p in write_scene(result, tmp_path / "pair")]
    assert written == [name for name in SCENE_FILES if name not in ("target.exr", "fill_light.exr")]
    h, w = config.camera.height, config.camera.width
    for name in TRANSMISSION_FILES:
        image = invsss.read_image(tmp_path / "pair" / name)
        channels = result.source.shape[-1] if name == "key_irradiance.exr" else 1  # the grey sphere's: 1
        assert image.dtype == np.float32 and image.shape == (h, w, channels)
        wrote = result.transmission[name]
        np.testing.assert_array_equal(image, wrote if wrote.ndim == 3 else wrote[..., None])


@pytest.mark.slow
def test_the_key_irradiance_holds_the_pigments_albedo_map():
    """With a pigment the source's albedo is a map (the calibrated albedo times what the
    pigment leaves): the buffer holds it, so the key light is its irradiance times the
    cosine pixel by pixel, which one albedo for the whole face is not."""
    pytest.importorskip("trimesh")
    meshes = ROOT / "experiments" / "scenes" / "meshes"
    # test_scene_pigment.py's face, its map at full strength, lit along the view.
    config = parse_config({
        "spp": 8, "geometry_spp": 4, "seed": 2, "max_depth": 32,
        "object": {"mesh": str(meshes / "LeePerrySmith.glb"), "mm_per_unit": 44.0,
                   "pigment": {"map": str(meshes / "Map-COL.jpg"), "strength": 1.0, "subdivide": 0}},
        "camera": {"position": [0.0, 40.0, 600.0], "look_at": [0.0, 40.0, 0.0], "fov": 8.0, "width": 24, "height": 24},
        "lights": [{"type": "directional", "direction": [0.0, 0.0, -1.0], "irradiance": 3.0}],
        "medium": {"preset": "thesis-940", "boundary": "index-matched"},
    }, "scene")
    result = render_scene(config, target=False)
    irradiance = result.transmission["key_irradiance.exr"][..., 0]
    cosine = np.clip(np.sum(result.normal * result.light, axis=-1), 0.0, None)
    # The light shines along the view: little of the face is in a shadow, and the light
    # that comes off the rest of the face (the nose's flanks) is a small part.
    lit = (result.coverage == 1.0) & (cosine > 0.5)
    ratio = result.key[..., 0][lit] / (irradiance[lit] * cosine[lit])
    albedo = result.info["source_albedo"]["value"][0]
    one_albedo = result.key[..., 0][lit] / (albedo * 3.0 / np.pi * cosine[lit])  # the directional light's 3
    assert lit.sum() > 300 and abs(np.median(ratio) - 1.0) < 0.03 and np.median(one_albedo) < 0.85
    assert np.std(np.log(ratio)) < 0.5 * np.std(np.log(one_albedo))
    assert np.all(irradiance[lit] <= albedo * 3.0 / np.pi * (1 + 1e-4))  # the pigment only takes away


@pytest.mark.parametrize("variant", ["scalar_rgb", "llvm_ad_rgb"])
def test_a_point_just_outside_the_surface_gets_the_thickness_behind_it(variant):
    # A pixel's averaged point lies outside a concave patch: the ray meets the surface
    # from outside first, enters and goes on to the exit; the thickness is the skin's, from
    # the entry. Here points 0.2 mm above a sphere's poles (more than the ray's inset),
    # and one inside it.
    try:
        mi = import_mitsuba(variant)
    except invsss.InvalidInputError as err:  # an LLVM variant without a usable libLLVM
        pytest.skip(str(err))
    scene = {"type": "scene", "object": {"type": "sphere", "radius": RADIUS}}
    points = np.array([[[0.0, 0.0, RADIUS + 0.2], [0.0, RADIUS + 0.2, 0.0], [0.0, 0.0, 10.0]]])
    normals = np.array([[[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]])
    aovs = {"cov": np.ones((1, 3, 3)), "pos": points, "nn": normals}
    buffers = transmission_buffers(mi, sphere_config(), scene, aovs, [0.5], 1)
    np.testing.assert_allclose(buffers["thickness_normal.exr"], [[2 * RADIUS, 2 * RADIUS, 50.0]], atol=1e-3)
