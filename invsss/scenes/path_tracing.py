"""Render a scene description into one source/target pair folder.

:func:`render_scene` runs the passes of :mod:`invsss.scenes.mitsuba_scene` and
turns them into images; :func:`write_scene` (and ``invsss scene``) writes them as
one unit through :class:`invsss.io.result_dir.ResultDir`:

==============  ==========================================================
``source.exr``  Lambertian render, albedo from :mod:`~invsss.scenes.calibration`
``target.exr``  path-traced medium, boundary reflection subtracted; the mean of
                two independently seeded halves
``depth.exr``   eye-space z in mm (distance along the optical axis), the
                average over the pixel's skin samples; 0 where no skin is seen
``mask.png``    255 where skin covers at least half the pixel, else 0
``normal.exr``  unit shading normals in camera space (x right, y up, z towards
                the camera); 0 where no skin is seen
``light.exr``   unit vectors from the surface towards the first (key) light,
                camera space (:func:`light_directions`); 0 where no skin is seen
``fill_light.exr`` the same towards the second light, the direction the ``fill``
                light term gives the other lights (scenes with two lights or more)
``coverage.exr`` fraction of the pixel where skin is seen (occluders excluded)
``thickness.exr`` mm the key light travels inside the skin to reach the seen point
                (0 where the point faces it), :mod:`~invsss.scenes.transmission`
``thickness_normal.exr`` mm from the seen point along the inward normal to where
                the skin ends (a baked thickness map)
``key_irradiance.exr`` the source's albedo times the key light's unshadowed
                irradiance on a surface facing it, over pi: where the key light
                reaches a point unshadowed, ``key.exr`` is this times ``max(n . l, 0)``
``scene.json``  the resolved scene, medium, calibration, seeds, spp, Mitsuba
                version, render times and the noise estimate (:mod:`~invsss.scenes.noise`)
==============  ==========================================================

Images are one channel when the medium and every light are grey (a NIR-like
pair), else RGB. A medium whose channels differ (Jensen's skin1) is rendered as
one grey medium per channel, each channel taken from its own render.

Depth is taken from Mitsuba's ``position`` AOV, not its ``depth`` AOV: the
latter is the ray distance from the near-clip-shifted origin, not eye z.
"""

from __future__ import annotations

import dataclasses
import json
import os
import platform
import tempfile
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from .. import __version__
from ..forward.profiles import jensen_dipole_total
from ..io import write_image, write_text_atomic
from ..io.result_dir import ResultDir
from .calibration import CALIBRATION_PIXELS, CALIBRATION_SPP, slab_albedo
from .config import SceneConfig
from .mitsuba_scene import import_mitsuba, load_mesh_ply, pigmented_mesh, scene_dict, write_attribute_ply
from .noise import half_render_noise
from .transmission import TRANSMISSION_FILES, albedo_map, transmission_buffers

__all__ = ["SCENE_FILES", "SceneRender", "camera_points", "camera_pose", "fill_light_directions", "light_directions",
           "object_ply", "render_aovs", "render_scene", "scene_writers", "write_scene"]

#: The files of a scene folder, in the order they are written.
SCENE_FILES = ("source.exr", "target.exr", "depth.exr", "mask.png", "normal.exr", "coverage.exr", "light.exr",
               "key.exr", "fill_light.exr", *TRANSMISSION_FILES, "scene.json")


@dataclasses.dataclass(frozen=True)
class SceneRender:
    """A rendered pair and its geometry (arrays as written) plus the ``scene.json`` content."""

    source: np.ndarray  # (H, W, C) float32
    target: np.ndarray | None  # (H, W, C) float32; None when rendered without it
    depth: np.ndarray  # (H, W) float32, mm, 0 off the skin
    mask: np.ndarray  # (H, W) float32 in {0, 1}
    normal: np.ndarray  # (H, W, 3) float32
    coverage: np.ndarray  # (H, W) float32 in [0, 1]
    info: dict
    target_halves: tuple[np.ndarray, np.ndarray] | None
    light: np.ndarray | None = None  # (H, W, 3) float32; None: computed from the depth when written
    key: np.ndarray | None = None  # (H, W, C) float32: the source lit by the first light alone; None: not written
    # thickness.exr, thickness_normal.exr, key_irradiance.exr (transmission_buffers); None: not written
    transmission: dict[str, np.ndarray] | None = None


def _channels(image, count: int) -> np.ndarray:
    return np.asarray(image, np.float64)[..., :count]


def render_aovs(mi, scene: dict) -> dict:
    """Render a Mitsuba scene dict whose integrator is an AOV integrator (the
    ``"geometry"`` and ``"visible"`` kinds of :func:`~invsss.scenes.mitsuba_scene.scene_dict`)
    and return its channels by name as float64 arrays."""
    loaded = mi.load_dict(scene)
    mi.render(loaded)
    bitmap = loaded.sensors()[0].film().bitmap()
    return {name: np.asarray(channel, np.float64) for name, channel in bitmap.split()}


def object_ply(config: SceneConfig, folder: str) -> tuple[str | None, dict | None]:
    """The scene's object as a PLY file in ``folder`` for :func:`~invsss.scenes.mitsuba_scene.scene_dict`
    (a mesh file with its bumps and scale, or the procedural face), and the record
    ``scene.json`` keeps of it; ``(None, None)`` for Mitsuba's own sphere and slab.
    An object with a pigment is made by :func:`render_scene` itself."""
    if config.object.mesh:
        assert config.object.mm_per_unit is not None  # the config requires it with a mesh
        return (load_mesh_ply(config.object.mesh, folder, bumps=config.object.bumps,
                              mm_per_unit=config.object.mm_per_unit, subdivisions=config.object.subdivisions),
                _mesh_record(config.object.mesh))
    if config.object.primitive == "face":
        from .procedural import write_face_ply

        return write_face_ply(config.object, folder)
    return None, None


def _is_grey(config: SceneConfig, coefficients: dict) -> bool:
    colours = [getattr(light, field) for light in config.lights
               for field in ("intensity", "radiance", "irradiance") if hasattr(light, field)]
    return len(coefficients["sigma_s_prime"]) == 1 and not any(isinstance(c, list) for c in colours)


def _mesh_record(path: str) -> dict:
    """The mesh file's name and SHA-256, so a scene.json pins the exact geometry."""
    import hashlib

    with open(path, "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()
    return {"file": os.path.basename(path), "sha256": digest}


def _portable(config: dict) -> dict:
    """The config as recorded: a mesh under the working directory by its relative path.

    ``load_config`` makes mesh paths absolute; a scene.json written in a repository
    should not carry the path of the machine it was rendered on.
    """
    mesh = config["object"].get("mesh")
    if mesh is not None:
        relative = os.path.relpath(mesh)
        if not relative.startswith(os.pardir):
            config = {**config, "object": {**config["object"], "mesh": relative}}
    pigment = config["object"].get("pigment")
    if pigment is not None:
        relative = os.path.relpath(pigment["map"])
        if not relative.startswith(os.pardir):
            config = {**config, "object": {**config["object"], "pigment": {**pigment, "map": relative}}}
    return config


def _grey_media(coefficients: dict) -> list[dict]:
    """The medium as one grey medium, or one grey medium per channel when the channels differ."""
    s, a = coefficients["sigma_s_prime"], coefficients["sigma_a"]
    if len(set(s)) == 1 and len(set(a)) == 1:
        return [{**coefficients, "sigma_s_prime": s[:1], "sigma_a": a[:1]}]
    return [{**coefficients, "sigma_s_prime": [s[c]], "sigma_a": [a[c]]} for c in range(len(s))]


# Over 80 lines, kept whole: the passes one after another on one Mitsuba scene
# (source, key, depth, normals, light, target halves), sharing its seeds.
def render_scene(config: SceneConfig, progress: Callable[[str], None] | None = None, *,
                 target: bool = True) -> SceneRender:
    """Render every pass of ``config`` and return the pair, its geometry and ``scene.json``.

    Parameters
    ----------
    config : SceneConfig
        From :func:`~invsss.scenes.config.load_config` (a mesh path must be absolute
        or relative to the working directory).
    progress : callable, optional
        Called with a short line before each pass.
    target : bool
        False: leave out the path-traced target (``target`` and ``target_halves``
        are None, ``scene.json`` has no noise estimate), for a source, depth and
        mask to fit a photograph with; the target is most of the time.

    Raises
    ------
    InvalidInputError
        Mitsuba or trimesh missing, an unavailable variant, an unreadable or open mesh,
        or a camera that sees no skin.

    Examples
    --------
    >>> from invsss.scenes import parse_config
    >>> config = parse_config({"object": {"primitive": "sphere", "radius": 40.0},
    ...     "camera": {"position": [0.0, 0.0, 300.0], "look_at": [0.0, 0.0, 0.0],
    ...                "fov": 20.0, "width": 16, "height": 16},
    ...     "lights": [{"type": "point", "position": [0.0, 100.0, 300.0], "intensity": 1e5}],
    ...     "medium": {"preset": "thesis-940"}, "spp": 2})
    >>> pair = render_scene(config)
    >>> pair.source.shape, pair.target.shape, pair.depth.shape
    ((16, 16, 1), (16, 16, 1), (16, 16))
    >>> bool(250.0 < pair.depth[8, 8] < 262.0)  # eye z of the sphere's front, 260 mm away
    True
    """
    say = progress or (lambda text: None)
    started = time.perf_counter()
    mi = import_mitsuba(config.variant)
    coefficients = config.medium.coefficients()
    channels = 1 if _is_grey(config, coefficients) else 3
    timings: dict[str, float] = {}

    def timed(name: str, work):
        say(f"scene: {name}")
        t0 = time.perf_counter()
        result = work()
        timings[name] = round(time.perf_counter() - t0, 3)
        return result

    half_spp = config.spp // 2
    seeds: dict[str, Any] = {"source": 2 * config.seed, "target_halves": [2 * config.seed, 2 * config.seed + 1],
             "specular_halves": [2 * config.seed, 2 * config.seed + 1], "calibration": 0}
    with tempfile.TemporaryDirectory(prefix="invsss-scene-") as folder:
        pigment = config.object.pigment
        mesh_ply: str | None
        mesh_record: dict | None
        if pigment is not None:
            # The pigment rides on the vertices of a finer copy of the same surface.
            mesh = config.object.mesh
            assert mesh is not None  # the config allows a pigment only on a mesh
            vertices, faces, transmittance, pigment_record = pigmented_mesh(mesh, pigment)
            mesh_record = {**_mesh_record(mesh), "pigment": pigment_record}
            mesh_ply = write_attribute_ply(os.path.join(folder, "object.ply"), vertices, faces,
                                           {"absorb": 1.0 - np.sqrt(transmittance)})
        else:
            mesh_ply, mesh_record = object_ply(config, folder)
        # The renderer's buffers come from the same object unless it has a coarser copy.
        buffers_ply, buffers_record = mesh_ply, None
        if config.object.buffers_cell is not None:
            from .procedural import write_face_ply

            coarse = config.object.model_copy(update={"cell": config.object.buffers_cell})
            os.mkdir(os.path.join(folder, "buffers"))
            buffers_ply, buffers_record = write_face_ply(coarse, os.path.join(folder, "buffers"))

        def build(kind: str, scene_config: SceneConfig = config, **extra):
            return scene_dict(mi, scene_config, kind, mesh_ply=buffers_ply, coefficients=coefficients, **extra)

        geometry = timed("geometry", lambda: render_aovs(mi, build("geometry")))
        visible = timed("visibility", lambda: render_aovs(mi, build("visible")))
        coverage = np.clip(visible["cov"][..., 0], 0.0, 1.0)
        mask = (coverage >= 0.5).astype(np.float32)
        if not mask.any():
            from ..validation import InvalidInputError

            raise InvalidInputError("camera: sees no skin (no pixel is at least half covered by the object)")
        depth, normal = _depth_and_normal(config, geometry)

        # A chromatic medium is rendered one channel at a time as a grey medium:
        # volpath's sampling of a chromatic medium follows one channel per path and
        # leaves the others (here the far-reaching red) with heavy fireflies.
        media = _grey_media(coefficients)
        # timed() calls its function at once, so the lambdas here and in the loops below
        # read the loop variables of their own iteration (B023 warns of a later call).
        calibrated = [timed(f"calibration {c + 1}/{len(media)}", lambda: slab_albedo(
            mi, medium, max_depth=config.max_depth, seed=seeds["calibration"]))  # noqa: B023
            for c, medium in enumerate(media)]
        albedo = np.concatenate([value for value, _ in calibrated])
        albedo_error = np.concatenate([error for _, error in calibrated])
        albedo_list = albedo.tolist()
        source_albedo = albedo_list if albedo.size > 1 else albedo_list[0]
        source_ply = buffers_ply
        if pigment is not None:
            # The renderer's albedo map: the calibrated albedo times what the pigment leaves.
            source_ply = write_attribute_ply(os.path.join(folder, "source.ply"), vertices, faces,
                                             {"albedo": np.outer(transmittance, np.resize(albedo, 3))})

        def build_source(scene_config: SceneConfig = config):
            return scene_dict(mi, scene_config, "source", mesh_ply=source_ply, coefficients=coefficients,
                              albedo=source_albedo)

        source_scene = mi.load_dict(build_source())
        source = timed("source", lambda: _channels(mi.render(source_scene, spp=config.spp, seed=seeds["source"]),
                                                   channels))
        # The first (key) light's part of the source: a deferred renderer's lighting
        # pass has it, and light-aware terms for one light need it (docs/model.md,
        # section 8). Same seed as the source, so source - key is the other lights'.
        if len(config.lights) > 1:
            alone = config.model_copy(update={"lights": config.lights[:1]})
            key_scene = mi.load_dict(build_source(alone))
            key = timed("key light", lambda: _channels(mi.render(key_scene, spp=config.spp, seed=seeds["source"]),
                                                       channels))
        else:
            key = source
        # The transmission term's buffers, from the geometry pass's points and the source's albedo.
        say("scene: transmission buffers")
        pixel_albedo = albedo if pigment is None else albedo_map(
            mi, scene_dict(mi, config, "geometry", mesh_ply=source_ply), geometry["cov"][..., 0])
        transmission = transmission_buffers(mi, config, build("geometry"), geometry, pixel_albedo, channels)
        scenes = [(mi.load_dict(scene_dict(mi, config, "target", mesh_ply=mesh_ply, coefficients=medium)),
                   mi.load_dict(scene_dict(mi, config, "specular", mesh_ply=mesh_ply, coefficients=medium)))
                  for medium in media] if target else []
        halves = []
        for k in range(2 if target else 0):
            parts = []
            for c, (target_scene, specular_scene) in enumerate(scenes):
                full = timed(f"target half {k + 1}, channel {c + 1}/{len(media)}", lambda: _channels(
                    mi.render(target_scene, spp=half_spp, seed=seeds["target_halves"][k]), channels))  # noqa: B023
                if coefficients["boundary"] == "index-matched":
                    mirror = 0.0  # a null surface reflects nothing
                else:
                    mirror = timed(f"specular half {k + 1}, channel {c + 1}/{len(media)}", lambda: _channels(
                        mi.render(specular_scene, spp=half_spp, seed=seeds["specular_halves"][k]), channels))  # noqa: B023
                parts.append(full - mirror)
            # One grey medium: all channels at once; one per channel: channel c from render c.
            halves.append(parts[0] if len(parts) == 1 else np.stack([p[..., c] for c, p in enumerate(parts)], -1))
    image = 0.5 * (halves[0] + halves[1]) if target else None
    noise = half_render_noise(halves[0], halves[1], mask) if target else None
    dipole = np.asarray(jensen_dipole_total(np.asarray(coefficients["sigma_s_prime"]),
                                            np.asarray(coefficients["sigma_a"]), coefficients["eta"]))
    info = {
        "invsss_version": __version__,
        "mitsuba_version": mi.__version__,
        "variant": config.variant,
        "platform": platform.platform(),
        "config": _portable(config.model_dump()),
        "mesh": mesh_record,
        **({"buffers_mesh": buffers_record} if buffers_record is not None else {}),
        "focal_px": config.camera.focal_length_px,
        "channels": channels,
        "medium": {
            **coefficients,
            "boundary_bsdf": "roughdielectric, Beckmann" if coefficients["boundary"] != "index-matched" else "null",
            "phase": "isotropic (sigma_s = sigma_s')",
        },
        "source_albedo": {
            "value": albedo_list,
            "standard_error": albedo_error.tolist(),
            "method": "path-traced slab of the medium under a uniform sky, boundary reflection "
            "subtracted (invsss.scenes.calibration)",
            "spp": CALIBRATION_SPP,
            "pixels": CALIBRATION_PIXELS,
            "dipole_total": np.atleast_1d(dipole).tolist(),
            "renders": len(media),
        },
        "spp": {"source": config.spp, "key_light": config.spp if len(config.lights) > 1 else 0,
                "target": config.spp if target else 0,
                "target_per_half": half_spp if target else 0, "specular_per_half": half_spp if target else 0,
                "geometry": config.geometry_spp},
        "seeds": seeds,
        "max_depth": config.max_depth,
        "render_seconds": {**timings, "total": round(time.perf_counter() - started, 3)},
        "noise": noise,
        "depth_background": 0.0,
        "normal_frame": "camera: x right, y up, z towards the camera",
        "skin_pixels": int(mask.sum()),
    }
    return SceneRender(
        source=source.astype(np.float32),
        target=None if image is None else image.astype(np.float32),
        depth=depth.astype(np.float32),
        mask=mask,
        normal=normal.astype(np.float32),
        coverage=coverage.astype(np.float32),
        info=info,
        target_halves=(halves[0].astype(np.float32), halves[1].astype(np.float32)) if target else None,
        light=light_directions(config, depth).astype(np.float32),
        key=key.astype(np.float32),
        transmission=transmission,
    )


def _depth_and_normal(config: SceneConfig, aovs: dict) -> tuple[np.ndarray, np.ndarray]:
    """Eye-space z (mm) and camera-space normals from the skin-only AOV pass.

    AOVs of rays that miss are 0 and the box filter averages over all samples, so
    the average over the skin samples is the pixel value divided by the coverage.
    """
    coverage = aovs["cov"][..., 0]
    seen = coverage > 1e-6
    safe = np.where(seen, coverage, 1.0)[..., None]
    position = aovs["pos"] / safe
    origin, right, up, forward = config.camera.frame()
    depth = np.where(seen, (position - origin) @ forward, 0.0)
    world_normal = aovs["nn"] / safe
    normal = np.stack([world_normal @ right, world_normal @ up, -(world_normal @ forward)], axis=-1)
    length = np.linalg.norm(normal, axis=-1, keepdims=True)
    normal = np.where(seen[..., None], normal / np.where(length > 0, length, 1.0), 0.0)
    return depth, normal


def camera_pose(config: SceneConfig) -> tuple[np.ndarray, np.ndarray]:
    """The camera's position (world) and the rotation (3, 3) from world to camera
    space (x right, y up, z towards the camera)."""
    origin, right, up, forward = config.camera.frame()
    return origin, np.stack([right, up, -forward])


def camera_points(config: SceneConfig, depth, within=(0.0, 0.0)) -> np.ndarray:
    """The camera-space points (H, W, 3) seen through the pixel centres at the
    eye-space ``depth`` (mm; 0 gives the camera's own position; 1, the ray's
    direction with unit depth).

    ``within`` = ``(rows, cols)`` moves every pixel's point from its centre by that
    many pixels (-0.5 to 0.5 spans the pixel), for sums over a pixel's footprint."""
    depth = np.asarray(depth, np.float64)
    camera = config.camera
    h, w = depth.shape
    f = camera.focal_length_px
    offset_rows, offset_cols = camera.principal_offset_px
    x = (np.arange(w)[None, :] + 0.5 + within[1] - w / 2 - offset_cols) / f * depth
    y = -(np.arange(h)[:, None] + 0.5 + within[0] - h / 2 - offset_rows) / f * depth
    return np.stack(np.broadcast_arrays(x, y, -depth), axis=-1)


def light_directions(config: SceneConfig, depth, light: int = 0) -> np.ndarray:
    """Unit vectors (H, W, 3) from each seen surface point towards one of the scene's
    lights (``light``: its index; 0, the first, is the key).

    Camera space (x right, y up, z towards the camera), as the light-aware terms
    read them (:class:`invsss.LightBuffers`). The point is rebuilt from the eye-space
    ``depth`` (mm) through the pixel centre; a point, spot or area light is taken
    at its position (an area light at its centre), a directional light as its
    constant reversed direction. 0 where ``depth`` is 0 (no skin seen).

    Examples
    --------
    >>> from invsss.scenes import parse_config
    >>> config = parse_config({"object": {"primitive": "sphere", "radius": 40.0},
    ...     "camera": {"position": [0.0, 0.0, 300.0], "look_at": [0.0, 0.0, 0.0],
    ...                "fov": 20.0, "width": 2, "height": 2},
    ...     "lights": [{"type": "directional", "direction": [0.0, 0.0, -1.0], "irradiance": 1.0}],
    ...     "medium": {"preset": "thesis-940"}})
    >>> light_directions(config, np.full((2, 2), 300.0))[0, 0].round(6) + 0.0
    array([0., 0., 1.])
    """
    depth = np.asarray(depth, np.float64)
    origin, rotation = camera_pose(config)
    points = camera_points(config, depth)
    key = config.lights[light]
    if key.type == "directional":
        towards = np.broadcast_to(-(rotation @ np.asarray(key.direction, np.float64)), points.shape)
    else:
        place = key.center if key.type == "area" else key.position
        towards = rotation @ (np.asarray(place, np.float64) - origin) - points
    towards = towards / np.linalg.norm(towards, axis=-1, keepdims=True)
    return np.where((depth > 0)[..., None], towards, 0.0)


def _light_buffer(result: SceneRender) -> np.ndarray:
    if result.light is not None:
        return result.light
    from .config import parse_config

    return light_directions(parse_config(result.info["config"], "scene.json"), result.depth).astype(np.float32)


def _fill_light_buffer(result: SceneRender) -> np.ndarray | None:
    """Unit vectors towards the second light (None with one light, or no scene
    description to place it): the fill term's buffer."""
    from .config import parse_config

    if "config" not in result.info:
        return None
    return fill_light_directions(parse_config(result.info["config"], "scene.json"), result.depth)


def fill_light_directions(config: SceneConfig, depth) -> np.ndarray | None:
    """``fill_light.exr``: float32 unit vectors towards the scene's second light
    (:func:`light_directions` with ``light=1``), or None for a scene with one light."""
    if len(config.lights) < 2:
        return None
    return light_directions(config, depth, light=1).astype(np.float32)


def scene_writers(result: SceneRender) -> dict[str, Callable[[str], None]]:
    """``{file name: writer(path)}`` for :meth:`invsss.io.result_dir.ResultDir.commit`.

    Examples
    --------
    >>> image, plane = np.ones((4, 4, 1), np.float32), np.ones((4, 4), np.float32)
    >>> flat = SceneRender(image, image, 500 * plane, plane, np.zeros((4, 4, 3), np.float32),
    ...                    plane, {"spp": 2}, (image, image), light=np.zeros((4, 4, 3), np.float32), key=image)
    >>> list(scene_writers(flat)) == [name for name in SCENE_FILES  # one light, no transmission buffers
    ...                               if name not in ("fill_light.exr", *TRANSMISSION_FILES)]
    True
    """
    text = json.dumps(result.info, indent=2) + "\n"
    fill = _fill_light_buffer(result)
    writers = {
        "source.exr": lambda path: write_image(path, result.source),
        "target.exr": lambda path: write_image(path, result.target),
        "depth.exr": lambda path: write_image(path, result.depth),
        "mask.png": lambda path: write_image(path, result.mask),
        "normal.exr": lambda path: write_image(path, result.normal),
        "coverage.exr": lambda path: write_image(path, result.coverage),
        "light.exr": lambda path: write_image(path, _light_buffer(result)),
        "key.exr": lambda path: write_image(path, result.key),
        "fill_light.exr": lambda path: write_image(path, fill),
        **{name: _image_writer(image) for name, image in (result.transmission or {}).items()},
        "scene.json": lambda path: write_text_atomic(path, text),
    }
    if fill is None:
        del writers["fill_light.exr"]
    if result.target is None:
        del writers["target.exr"]
    if result.key is None:
        del writers["key.exr"]
    return writers


def _image_writer(image: np.ndarray) -> Callable[[str], None]:
    return lambda path: write_image(path, image)


def write_scene(result: SceneRender, out, *, overwrite: bool = False) -> list[str]:
    """Write a rendered scene into the folder ``out`` as one result (all files or none).

    Returns the paths written. A folder that already holds a result is refused
    unless ``overwrite`` (see :class:`invsss.io.result_dir.ResultDir`).

    Examples
    --------
    >>> import os, tempfile
    >>> from invsss.scenes import parse_config
    >>> config = parse_config({"object": {"primitive": "sphere", "radius": 40.0},
    ...     "camera": {"position": [0.0, 0.0, 300.0], "look_at": [0.0, 0.0, 0.0],
    ...                "fov": 20.0, "width": 8, "height": 8},
    ...     "lights": [{"type": "point", "position": [0.0, 100.0, 300.0], "intensity": 1e5}],
    ...     "medium": {"preset": "thesis-940"}, "spp": 2})
    >>> folder = os.path.join(tempfile.mkdtemp(), "pair")
    >>> [os.path.basename(p) for p in write_scene(render_scene(config), folder)]  # one light: no fill_light.exr
    ['source.exr', 'target.exr', 'depth.exr', 'mask.png', 'normal.exr', 'coverage.exr', 'light.exr', 'key.exr', 'thickness.exr', 'thickness_normal.exr', 'key_irradiance.exr', 'scene.json']
    """  # noqa: E501
    with ResultDir(os.fspath(out), overwrite=overwrite, names=SCENE_FILES, option="overwrite=True") as folder:
        return folder.commit(scene_writers(result), {"command": "scene"})
