"""invsss.scenes: path-traced pairs checked against geometry and physics.

The renders are tiny (24-32 px) so that the file runs in well under a minute on
two cores with Mitsuba's scalar_rgb variant. Expected values are computed here
independently of Mitsuba: rays through a sub-pixel grid of the pinhole camera,
intersected analytically with the plane or sphere. (The command, `invsss scene`:
tests/cli/test_scenes.py.)
"""

from __future__ import annotations

import os

import numpy as np
import pytest

import invsss
from invsss.scenes import MEDIUM_PRESETS, load_config, parse_config
from invsss.scenes.media import dipole_fit_to_thesis_profile

mitsuba = pytest.importorskip("mitsuba", reason='the scene tests need pip install "invsss[scenes]"')
from invsss.scenes import render_scene  # noqa: E402  (needs Mitsuba)
from tests import ROOT
from tests.scenes._scene_configs import CAMERA, POINT_LIGHT, pixel_rays, sphere_config

# ------------------------------------------------------------------ geometry


@pytest.mark.slow
def test_depth_of_tilted_plane_is_analytic_eye_z():
    tilt = -35.0
    config = sphere_config(object={"primitive": "slab", "size": [2000.0, 2000.0, 200.0],
                             "pose": {"rotate": [tilt, 0.0, 0.0]}},
                     camera={**CAMERA, "width": 32, "height": 24})
    result = render_scene(config)
    origin, directions, _ = pixel_rays(config)
    # The slab's front face: through the origin, normal R_x(tilt) (0, 0, 1).
    normal = np.array([0.0, -np.sin(np.radians(tilt)), np.cos(np.radians(tilt))])
    eye_z = (-(origin @ normal) / (directions @ normal)).mean(axis=(2, 3))
    assert result.mask.all()
    np.testing.assert_allclose(result.depth, eye_z, rtol=5e-4)
    # The depth is eye z, not the ray length: at the corners they differ by several %.
    ray_length = (-(origin @ normal) / (directions @ normal) * np.linalg.norm(directions, axis=-1)).mean(axis=(2, 3))
    assert np.abs(result.depth / ray_length - 1).max() > 0.01
    camera_normal = np.array([0.0, normal[1], normal[2]])  # camera frame = world frame here
    np.testing.assert_allclose(result.normal, np.broadcast_to(camera_normal, result.normal.shape), atol=1e-3)


@pytest.mark.parametrize("camera", [
    {**CAMERA, "width": 32, "height": 32},
    # Not square, rolled, and with the principal point moved (rows down, columns
    # right): checks the sign and scale of Mitsuba's principal point offset.
    {**CAMERA, "up": [0.2, 1.0, 0.0], "width": 40, "height": 28, "principal_offset_px": [3.0, -5.0]},
])
def test_mask_and_coverage_match_the_silhouette_minus_occluder(camera):
    radius = 40.0
    stripe = {"center": [0.0, 20.0, 100.0], "normal": [0.0, 0.0, 1.0], "along": [1.0, 0.0, 0.0],
              "width": 10.0, "length": 300.0, "count": 1, "duty": 0.5}
    config = sphere_config(occluders=[stripe], camera=camera)
    result = render_scene(config)
    origin, directions, (right, up, forward) = pixel_rays(config, n=16)
    # Sphere about the origin: a ray hits it where its distance to the centre is < radius.
    unit = directions / np.linalg.norm(directions, axis=-1, keepdims=True)
    along = -(unit @ origin)
    closest = origin + along[..., None] * unit
    on_sphere = np.linalg.norm(closest, axis=-1) < radius
    # The stripe: the plane z = 100, 5 mm (duty 0.5 of 10 mm) tall about y = 20, long in x.
    t_plane = (100.0 - origin[2]) / directions[..., 2]
    hit = origin + t_plane[..., None] * directions
    blocked = (np.abs(hit[..., 1] - 20.0) < 2.5) & (np.abs(hit[..., 0]) < 150.0)
    coverage = (on_sphere & ~blocked).mean(axis=(2, 3))
    assert blocked.any(axis=(2, 3)).sum() >= 32  # the stripe crosses the sphere's image
    assert np.abs(result.coverage - coverage).max() < 0.1
    clear = np.abs(coverage - 0.5) > 0.1
    np.testing.assert_array_equal(result.mask[clear], (coverage[clear] >= 0.5).astype(np.float32))
    # Depth and normals exist where skin is seen (behind the stripe too) and nowhere else.
    # (A pixel the silhouette only grazes may be caught by one sampling grid and not
    # the other, so "nowhere else" means where every ray of the grid misses the
    # sphere by more than 0.5 mm, a fifth of a pixel there.)
    sphere_share = on_sphere.mean(axis=(2, 3))
    assert np.all(result.depth[sphere_share > 0.05] > 0)
    miss = np.linalg.norm(closest, axis=-1).min(axis=(2, 3)) - radius
    assert np.all(result.depth[miss > 0.5] == 0)
    inside = on_sphere.all(axis=(2, 3))
    # Normals of fully covered pixels: the pixel-average sphere normal, in camera space.
    t_hit = along - np.sqrt(np.maximum(radius**2 - np.sum(closest**2, axis=-1), 0.0))
    world = (origin + t_hit[..., None] * unit) / radius
    expected = np.stack([world @ right, world @ up, -(world @ forward)], -1).mean(axis=(2, 3))
    expected /= np.linalg.norm(expected, axis=-1, keepdims=True)
    assert np.min(np.sum(result.normal[inside] * expected[inside], axis=-1)) > 0.999


# ------------------------------------------------------------------- physics


@pytest.mark.slow
@pytest.mark.parametrize(("medium", "spp"), [
    ({"preset": "thesis-940"}, 512),
    ({"sigma_s_prime": 2.4, "sigma_a": 0.1}, 512),
    # About 50x less variance per sample (see test_index_matched_boundary_converges_faster).
    ({"preset": "thesis-940", "boundary": "index-matched"}, 32),
])
def test_flat_slab_target_and_source_reflect_the_same_energy(medium, spp):
    # Lit at 30 degrees, seen at 20 degrees: not the straight-down, uniform-sky
    # set-up the source albedo was calibrated in.
    light, view = np.radians(30.0), np.radians(20.0)
    config = sphere_config(
        object={"primitive": "slab", "size": [2000.0, 2000.0, 300.0]},
        camera={"position": [300.0 * np.sin(view), 0.0, 300.0 * np.cos(view)], "look_at": [0.0, 0.0, 0.0],
                "fov": 4.0, "width": 24, "height": 24},
        lights=[{"type": "directional", "direction": [0.0, -np.sin(light), -np.cos(light)], "irradiance": 1.0}],
        medium=medium,
        spp=spp,
        seed=3,
    )
    result = render_scene(config)
    ratio = float(result.target.mean() / result.source.mean())
    assert abs(ratio - 1.0) < 0.05, ratio
    albedo = result.info["source_albedo"]
    if medium.get("boundary") != "index-matched":
        # Behind the rough dielectric the dipole's closed form would have missed by
        # far more: the calibration matters.
        assert albedo["dipole_total"][0] / albedo["value"][0] > 1.08


def test_index_matched_boundary_converges_faster():
    rough, matched = (render_scene(sphere_config(spp=16, medium={"preset": "thesis-940", "boundary": boundary}))
                      for boundary in ("rough-dielectric", "index-matched"))
    relative = [r.info["noise"]["noise_rms"] / float(r.target[r.mask > 0].mean()) for r in (rough, matched)]
    assert relative[1] < relative[0] / 3, relative
    assert matched.info["medium"]["eta"] == 1.0 and matched.info["medium"]["roughness"] is None
    with pytest.raises(invsss.InvalidInputError, match="medium: an index-matched boundary has eta 1"):
        sphere_config(medium={"sigma_s_prime": 1.0, "sigma_a": 0.1, "eta": 1.4, "boundary": "index-matched"})


def test_two_seeds_give_the_stated_noise():
    first, second = (render_scene(sphere_config(spp=16, seed=seed)) for seed in (0, 1))
    on = first.mask > 0
    measured = np.sqrt(np.mean((first.target - second.target)[on] ** 2))
    # Each target's noise_rms is the noise of its mean; independent, they add in quadrature.
    stated = np.hypot(first.info["noise"]["noise_rms"], second.info["noise"]["noise_rms"])
    assert 0.8 < measured / stated < 1.25, (measured, stated)
    # The ceiling is the PSNR of a noise-free image against the target: 6 dB above the halves.
    noise = first.info["noise"]
    assert noise["noise_ceiling_db"] == pytest.approx(noise["psnr_halves_db"] + 20 * np.log10(2))
    halves = first.target_halves
    np.testing.assert_allclose(first.target, 0.5 * (halves[0] + halves[1]), atol=1e-6)
    assert first.info["seeds"]["target_halves"] != second.info["seeds"]["target_halves"]


def test_a_camera_that_sees_no_skin_is_one_line():
    away = {**CAMERA, "look_at": [0.0, 0.0, 600.0], "width": 8, "height": 8}
    with pytest.raises(invsss.InvalidInputError, match="^camera: sees no skin"):
        render_scene(sphere_config(camera=away))


def test_key_is_the_source_lit_by_the_first_light_alone():
    fill = {**POINT_LIGHT, "position": [-200.0, -50.0, 250.0], "intensity": 6e4}
    camera = {**CAMERA, "width": 12, "height": 12}
    both = render_scene(sphere_config(lights=[POINT_LIGHT, fill], camera=camera, spp=16), target=False)
    alone = render_scene(sphere_config(lights=[POINT_LIGHT], camera=camera, spp=16), target=False)
    # The same spp and seed: the key pass is the one-light source, sample for sample.
    np.testing.assert_array_equal(both.key, alone.source)
    np.testing.assert_array_equal(alone.key, alone.source)
    on = both.mask > 0
    fill_part = (both.source - both.key)[on]
    assert fill_part.mean() > 0.05 * both.source[on].mean()  # the second light adds light
    assert both.info["spp"]["key_light"] == 16 and alone.info["spp"]["key_light"] == 0


def test_coloured_light_gives_rgb_even_for_a_grey_medium():
    light = {**POINT_LIGHT, "intensity": [1e5, 5e4, 2e4]}
    result = render_scene(sphere_config(lights=[light], camera={**CAMERA, "width": 8, "height": 8}))
    assert result.source.shape == (8, 8, 3)
    red, green, blue = result.source[result.mask > 0].mean(axis=0)
    assert red > green > blue


@pytest.mark.slow
def test_chromatic_medium_gives_rgb_with_an_albedo_per_channel():
    config = sphere_config(medium={"preset": "jensen-skin1"}, spp=8, camera={**CAMERA, "width": 16, "height": 16})
    result = render_scene(config)
    assert result.target.shape == (16, 16, 3) and result.source.shape == (16, 16, 3)
    value = result.info["source_albedo"]["value"]
    assert value[0] > value[1] > value[2]  # skin1 absorbs blue most


def test_thesis_medium_preset_is_the_dipole_fit_to_the_thesis_profile():
    sigma_s_prime, sigma_a = dipole_fit_to_thesis_profile()
    preset = MEDIUM_PRESETS["thesis-940"]
    assert sigma_s_prime == pytest.approx(preset["sigma_s_prime"], rel=2e-3)
    assert sigma_a == pytest.approx(preset["sigma_a"], rel=2e-3)


# ------------------------------------------------------------------ the example scenes


EXAMPLES = str(ROOT / "experiments" / "scenes")


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(f for f in os.listdir(EXAMPLES) if f.endswith(".toml")))
def test_example_scenes_render(name):
    config = load_config(os.path.join(EXAMPLES, name)).with_overrides(width=16, spp=2)
    try:
        result = render_scene(config)
    except invsss.InvalidInputError as err:
        if "libLLVM" not in str(err):
            raise
        # An LLVM variant on a machine whose libLLVM aborts on Mitsuba's kernels
        # (Debian's libllvm15, which lavapipe brings); .ci/run installs libllvm19.
        pytest.skip(str(err))
    assert result.mask.sum() >= 64  # the object fills a good part of the view
    assert result.info["mesh"] is None or len(result.info["mesh"]["sha256"]) == 64
    # Depth in mm: the camera is 0.5-0.8 m from the object.
    assert 300.0 < float(np.median(result.depth[result.mask > 0])) < 900.0


def test_light_directions_point_from_the_surface_to_the_light():
    # Rebuild each pixel centre's surface point from the camera's definition
    # (pixel_rays, with one sample at the pixel centre) and the depth, and compare
    # its direction towards the point light with the light buffer.
    from invsss.scenes.path_tracing import light_directions

    config = sphere_config()
    depth = np.full((config.camera.height, config.camera.width), 250.0)
    depth[:3] = 0.0  # nothing seen
    origin, directions, (right, up, forward) = pixel_rays(config, n=1)
    points = origin + depth[..., None] * directions[:, :, 0, 0]
    towards = np.asarray(POINT_LIGHT["position"], float) - points
    towards /= np.linalg.norm(towards, axis=-1, keepdims=True)
    expected = np.stack([towards @ right, towards @ up, -(towards @ forward)], axis=-1)
    got = light_directions(config, depth)
    np.testing.assert_allclose(got[3:], expected[3:], atol=1e-12)
    assert np.all(got[:3] == 0.0)


def test_light_directions_follow_the_principal_point():
    # A principal point moved by whole pixels moves the picture by as many: the
    # buffer of the moved camera at (row + 2, col - 3) is the original's at (row, col).
    from invsss.scenes.path_tracing import light_directions

    config = sphere_config()
    moved = parse_config({**config.model_dump(), "camera": {**config.camera.model_dump(),
                                                            "principal_offset_px": [2.0, -3.0]}}, "test scene")
    depth = 250.0 + np.random.default_rng(0).uniform(0.0, 20.0, (config.camera.height, config.camera.width))
    shifted = np.zeros_like(depth)
    shifted[2:, :-3] = depth[:-2, 3:]
    before, after = light_directions(config, depth), light_directions(moved, shifted)
    np.testing.assert_allclose(after[2:, :-3], before[:-2, 3:], atol=1e-12)
    assert np.abs(light_directions(config, shifted)[2:, :-3] - before[:-2, 3:]).max() > 1e-3


def test_with_warp_refuses_a_warp_no_camera_move_makes():
    from invsss.estimator.registration import Warp

    shear = Warp("affine", (0.5, 0.5, 0.0, 0.02, 0.0, 0.0), (16.0, 16.0))
    with pytest.raises(invsss.InvalidInputError, match="affine warp is not a camera move"):
        sphere_config().with_warp(shear)


def test_with_warp_keeps_the_camera_where_the_warp_is_the_identity():
    from invsss.estimator.registration import Warp

    config = sphere_config()
    same = config.with_warp(Warp("similarity", (0.0, 0.0, 0.0, 0.0), (10.0, 20.0))).camera
    np.testing.assert_allclose(same.up, config.camera.frame()[2], atol=1e-12)
    assert same.principal_offset_px == [0.0, 0.0]
    assert same.focal_px == pytest.approx(config.camera.focal_length_px, rel=1e-12)


# ------------------------------------------------- procedural face, bumps, closed fran


@pytest.mark.parametrize(("object_", "message"), [
    ({"primitive": "sphere", "radius": 40.0, "cell": 4.0}, 'object: cell: only for primitive "face"'),
    ({"primitive": "slab", "size": [10.0, 10.0, 1.0], "ears": False}, 'object: ears: only for primitive "face"'),
    ({"primitive": "face", "size": [10.0, 10.0, 1.0]}, 'object: primitive "face" has a fixed size'),
    ({"primitive": "face", "cell": 0.5}, "object.cell: input should be greater than or equal to 1"),
    ({"primitive": "face", "ears": 1}, "object.ears: expected true or false, got 1"),
    ({"primitive": "face", "wrinkle": False}, "object.wrinkle: unknown key, did you mean 'wrinkles'?"),
    ({"primitive": "sphere", "radius": 40.0, "bumps": 10.0}, "object: bumps: only for a mesh or primitive"),
    ({"primitive": "face", "bumps": 60.0}, "object.bumps: input should be less than 60"),
    ({"primitive": "sphere", "radius": 40.0, "face_normals": True}, "object: face_normals: only for a mesh or"),
    ({"primitive": "sphere", "radius": 40.0, "buffers_cell": 9.0}, 'object: buffers_cell: only for primitive "face"'),
    ({"primitive": "face", "bumps": 5.0, "face_normals": True}, "object: face_normals: only for a mesh or"),
    ({"primitive": "face", "subdivisions": 1}, "object: subdivisions: only for a mesh without a pigment"),
    ({"primitive": "face", "subdivisions": 4}, "object.subdivisions: input should be less than or equal to 3"),
])
def test_face_and_bump_keys_are_checked_in_one_line(object_, message):
    with pytest.raises(invsss.InvalidInputError) as err:
        sphere_config(object=object_)
    assert str(err.value).count("\n") == 0
    assert str(err.value).startswith(f"test scene: {message}")


def test_procedural_face_is_closed_deterministic_and_has_its_parts():
    from invsss.scenes.procedural import face_mesh, face_sdf

    fine = face_mesh(2.0)
    assert fine.is_watertight and fine.is_winding_consistent and fine.volume > 0
    again = face_mesh(2.0)
    np.testing.assert_array_equal(fine.vertices, again.vertices)
    np.testing.assert_array_equal(fine.faces, again.faces)
    # The ears stand out beyond the head's 72 mm half-width; without them it is the head alone.
    bare = face_mesh(2.0, ears=False)
    assert fine.bounds[1][0] > 79.0 and bare.bounds[1][0] < 73.0
    # The nose is the front: 100 mm ahead of the head's centre.
    assert 98.0 < fine.bounds[1][2] < 101.0
    # The furrows move the forehead's surface by their depth and nowhere else.
    y = np.linspace(35.0, 60.0, 400)
    forehead = face_sdf(0.0, y, 75.0) - face_sdf(0.0, y, 75.0, wrinkles=False)
    cheek = face_sdf(50.0, -20.0, 60.0) - face_sdf(50.0, -20.0, 60.0, wrinkles=False)
    assert 0.25 < np.abs(forehead).max() <= 0.35 + 1e-6 and float(cheek) == 0.0
    # A coarse grid is a low-poly head: a hundredth of the triangles.
    low = face_mesh(9.0, ears=False, wrinkles=False)
    assert low.is_watertight and len(low.faces) < len(face_mesh(1.0).faces) / 50


def test_face_primitive_renders_and_scene_json_pins_its_mesh():
    config = sphere_config(object={"primitive": "face", "cell": 9.0, "ears": False, "wrinkles": False},
                     camera={"position": [0.0, 0.0, 600.0], "look_at": [0.0, 0.0, 0.0], "fov": 24.0,
                             "width": 16, "height": 16},
                     lights=[{"type": "directional", "direction": [0.0, 0.0, -1.0], "irradiance": 1.0}])
    result = render_scene(config)
    record = result.info["mesh"]
    assert record["procedural"] == "face" and record["cell_mm"] == 9.0 and not record["ears"]
    assert 1000 < record["triangles"] < 10000 and len(record["sha256"]) == 64
    assert result.mask.sum() > 0.3 * result.mask.size
    # The nose, 100 mm in front of the centre, is the nearest point: about 500 mm away.
    assert 495.0 < float(result.depth[result.mask > 0].min()) < 515.0


def test_bumps_tilt_the_shading_normals_and_leave_the_surface():
    sphere_mesh = {"mesh": None, "mm_per_unit": 1.0}
    import tempfile

    import trimesh

    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "ball.ply")
        trimesh.creation.icosphere(subdivisions=4, radius=40.0).export(path)
        sphere_mesh["mesh"] = path
        camera = {**CAMERA, "width": 24, "height": 24}
        plain = render_scene(sphere_config(object=sphere_mesh, camera=camera), target=False)
        bumped = render_scene(sphere_config(object={**sphere_mesh, "bumps": 30.0}, camera=camera), target=False)
    np.testing.assert_array_equal(plain.mask, bumped.mask)
    np.testing.assert_allclose(plain.depth, bumped.depth, atol=1e-3)
    inside = plain.coverage > 0.999
    angle = np.degrees(np.arccos(np.clip(np.sum(plain.normal * bumped.normal, axis=-1), -1.0, 1.0)))[inside]
    # Tilted by up to 30 degrees (a pixel averages a little of its neighbours' tilt), not everywhere alike.
    assert 12.0 < angle.max() < 31.0 and np.median(angle) > 3.0
    assert not np.allclose(plain.source, bumped.source)


def test_buffers_cell_renders_the_buffers_from_a_coarser_head():
    camera = {"position": [0.0, 0.0, 650.0], "look_at": [0.0, 0.0, 0.0], "fov": 24.0, "width": 16, "height": 16}
    face = {"primitive": "face", "cell": 10.0, "ears": False, "wrinkles": False}
    same = render_scene(sphere_config(object=face, camera=camera), target=False)
    coarse = render_scene(sphere_config(object={**face, "buffers_cell": 20.0}, camera=camera), target=False)
    # scene.json records both heads; the buffers' has fewer triangles.
    assert coarse.info["mesh"] == same.info["mesh"] and "buffers_mesh" not in same.info
    assert coarse.info["buffers_mesh"]["cell_mm"] == 20.0
    assert coarse.info["buffers_mesh"]["triangles"] < coarse.info["mesh"]["triangles"]
    # The depth and normals are the coarse head's, not the medium's.
    both = (same.mask > 0) & (coarse.mask > 0)
    assert np.abs(same.depth[both] - coarse.depth[both]).max() > 0.5
    assert not np.allclose(same.normal[both], coarse.normal[both], atol=0.01)


def test_face_normals_shade_with_the_triangles_own_normals():
    import tempfile

    import trimesh

    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "ball.ply")
        ball = trimesh.creation.icosphere(subdivisions=1, radius=40.0)  # 80 flat triangles
        ball.export(path)
        camera = {**CAMERA, "width": 24, "height": 24}
        mesh = {"mesh": path, "mm_per_unit": 1.0}
        smooth = render_scene(sphere_config(object=mesh, camera=camera), target=False)
        flat = render_scene(sphere_config(object={**mesh, "face_normals": True}, camera=camera), target=False)
    np.testing.assert_array_equal(smooth.mask, flat.mask)
    inside = smooth.coverage > 0.999
    def on_a_facet(render):
        # The share of pixels whose normal is one of the triangles' own (within 0.1
        # degrees; camera space: the camera looks down -z, world and camera axes
        # agree). A pixel across an edge averages two of them.
        unit = render.normal[inside] / np.linalg.norm(render.normal[inside], axis=-1, keepdims=True)
        nearest = np.max(unit @ np.asarray(ball.face_normals).T, axis=1)
        return float(np.mean(nearest > np.cos(np.radians(0.1))))

    # Measured: 34 % of the 210 covered pixels with face normals, none with the smooth ones.
    assert on_a_facet(flat) > 0.25 and on_a_facet(smooth) < 0.02


def test_subdivisions_refine_the_mesh_towards_a_smooth_surface():
    import tempfile

    import trimesh

    from invsss.scenes.mitsuba_scene import load_mesh_ply

    def facet_angle(mesh):
        # Median angle (degrees) between each triangle and its corners' mean vertex normal.
        corners = mesh.vertex_normals[mesh.faces].mean(axis=1)
        corners /= np.linalg.norm(corners, axis=1, keepdims=True)
        return float(np.degrees(np.median(np.arccos(np.clip(np.sum(corners * mesh.face_normals, axis=1), -1, 1)))))

    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "ball.ply")
        trimesh.creation.icosphere(subdivisions=1, radius=40.0).export(path)  # 80 flat triangles
        as_given = trimesh.load(load_mesh_ply(path, folder), process=False)
        refined = trimesh.load(load_mesh_ply(path, folder, subdivisions=2), process=False)
    assert len(as_given.faces) == 80 and len(refined.faces) == 16 * 80
    assert refined.is_watertight
    assert facet_angle(refined) < facet_angle(as_given) / 3


def test_closed_fran_is_the_scan_closed_by_its_script():
    import importlib.util

    import trimesh

    folder = os.path.join(EXAMPLES, "meshes")
    spec = importlib.util.spec_from_file_location("close_fran", os.path.join(folder, "close_fran.py"))
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    scan = trimesh.load(os.path.join(folder, "fran_cut.ply"), process=False)
    scan.merge_vertices(merge_tex=True, merge_norm=True)
    closed, apex = script.close(scan)
    script.check(closed, apex, scan)
    shipped = trimesh.load(os.path.join(folder, "fran_closed.ply"), process=False)
    np.testing.assert_allclose(shipped.vertices, closed.vertices, atol=1e-4)
    np.testing.assert_array_equal(shipped.faces, closed.faces)
    assert shipped.is_watertight and shipped.volume > 0
    # Its front (the nose tip) at z = 0, looking along +z: the scan's triangles face +z on the whole.
    assert abs(shipped.bounds[1][2]) < 1e-6
    face = shipped.face_normals[: len(scan.faces)]
    assert np.average(face[:, 2], weights=shipped.area_faces[: len(scan.faces)]) > 0.3


# ------------------------------------------------------------------- split


def test_split_file_errors_are_one_line(tmp_path):
    from invsss.scenes.split import read_split

    cases = {
        'tuning = ["a"]\n': "held-out: missing",
        'tuning = ["a"]\nheld-out = ["b"]\nheldout = []\n': "heldout: unknown key",
        'tuning = "a"\nheld-out = ["b"]\n': "tuning: expected a list of pair folder names",
        'tuning = ["a"]\nheld-out = ["b", "a"]\n': "a is listed as tuning and as held-out",
        'tuning = [\n': "not valid TOML",
    }
    for text, message in cases.items():
        path = tmp_path / "SPLIT.toml"
        path.write_text(text)
        with pytest.raises(invsss.InvalidInputError) as err:
            read_split(path)
        assert str(err.value).count("\n") == 0 and message in str(err.value), text
