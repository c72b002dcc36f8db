"""Make the bundled pairs in ``data_synthetic/`` (seeded, reproducible): one command for all.

Two kinds of pair:

**Model-made pairs** (``fran_front``, ``fran_turned``, ``leeperrysmith``, ``flat_card``):
a face scan (or a flat card) rendered with Mitsuba 3 as albedo x Lambert shading,
and a target made from it by invsss's own forward model with written-down
parameters, so an estimator can be checked on exactly known answers:

* ``source.exr``  linear RGB without scattering: textured albedo times Lambert shading,
* ``depth.exr``   linear eye-space depth in mm (the distance along the optical axis), 0 off the object,
* ``mask.png``    8-bit skin mask,
* ``target.exr``  ``gain * (channels_mix . render(source, depth, mask, truth)) + offset`` plus
  Gaussian noise, where ``render`` is :func:`invsss.render` with ``model="sog"``,
* ``truth.json``  the parameters and everything else needed to rebuild the target,
* ``preview.png`` source | depth | mask | target, for people.

**Path-traced pairs** (``pt_*``, listed in :data:`PATH_TRACED`): the scene descriptions
``experiments/scenes/<name>.toml`` rendered by :mod:`invsss.scenes` (a volumetric path
tracer, not invsss's model), the files ``invsss scene`` writes. They take minutes each
(``data_synthetic/README.md`` lists each one's time); ``--skip-path-traced`` leaves them
alone, ``--scenes pt_proc_area_940 ...`` remakes some. Which of them are tuning and which
held-out pairs is ``data_synthetic/SPLIT.toml``, written by hand.

Run from the repository root::

    python experiments/make_synthetic.py            # every pair into data_synthetic/
    python experiments/make_synthetic.py --scenes fran_front --out /tmp/synth
    python experiments/make_synthetic.py --skip-path-traced

Every random draw comes from ``numpy.random.default_rng`` seeded per scene and every
Mitsuba render has a fixed seed, so running it again writes the same numbers (on the
same platform: the blur runs in float32). Meshes and textures come from
``experiments/scenes/meshes/`` (see its README for their sources and licences),
loaded with trimesh.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import trimesh
from scipy import ndimage

import invsss
from invsss.io import read_image, srgb_to_linear, write_image
from invsss.scenes import load_config, render_scene, write_scene as write_scene_folder
from invsss.scenes.mitsuba_scene import import_mitsuba

REPO = Path(__file__).resolve().parent.parent
MESHES = REPO / "experiments" / "scenes" / "meshes"
SCENE_CONFIGS = REPO / "experiments" / "scenes"
IMAGE_SIZE = 224  # pixels, square
NOISE_FRACTION = 0.01  # noise std as a fraction of the mean masked target
SOURCE_SPP = 64  # stratified samples per pixel of the Mitsuba source renders

# The thesis's 940 nm forearm fit (its Table 5.1; "8,749" read as 8.749), docs/model.md, section 4.
TABLE_5_1_VARIANCES = [8.749, 2.099, 0.549, 0.5574, 1.194]
TABLE_5_1_WEIGHTS = [0.1478, 0.1323, 0.0004, 0.0527, 0.090]

FRAN_ATTRIBUTION = (
    "Face scan 'fran_cut' (mesh fran_cut.vtk, texture fran_cut.png) from the VTK example data "
    "(VTKData), Copyright (c) 1993-2008 Ken Martin, Will Schroeder, Bill Lorensen, all rights "
    "reserved; redistributed under the VTK data copyright notice (BSD-style) and the Apache "
    "License 2.0 shipped with it. Modified: re-rendered with new camera, lighting, added "
    "albedo noise and synthetic scattering."
)
LEE_PERRY_SMITH_ATTRIBUTION = (
    "'Infinite, 3D Head Scan' by Lee Perry-Smith (Infinite-Realities, www.ir-ltd.net), based on "
    "a work at www.triplegangers.com, licensed under Creative Commons Attribution 3.0 Unported "
    "(https://creativecommons.org/licenses/by/3.0/); glTF conversion (LeePerrySmith.glb, "
    "Map-COL.jpg) from the three.js examples. Modified: re-rendered with new camera, lighting, "
    "added albedo noise and synthetic scattering."
)


# ----------------------------------------------------------------------------- textures


def read_texture(path: Path) -> np.ndarray:
    """An 8-bit sRGB texture as linear float64 (H, W, 3), alpha dropped."""
    return read_image(path).astype(np.float64)


def sample_texture(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup with clamp-to-edge; ``uv`` (..., 2) with v up (row 0 at v = 1)."""
    h, w = texture.shape[:2]
    x = np.clip(uv[..., 0] * w - 0.5, 0, w - 1)
    y = np.clip((1.0 - uv[..., 1]) * h - 0.5, 0, h - 1)
    x0 = np.minimum(np.floor(x).astype(int), w - 2)
    y0 = np.minimum(np.floor(y).astype(int), h - 2)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    top = texture[y0, x0] * (1 - fx) + texture[y0, x0 + 1] * fx
    bottom = texture[y0 + 1, x0] * (1 - fx) + texture[y0 + 1, x0 + 1] * fx
    return top * (1 - fy) + bottom * fy


def texel_uv(shape: tuple[int, int]) -> np.ndarray:
    """The uv (v up) of every texel centre of an image of ``shape`` (rows, columns)."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    return np.stack([(cols + 0.5) / shape[1], 1.0 - (rows + 0.5) / shape[0]], axis=-1)


def skin_detail(rng: np.random.Generator, size: int, strength: float) -> np.ndarray:
    """A multiplicative pore-scale albedo texture (size, size, 1), mean about 1.

    Two octaves of smoothed white noise (about one and three texels) stand in for pores
    and blotches: the photographs lack detail at the scale of the blur, and an estimator
    can only see a blur where there is something to blur.
    """
    fine = ndimage.gaussian_filter(rng.standard_normal((size, size)), 0.7, mode="wrap")
    coarse = ndimage.gaussian_filter(rng.standard_normal((size, size)), 2.5, mode="wrap")
    field = fine / fine.std() + 0.6 * coarse / coarse.std()
    return np.exp(strength * field / field.std())[..., None]


# ----------------------------------------------------------------------------- heads


@dataclasses.dataclass
class Head:
    """A textured head scan: the mesh in mm (outward winding), linear albedo, skin map.

    ``mesh.visual.uv`` has v up (row 0 of the textures at v = 1).
    """

    mesh: "trimesh.Trimesh"
    albedo: np.ndarray  # (H, W, 3) linear
    skin: np.ndarray  # (H', W', 1), 1 where the texture shows skin


def load_fran() -> Head:
    """The VTK 'fran' face in mm, its linear albedo and a skin map in texture space.

    The scan is stored in metres with y up; its triangles wind inwards, so they are
    turned round. The texture is a photograph; the skin map drops texels much darker
    than their surroundings (eyes, eyebrows, nostrils, the mouth line), found with a
    local-contrast rule and checked by eye on the preview.
    """
    mesh = trimesh.load(MESHES / "fran_cut.ply", process=False)
    mesh.apply_scale(1000.0)
    mesh.invert()
    texture = read_texture(MESHES / "fran_cut.png")
    luminance = texture @ np.array([0.2126, 0.7152, 0.0722])
    dark = luminance < 0.5 * ndimage.gaussian_filter(luminance, 6.0)
    dark = ndimage.binary_closing(ndimage.binary_opening(dark), iterations=2)
    skin = ~ndimage.binary_dilation(dark) & (luminance > 0.01)
    return Head(mesh, texture, skin.astype(np.float64)[..., None])


def load_lee_perry_smith(mm_per_unit: float) -> Head:
    """The Lee Perry-Smith bust (y up, face along +z) in mm; its whole texture is skin.

    The asset was made for three.js, which flips images on load: its texture
    coordinates already have v up.
    """
    mesh = trimesh.load(MESHES / "LeePerrySmith.glb", force="mesh", process=False)
    mesh.apply_scale(mm_per_unit)
    texture = read_texture(MESHES / "Map-COL.jpg")
    return Head(mesh, texture, np.ones((4, 4, 1)))


# ----------------------------------------------------------------------------- rendering


@dataclasses.dataclass
class Lighting:
    """Directional lights given in eye space (x right, y up, z away from the camera) plus ambient light.

    An intensity ``k`` gives a white Lambertian surface facing the light a radiance
    of ``k``; ``ambient`` is the radiance of a uniform sky (occluded where the head
    hides it).
    """

    directions: list  # of (3,), pointing towards each light; normalised when used
    intensities: list  # of float
    ambient: float

    def to_dict(self) -> dict:
        unit = [list(np.round(np.asarray(d) / np.linalg.norm(d), 6)) for d in self.directions]
        return {
            "eye_space_directions": unit,
            "intensities": self.intensities,
            "ambient": self.ambient,
        }


@dataclasses.dataclass
class Rendering:
    source: np.ndarray  # (H, W, 3) linear
    depth: np.ndarray  # (H, W) mm, 0 off the object
    mask: np.ndarray  # (H, W) 0 or 1
    camera: dict


@dataclasses.dataclass(frozen=True)
class CameraFrame:
    """A pinhole camera looking from ``position`` at ``look_at`` with y up."""

    position: np.ndarray
    right: np.ndarray
    up: np.ndarray
    forward: np.ndarray

    @classmethod
    def look_at(cls, position, target) -> "CameraFrame":
        position = np.asarray(position, np.float64)
        forward = np.asarray(target, np.float64) - position
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, [0.0, 1.0, 0.0])
        right /= np.linalg.norm(right)
        return cls(position, right, np.cross(right, forward), forward)

    def to_world(self, eye_direction) -> np.ndarray:
        x, y, z = np.asarray(eye_direction, np.float64) / np.linalg.norm(eye_direction)
        return x * self.right + y * self.up + z * self.forward


def _mitsuba():
    mi = import_mitsuba("scalar_rgb")
    mi.set_log_level(mi.LogLevel.Warn)
    return mi


def _write_mitsuba_mesh(mesh, path: Path) -> None:
    """PLY for Mitsuba, whose bitmap lookup puts v = 0 at the image's top row."""
    flipped = mesh.copy()
    uv = np.asarray(mesh.visual.uv, np.float64).copy()
    uv[:, 1] = 1.0 - uv[:, 1]
    flipped.visual = trimesh.visual.TextureVisuals(uv=uv)
    flipped.export(path, file_type="ply", vertex_normal=True)


def _bitmap(path: Path) -> dict:
    return {"type": "bitmap", "filename": str(path), "raw": True, "filter_type": "bilinear", "wrap_mode": "clamp"}


@dataclasses.dataclass(frozen=True)
class CameraMove:
    """A small move of the camera against the one a pair was made with (a misregistered photo).

    The image content moves by ``shift_px`` (rows, columns), turns by
    ``rotation_deg`` (counter-clockwise as displayed, i.e. with rows pointing
    down) and grows by ``zoom`` about the image centre: the warp
    ``experiments/photo_robustness.misregister`` applies by resampling, made by
    the optics instead (a principal-point offset, a roll about the optical axis
    and a focal length change), so nothing is interpolated.
    """

    shift_px: tuple[float, float] = (0.0, 0.0)
    rotation_deg: float = 0.0
    zoom: float = 1.0


def render_head(head: Head, frame: CameraFrame, focal_px: float, lighting: Lighting, seed: int,
                move: CameraMove = CameraMove()) -> Rendering:
    """Render ``head`` with Mitsuba 3: albedo x Lambert shading (with shadows), depth and skin mask.

    The albedo texture (already multiplied by the detail texture) is looked up by
    Mitsuba; each light is rendered on its own (direct light only) and the images
    are summed, so the directional lights add no Monte Carlo noise. The mask is the
    front-facing surface whose skin map covers at least half the pixel. Depth is
    eye-space z averaged over the pixel's samples on the head, 0 off it.
    """
    mi = _mitsuba()
    size = IMAGE_SIZE
    fov = float(np.degrees(2.0 * np.arctan(size / 2.0 / (focal_px * move.zoom))))
    # Rolling the camera turns the picture the other way; depth (along the
    # optical axis) is unchanged by a roll. Signs checked by registering the
    # moved render against the bundled one.
    a = np.radians(move.rotation_deg)
    up = np.cos(a) * frame.up + np.sin(a) * frame.right
    with tempfile.TemporaryDirectory(prefix="make-synthetic-") as folder:
        folder = Path(folder)
        _write_mitsuba_mesh(head.mesh, folder / "head.ply")
        write_image(folder / "albedo.exr", head.albedo.astype(np.float32))
        write_image(folder / "skin.exr", np.repeat(head.skin, 3, axis=-1).astype(np.float32))

        def scene(bsdf: dict, integrator: dict, emitter: dict | None = None, spp: int = SOURCE_SPP):
            description = {
                "type": "scene",
                "integrator": integrator,
                "sensor": {
                    "type": "perspective", "fov": fov, "fov_axis": "x", "near_clip": 1.0, "far_clip": 1e5,
                    "principal_point_offset_x": -move.shift_px[1] / size,
                    "principal_point_offset_y": -move.shift_px[0] / size,
                    "to_world": mi.ScalarTransform4f().look_at(
                        origin=frame.position.tolist(), target=(frame.position + frame.forward).tolist(),
                        up=up.tolist()),
                    "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"},
                             "pixel_format": "rgb"},
                    "sampler": {"type": "stratified", "sample_count": spp, "seed": seed},
                },
                "head": {"type": "ply", "filename": str(folder / "head.ply"), "bsdf": bsdf},
            }
            if emitter is not None:
                description["light"] = emitter
            loaded = mi.load_dict(description)
            mi.render(loaded)
            return {name: np.asarray(channel, np.float64)
                    for name, channel in loaded.sensors()[0].film().bitmap().split()}

        aovs = {"type": "aov", "aovs": "pos:position,nn:sh_normal,cov:albedo"}
        geometry = scene({"type": "diffuse", "reflectance": {"type": "rgb", "value": 1.0}}, aovs)
        skin = scene({"type": "diffuse", "reflectance": _bitmap(folder / "skin.exr")},
                     {"type": "aov", "aovs": "cov:albedo"})["cov"][..., 0]
        albedo = {"type": "diffuse", "reflectance": _bitmap(folder / "albedo.exr")}
        direct = {"type": "path", "max_depth": 2, "hide_emitters": True}
        emitters = [
            {"type": "directional", "direction": (-frame.to_world(d)).tolist(),
             # A directional light's irradiance E gives a white Lambertian surface facing
             # it a radiance E / pi.
             "irradiance": {"type": "rgb", "value": float(np.pi * k)}}
            for d, k in zip(lighting.directions, lighting.intensities)
        ] + [{"type": "constant", "radiance": {"type": "rgb", "value": float(lighting.ambient)}}]
        source = sum(scene(albedo, direct, emitter)["<root>"][..., :3] for emitter in emitters)
    coverage = geometry["cov"][..., 0]
    seen = coverage > 1e-6
    safe = np.where(seen, coverage, 1.0)[..., None]
    position, normal = geometry["pos"] / safe, geometry["nn"] / safe
    towards_camera = frame.position - position
    front = seen & (np.einsum("hwc,hwc->hw", normal, towards_camera) > 0)
    mask = front & (coverage >= 0.5) & (skin >= 0.5 * coverage)
    depth = np.where(seen, (position - frame.position) @ frame.forward, 0.0)
    return Rendering(source, depth, mask.astype(np.float64), {})


HEADS = {
    "fran": {
        "load": lambda spec: load_fran(),
        # The scan's mean outward normal with its small vertical part dropped.
        "facing": [0.8121, 0.0, -0.5835],
        "attribution": FRAN_ATTRIBUTION,
        "files": ["experiments/scenes/meshes/fran_cut.ply", "experiments/scenes/meshes/fran_cut.png"],
    },
    "leeperrysmith": {
        "load": lambda spec: load_lee_perry_smith(spec["mm_per_unit"]),
        "facing": [0.0, 0.0, 1.0],
        "attribution": LEE_PERRY_SMITH_ATTRIBUTION,
        "files": ["experiments/scenes/meshes/LeePerrySmith.glb", "experiments/scenes/meshes/Map-COL.jpg"],
    },
}


def rotation_y(degrees: float) -> np.ndarray:
    a = np.radians(degrees)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def face_scene(spec: dict, rng: np.random.Generator, move: CameraMove = CameraMove()) -> tuple[Rendering, dict]:
    """Put a pinhole camera in front of the head (turned and tilted) and render it."""
    head_info = HEADS[spec["mesh"]]
    head = head_info["load"](spec)
    detail = skin_detail(rng, spec["detail_texels"], spec["detail_strength"])
    # The detail is attached to the surface: bake it into the albedo texture.
    head.albedo = head.albedo * sample_texture(detail, texel_uv(head.albedo.shape[:2]))
    centre = np.asarray(spec["look_at_mm"], np.float64)
    view = rotation_y(spec["turn_deg"]) @ np.asarray(head_info["facing"])
    view = view + np.array([0.0, np.tan(np.radians(spec["tilt_deg"])), 0.0])
    view /= np.linalg.norm(view)
    frame = CameraFrame.look_at(centre + spec["distance_mm"] * view, centre)
    rendering = render_head(head, frame, spec["focal_px"], Lighting(**spec["lighting"]), spec["seed"], move)
    c = (IMAGE_SIZE - 1) / 2.0
    rendering.camera = {
        "model": "pinhole",
        "focal_px": spec["focal_px"],
        "principal_point_px": [c, c],
        "distance_mm": spec["distance_mm"],
        "position_mm": np.round(frame.position, 3).tolist(),
        "look_at_mm": centre.tolist(),
        "up": [0.0, 1.0, 0.0],
        "head_turn_deg": spec["turn_deg"],
        "tilt_deg": spec["tilt_deg"],
        "background_depth_mm": 0.0,
        "renderer": f"Mitsuba {import_mitsuba('scalar_rgb').__version__} scalar_rgb, "
        f"{SOURCE_SPP} stratified samples per pixel, box filter, direct light only",
    }
    source = {"files": head_info["files"], "attribution": head_info["attribution"]}
    if spec["mesh"] == "leeperrysmith":
        source["mm_per_unit"] = spec["mm_per_unit"]
    return rendering, source


def card_scene(spec: dict, rng: np.random.Generator) -> tuple[Rendering, dict]:
    """A flat card square to the optical axis, printed with a crop of a face texture.

    Every pixel has the same eye depth, so all depth slopes are exactly 0: the
    correction and maxdd have no effect on the target and cannot be estimated.
    The skin mask is an ellipse on the card (the rest stands for cloth or paper).
    The card faces the camera, so its shading is the same everywhere: it is
    computed here rather than rendered.
    """
    albedo = read_texture(MESHES / "Map-COL.jpg")
    detail = skin_detail(rng, spec["detail_texels"], spec["detail_strength"])
    size, f, distance = IMAGE_SIZE, spec["focal_px"], spec["distance_mm"]
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float64)
    (u0, u1), (v0, v1) = spec["uv_crop"]
    t = (cols + 0.5) / size, (rows + 0.5) / size
    uv = np.stack([u0 + (u1 - u0) * t[0], v1 - (v1 - v0) * t[1]], axis=-1)
    lighting = Lighting(**spec["lighting"])
    # Lambert for the card's normal, which points at the camera (eye z = -1).
    shading = lighting.ambient + sum(
        k * max(-float(d[2]) / float(np.linalg.norm(d)), 0.0)
        for d, k in zip(lighting.directions, lighting.intensities))
    source = sample_texture(albedo, uv) * sample_texture(detail, uv) * shading
    c = (size - 1) / 2.0
    ellipse = ((cols - c) / (0.40 * size)) ** 2 + ((rows - c) / (0.46 * size)) ** 2 <= 1.0
    camera = {
        "model": "pinhole",
        "focal_px": f,
        "principal_point_px": [c, c],
        "distance_mm": distance,
        "card_width_mm": size * distance / f,
    }
    depth = np.full((size, size), distance)
    rendering = Rendering(source, depth, ellipse.astype(np.float64), camera)
    source_info = {
        "files": ["experiments/scenes/meshes/Map-COL.jpg"],
        "attribution": LEE_PERRY_SMITH_ATTRIBUTION,
        "uv_crop": spec["uv_crop"],
    }
    return rendering, source_info


# ----------------------------------------------------------------------------- targets


def slope_fractions(depth: np.ndarray, mask: np.ndarray, maxdd: float) -> dict:
    """Fraction of masked pixels whose |dd/dx| (|dd/dy|) exceeds ``maxdd`` (docs/model.md, section 2)."""
    dy, dx = np.gradient(depth)
    skin = mask > 0.5
    return {
        "x": float(np.mean(np.abs(dx[skin]) > maxdd)),
        "y": float(np.mean(np.abs(dy[skin]) > maxdd)),
    }


def noise_free_target(source, depth, mask, params, *, gain, offset, channels_mix, model="sog", tap_weights=None):
    """``gain * (channels_mix . render(source, depth, mask, params)) + offset``, float64:
    the formula truth.json records (``channels_mix`` None: gain and offset per channel)."""
    scattered = np.asarray(invsss.render(source, depth, mask, params, model=model, tap_weights=tap_weights),
                           np.float64)
    if channels_mix is not None:
        scattered = scattered @ np.asarray(channels_mix, np.float64)[:, None]
    return np.asarray(gain) * scattered + np.asarray(offset)


def make_target(rendering: Rendering, spec: dict, rng: np.random.Generator):
    """``gain * (channels_mix . render(source)) + offset + noise``; returns (target, sigma).

    The noise is i.i.d. Gaussian with one standard deviation for the whole image:
    ``NOISE_FRACTION`` of the mean noise-free target over the mask.
    """
    params = invsss.SSSParams.from_dict(spec["params"], source=f"scene {spec['name']}")
    clean = noise_free_target(rendering.source, rendering.depth, rendering.mask, params,
                              gain=spec["gain"], offset=spec["offset"], channels_mix=spec["channels_mix"])
    sigma = NOISE_FRACTION * float(clean[rendering.mask > 0.5].mean())
    target = clean + sigma * rng.standard_normal(clean.shape)
    return target, sigma


# ----------------------------------------------------------------------------- files


def preview(rendering: Rendering, target: np.ndarray) -> np.ndarray:
    """source | depth | mask | target as one linear image for an 8-bit sRGB PNG.

    Source and target are each exposed to their own 99th percentile on skin; depth
    shows near as bright over the skin's depth range, the background black.
    """
    skin = rendering.mask > 0.5
    d = rendering.depth
    near, far = d[skin].min(), d[skin].max()
    if far - near > 1e-6:
        depth_view = np.where(d > 0, np.clip((far - d) / (far - near), 0, 1), 0.0)
    else:  # flat: one grey
        depth_view = np.full_like(d, 0.5)
    height = d.shape[0]
    tiles = [
        rendering.source * 0.8 / np.percentile(rendering.source[skin], 99),
        srgb_to_linear(0.1 + 0.9 * depth_view)[..., None],
        rendering.mask[..., None],
        target * 0.8 / np.percentile(target[skin], 99),
    ]
    row = []
    for tile in tiles:
        row += [np.broadcast_to(tile, (height, tile.shape[1], 3)), np.ones((height, 2, 3))]
    return np.clip(np.concatenate(row[:-1], axis=1), 0.0, 1.0)


def write_exr(path: Path, image: np.ndarray) -> None:
    """float32 OpenEXR, zip-compressed, with a fixed timestamp.

    Not :func:`invsss.io.write_image`: OpenImageIO stamps EXR files with the current
    time, and the bundled files should come out byte-identical on every run.
    """
    image = np.ascontiguousarray(image, np.float32)
    image = image[..., None] if image.ndim == 2 else image
    spec = oiio.ImageSpec(image.shape[1], image.shape[0], image.shape[2], oiio.FLOAT)
    spec.channelnames = {1: ("Y",), 3: ("R", "G", "B")}[image.shape[2]]
    spec.attribute("compression", "zip")
    spec.attribute("DateTime", "2000:01:01 00:00:00")
    output = oiio.ImageOutput.create(str(path))
    if output is None or not output.open(str(path), spec) or not output.write_image(image):
        raise OSError(f"{path}: cannot write ({oiio.geterror()})")
    output.close()


def write_scene(folder: Path, rendering: Rendering, target: np.ndarray, truth: dict) -> None:
    """The five data files and the preview."""
    folder.mkdir(parents=True, exist_ok=True)
    write_exr(folder / "source.exr", rendering.source)
    write_exr(folder / "target.exr", target)
    write_exr(folder / "depth.exr", rendering.depth)
    write_image(folder / "mask.png", rendering.mask.astype(np.float32))  # 0 and 1 encode exactly
    write_image(folder / "preview.png", preview(rendering, target).astype(np.float32))
    (folder / "truth.json").write_text(json.dumps(with_fit_view(truth, folder), indent=2) + "\n")


def with_fit_view(truth: dict, folder: Path) -> dict:
    """``truth`` plus the keys that compare it with a fit (docs/truth-json.md).

    ``weights_normalised`` is the form a fit writes: per-channel sums of 1, one
    column per target channel. ``undetermined`` and ``undetermined_why`` are what
    fits of the scene report; they come from running the estimator, not from the
    generator, so a regenerated scene keeps the lists of the truth.json it
    replaces (re-check them with a fit when the scene changes).
    """
    weights = np.asarray(truth["weights"], np.float64)
    channels = 1 if truth.get("channels_mix") is not None else len(np.atleast_1d(truth["gain"]))
    if weights.ndim == 1 and channels > 1:
        weights = np.repeat(weights[:, None], channels, axis=1)
    out = dict(truth)
    out["weights_normalised"] = np.round(weights / weights.sum(axis=0), 6).tolist()
    previous = folder / "truth.json"
    if previous.exists():
        measured = json.loads(previous.read_text())
        for key in ("undetermined", "undetermined_why"):
            if key in measured:
                out[key] = measured[key]
    return out


# ----------------------------------------------------------------------------- scenes

KEY_AND_FILL = {  # eye space: x right, y up, z away from the camera
    "directions": [[-0.5, 0.6, -0.7], [0.7, 0.1, -0.6]],
    "intensities": [0.9, 0.35],
    "ambient": 0.06,
}


def _table_5_1(sss_level: float, correction: float, maxdd: float) -> dict:
    return {
        "sss_level": sss_level,
        "correction": correction,
        "maxdd": maxdd,
        "weights": TABLE_5_1_WEIGHTS,
        "variances": TABLE_5_1_VARIANCES,
    }


# sss_level equals the focal length in pixels: with depth in mm that makes the
# variances true mm^2 (docs/model.md, section 2). correction and maxdd are chosen so that a
# sizeable share of skin pixels has slopes on each side of maxdd (printed when run).
SCENES = {
    "fran_front": {
        "about": "VTK 'fran' face scan seen from the front; RGB source, 1-channel NIR-like target "
        "(a fixed RGB mix of the scattered image).",
        "kind": "face", "seed": 101, "mesh": "fran", "look_at_mm": [50.0, -128.0, -60.0],
        "distance_mm": 500.0, "focal_px": 600.0, "turn_deg": 0.0, "tilt_deg": 5.0,
        "detail_texels": 512, "detail_strength": 0.12, "lighting": KEY_AND_FILL,
        "params": _table_5_1(600.0, 800.0, 0.5),
        "channels_mix": [0.6, 0.3, 0.1], "gain": [0.8], "offset": [0.01],
    },
    "fran_turned": {
        "about": "The same scan turned 30 degrees and seen from slightly below, closer; RGB "
        "source, RGB target with per-channel gain and offset.",
        "kind": "face", "seed": 202, "mesh": "fran", "look_at_mm": [50.0, -128.0, -60.0],
        "distance_mm": 450.0, "focal_px": 540.0, "turn_deg": 30.0, "tilt_deg": -8.0,
        "detail_texels": 512, "detail_strength": 0.12, "lighting": KEY_AND_FILL,
        "params": _table_5_1(540.0, 800.0, 0.5),
        "channels_mix": None, "gain": [1.1, 1.0, 0.9], "offset": [0.0, 0.005, 0.01],
    },
    "leeperrysmith": {
        "about": "Lee Perry-Smith head scan (three.js glTF) in three-quarter view from slightly "
        "above; RGB source, "
        "1-channel NIR-like target.",
        "kind": "face", "seed": 303, "mesh": "leeperrysmith", "mm_per_unit": 45.0,
        "look_at_mm": [-4.0, 50.0, 40.0], "distance_mm": 550.0, "focal_px": 450.0,
        "turn_deg": -25.0, "tilt_deg": 10.0,
        "detail_texels": 512, "detail_strength": 0.12, "lighting": KEY_AND_FILL,
        "params": _table_5_1(450.0, 800.0, 0.5),
        "channels_mix": [0.5, 0.35, 0.15], "gain": [1.2], "offset": [0.0],
    },
    "flat_card": {
        "about": "A flat card square to the camera, printed with a crop of the Lee Perry-Smith "
        "colour map; constant depth, so correction and maxdd have no effect (undetermined). "
        "RGB source, RGB target.",
        "kind": "card", "seed": 404, "uv_crop": [[0.30, 0.70], [0.42, 0.82]],
        "distance_mm": 500.0, "focal_px": 500.0,
        "detail_texels": 512, "detail_strength": 0.12, "lighting": KEY_AND_FILL,
        "params": _table_5_1(500.0, 800.0, 0.5),
        "undetermined": ["correction", "maxdd"],
        "channels_mix": None, "gain": [1.0, 0.95, 0.9], "offset": [0.01, 0.01, 0.01],
    },
}


def render_moved_view(name: str, move: CameraMove) -> Rendering:
    """The source, depth and mask of face scene ``name`` seen by a camera moved by ``move``.

    Same mesh, albedo detail (drawn first from the scene's seed), lighting and
    sampler seed as the bundled pair; only the camera differs. Float32, as the
    pair's files hold them.
    """
    spec = dict(SCENES[name], name=name)
    if spec["kind"] != "face":
        raise ValueError(f"{name}: only face scenes can be seen from a moved camera")
    rendering, _ = face_scene(spec, np.random.default_rng(spec["seed"]), move)
    return dataclasses.replace(
        rendering,
        source=rendering.source.astype(np.float32),
        depth=rendering.depth.astype(np.float32),
        mask=rendering.mask.astype(np.float32),
    )


def make_scene(name: str, out: Path) -> dict:
    """Render one scene, write its files, return its truth record."""
    spec = dict(SCENES[name], name=name)
    rng = np.random.default_rng(spec["seed"])
    build = face_scene if spec["kind"] == "face" else card_scene
    rendering, mesh_source = build(spec, rng)
    # From here on use exactly the values the files will hold.
    rendering = dataclasses.replace(
        rendering,
        source=rendering.source.astype(np.float32),
        depth=rendering.depth.astype(np.float32),
        mask=rendering.mask.astype(np.float32),
    )
    target, noise_sigma = make_target(rendering, spec, rng)
    fractions = slope_fractions(rendering.depth, rendering.mask, spec["params"]["maxdd"])
    truth = dict(spec["params"])
    truth.update(
        model="sog",
        tap_weights="jimenez",
        gain=spec["gain"],
        offset=spec["offset"],
        channels_mix=spec["channels_mix"],
        undetermined=spec.get("undetermined", []),
        noise_sigma=noise_sigma,
        noise={
            "kind": "gaussian, independent per pixel and channel, over the whole image",
            "sigma_relative_to_mean_masked_target": NOISE_FRACTION,
        },
        focal_px=spec["focal_px"],
        scene={
            "about": spec["about"],
            "formula": "target = gain * (channels_mix . render(source, depth, mask, params, "
            "model='sog')) + offset + noise; with channels_mix null, gain and offset are per "
            "channel of an RGB target",
            "fraction_of_mask_with_slope_above_maxdd": fractions,
            "camera": rendering.camera,
            "lighting": Lighting(**spec["lighting"]).to_dict(),
            "albedo_detail": {"texels": spec["detail_texels"], "log_std": spec["detail_strength"]},
            "image_size": [IMAGE_SIZE, IMAGE_SIZE],
            "depth": "linear eye-space depth in mm (distance along the optical axis)",
            "mesh_source": mesh_source,
            "seed": spec["seed"],
            "generator": "python experiments/make_synthetic.py",
        },
    )
    write_scene(out / name, rendering, target, truth)
    skin = rendering.mask > 0.5
    print(
        f"{name:14s} mask {skin.mean():.2f} of image | depth {rendering.depth[skin].min():.0f}-"
        f"{rendering.depth[skin].max():.0f} mm | slopes > maxdd: x {fractions['x']:.2f}, "
        f"y {fractions['y']:.2f} | noise sigma {noise_sigma:.4g}"
    )
    return truth


README_HEAD = """\
# Synthetic photo pairs with known parameters

Small rendered image pairs for testing the estimator: each scene is a source image
*without* subsurface scattering, its depth and skin mask, and a target made from them
with the `sog` model of `invsss.render` and parameters that are written down, plus
known photometric gain, offset, channel mix and noise. Fitting a scene should give
back `truth.json`.

Made by `python experiments/make_synthetic.py` (run from the repository root; about
20 s on one CPU core). The script is seeded: running it again rewrites these files
byte for byte on the same platform. `tests/scripts/test_synthetic_data.py` loads every scene
and checks that the target equals the recorded model plus noise of the recorded size.

## Files in each scene folder

| file | content |
|---|---|
| `source.exr` | (H, W, 3) float32, linear: albedo x Lambert shading, no scattering |
| `target.exr` | (H, W, 1) or (H, W, 3) float32, linear: see the formula below |
| `depth.exr` | (H, W) float32: linear eye-space depth in mm (distance along the optical axis) |
| `mask.png` | 8-bit, 255 on skin, 0 elsewhere |
| `truth.json` | params.json keys and `model`, `tap_weights`, `gain`, `offset`, `channels_mix`, `undetermined`, `noise_sigma`, `noise`, `focal_px`, and `scene` (camera, lights, mesh source and attribution, seed) |
| `preview.png` | source, depth, mask, target side by side (for people, not for tests) |

EXR files are float32 with zip compression. To use a scene:

    import json, invsss
    folder = "data_synthetic/fran_front/"
    pair = invsss.load_pair(*(folder + f for f in ("source.exr", "target.exr", "depth.exr", "mask.png")))
    truth = json.load(open(folder + "truth.json"))
    params = invsss.SSSParams.from_dict({k: truth[k] for k in invsss.io.PARAMS_KEYS})

(`truth.json` carries more keys than a params file, so `invsss.read_params` refuses it.)

    target = gain * (channels_mix . render(source, depth, mask, params, model="sog")) + offset + noise

`channels_mix` (3 numbers) turns the scattered RGB image into one NIR-like channel; where
it is `null` the target is RGB and `gain`, `offset` are per channel. `noise` is i.i.d.
Gaussian over the whole image with standard deviation `noise_sigma`, set to 1 % of the
mean noise-free target on the mask.

## How the images were made

A pinhole camera (principal point at the image centre, square pixels, focal length
`focal_px`) looks at a textured mesh, rendered with Mitsuba 3 (`scalar_rgb`, 64
stratified samples per pixel, box filter, so each pixel is the average over its area).
Texture colours are sRGB-decoded to linear and multiplied by a seeded two-octave
log-normal noise texture (about 12 % std, attached to the surface) so that there is
pore-scale detail for the blur to act on. Shading is Lambert from a key and a fill
directional light plus a little light from a uniform sky, direct light only, with cast
shadows. Depth is eye-space z averaged over the pixel's samples on the mesh, 0 where the
mesh is not seen (the renderer convention `invsss` accepts); the background of the source
is black. Meshes and textures: `experiments/scenes/meshes/`.

The scattering parameters are the thesis's 940 nm fit (its Table 5.1) for every scene:
variances `[8.749, 2.099, 0.549, 0.5574, 1.194]` mm^2 and weights
`[0.1478, 0.1323, 0.0004, 0.0527, 0.090]` (note the near-equal 0.549/0.5574 pair whose
first weight is almost 0: only their sum is well determined). `sss_level` equals
`focal_px`, so with depth in mm the variances are in true mm^2. `correction` = 800 and
`maxdd` = 0.5 mm per pixel give a real share of skin pixels on each side of `maxdd`
(the table lists the shares of skin pixels with |dd/dx|, |dd/dy| > maxdd).

Skin masks (pixels at least half covered by the mesh, front facing): for the fran scan, surface whose texture is not much darker than
its surroundings (a local-contrast rule that removes eyes, eyebrows, nostrils and the
mouth line, and also a baked shadow beside the nose); for Lee Perry-Smith, all front-facing
surface of the bust; for the card, an ellipse.

## Scenes

"""

README_ATTRIBUTION = """\

## Sources and attribution

The images are derived works of two scanned heads. Both licences ask that the source is
named and that changes are stated; the licence texts are in `LICENSES/`.

**fran_front, fran_turned** use the face scan "fran" (`fran_cut.vtk`, `fran_cut.png`)
from the VTK example data (VTKData), Copyright (c) 1993-2008 Ken Martin, Will Schroeder,
Bill Lorensen, all rights reserved. It is distributed with the VTK copyright notice (a
BSD-style licence: keep the copyright notice, the list of conditions and the disclaimer
with any redistribution, and do not use the authors' names to endorse derived products)
and with the Apache License 2.0 (give recipients a copy of the licence, say that the
files were changed, keep the attribution notices). Both texts are copied unchanged in
`LICENSES/vtk-data-Copyright.txt` and `LICENSES/vtk-data-LICENSE-Apache-2.0.txt`.
No endorsement by the VTK authors is implied.

**pt_fran_dir_940, pt_fran_dir_rough_940, pt_fran_point_fill_940 and
pt_fran_smooth_point_fill_940** use the same scan, closed into a solid by
`experiments/scenes/meshes/close_fran.py` (`fran_closed.ply`: the scan turned to look
along +z, scaled to millimetres, and closed behind by a cone of triangles from its rim
to a point inside; the scan's own triangles are unchanged, its texture is not used;
pt_fran_smooth_point_fill_940 renders it refined by two levels of Loop subdivision).

**leeperrysmith, flat_card and the path-traced pt_face_940, pt_face_940_turned,
pt_face_skin1, pt_face_ear_backlit_940, pt_face_rough_area_940, pt_face_rough_940,
pt_face_ear_glow_940, pt_face_nose_sidelit_940, pt_face_nose_backlit_940 and
twowave_face** use "Infinite, 3D Head Scan" by Lee Perry-Smith (Infinite-Realities,
www.ir-ltd.net), based on a work at www.triplegangers.com, licensed under Creative
Commons Attribution 3.0 Unported (https://creativecommons.org/licenses/by/3.0/); the
licence note asks that users always say where they got the files. We took the glTF
conversion `LeePerrySmith.glb` and its colour map `Map-COL.jpg` as distributed with the
three.js examples (examples/models/gltf/LeePerrySmith/, via a verbatim copy in
github.com/espisepi/t-shirt-configurator-espinaco). The licence note is copied in
`LICENSES/LeePerrySmith_License.txt`.

Changes made to both (for all scenes): the meshes were re-rendered here with a new camera
and lighting and scaled to millimetres (fran: stored in metres; Lee Perry-Smith: an
estimated 45 mm per model unit, 44 mm in the path-traced pairs); for the model-made pairs
their textures were multiplied by synthetic noise and the targets add synthetic subsurface
scattering, a colour mix and noise; the path-traced pairs use the untextured mesh as the
boundary of a scattering medium, and `twowave_face` also the colour map's green channel
as an absorbing layer on that boundary (the mesh split into four triangles per triangle
twice to carry it). The flat card shows a crop of
the Lee Perry-Smith colour map as a flat picture.

**pt_proc_area_940, pt_proc_lowpoly_dir_940, pt_proc_dir_fill_940,
pt_proc_lowpoly_smooth_dir_940 and pt_proc_ear_glow_940** use no outside data: their
head is made by `invsss.scenes.procedural` (a signed distance field meshed by marching
cubes).
"""

LICENCE_FILES = {
    "vtk-data-Copyright.txt": "Copyright_vtk-data.txt",
    "vtk-data-LICENSE-Apache-2.0.txt": "LICENSE_vtk-data.txt",
    "LeePerrySmith_License.txt": "LeePerrySmith_License.txt",
}


def written_by_hand(readme: Path, generated: str) -> str:
    """The ``## `` sections of an existing ``readme`` that ``generated`` does not hold
    (written by hand, such as the two-wavelength pair's), so that writing the README
    again keeps them; empty when there is no README."""
    if not readme.is_file():
        return ""
    kept = []
    for section in readme.read_text().split("\n## ")[1:]:
        heading = section.splitlines()[0]
        if f"## {heading}\n" not in generated:
            kept.append("\n## " + section.rstrip("\n") + "\n")
    return "".join(kept)


def write_readme(out: Path, truths: dict) -> None:
    """README.md with a table of the scenes built from their truth records; licence copies."""
    (out / "README.md").write_text(readme_text(out, truths))
    licences = out / "LICENSES"
    licences.mkdir(exist_ok=True)
    for copy, original in LICENCE_FILES.items():
        (licences / copy).write_bytes((MESHES / original).read_bytes())


def readme_text(out: Path, truths: dict) -> str:
    """The README of ``out``: the scenes' table from their truth records, the path-traced
    pairs' from their scene.json files, and the sections written by hand kept."""
    about = [f"- `{name}`: {t['scene']['about']}" for name, t in truths.items()]
    rows = [
        "",
        "| scene | camera | target | gain | offset | channels_mix | noise_sigma | "
        "slopes > maxdd (x, y) | undetermined |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, t in truths.items():
        cam = t["scene"]["camera"]
        fr = t["scene"]["fraction_of_mask_with_slope_above_maxdd"]
        channels = "1 (NIR-like)" if t["channels_mix"] else "RGB"
        rows.append(
            f"| `{name}` | {cam['distance_mm']:g} mm, f = {t['focal_px']:g} px | {channels} | "
            f"{t['gain']} | {t['offset']} | {t['channels_mix'] or '-'} | "
            f"{t['noise_sigma']:.3g} | {fr['x']:.2f}, {fr['y']:.2f} | "
            f"{', '.join(t['undetermined']) or '-'} |"
        )
    params = [
        "",
        "True scattering parameters (model `sog`, tap weights `jimenez`):",
        "",
        "| scene | sss_level | correction | maxdd |",
        "|---|---|---|---|",
    ]
    params += [
        f"| `{name}` | {t['sss_level']:g} | {t['correction']:g} | {t['maxdd']:g} |"
        for name, t in truths.items()
    ]
    text = README_HEAD + "\n".join(about + rows + params) + "\n" + path_traced_section(out)
    return text + written_by_hand(out / "README.md", text + README_ATTRIBUTION) + README_ATTRIBUTION


# ----------------------------------------------------------------------------- path-traced pairs

#: Path-traced pairs: folder name -> scene description in experiments/scenes/.
PATH_TRACED = {
    "pt_face_940": "face_940.toml",
    "pt_face_940_turned": "face_940_turned.toml",
    "pt_face_skin1": "face_skin1.toml",
    "pt_proc_area_940": "proc_area_940.toml",
    "pt_face_ear_backlit_940": "face_ear_backlit_940.toml",
    "pt_fran_dir_940": "fran_dir_940.toml",
    "pt_fran_dir_rough_940": "fran_dir_rough_940.toml",
    "pt_proc_lowpoly_dir_940": "proc_lowpoly_dir_940.toml",
    "pt_face_rough_area_940": "face_rough_area_940.toml",
    "pt_fran_point_fill_940": "fran_point_fill_940.toml",
    "pt_proc_dir_fill_940": "proc_dir_fill_940.toml",
    "pt_proc_lowpoly_smooth_dir_940": "proc_lowpoly_smooth_dir_940.toml",
    "pt_fran_smooth_point_fill_940": "fran_smooth_point_fill_940.toml",
    "pt_face_rough_940": "face_rough_940.toml",
    "pt_face_ear_glow_940": "face_ear_glow_940.toml",
    "pt_proc_ear_glow_940": "proc_ear_glow_940.toml",
    "pt_face_nose_sidelit_940": "face_nose_sidelit_940.toml",
    "pt_face_nose_backlit_940": "face_nose_backlit_940.toml",
}

PATH_TRACED_HEAD = """
## Path-traced pairs

The `pt_*` pairs are not made by invsss's model: their targets are Mitsuba 3 volumetric
path traces of a homogeneous scattering medium (`invsss scene experiments/scenes/<file>.toml`,
see `docs/scenes.md`) in the shape of the Lee Perry-Smith scan, of the VTK 'fran' scan
closed into a solid, or of a procedural head. Each folder holds what `invsss scene`
writes: `source.exr` (Lambertian, albedo calibrated to the medium's total reflectance),
`target.exr` (the mean of two independently seeded half renders), `depth.exr` (eye z in
mm, 0 off the head), `mask.png`, `normal.exr` (the shading normals a renderer would
have), `coverage.exr`, `light.exr` (camera-space unit vectors towards the key light, the
buffer of the `shift` light term), `key.exr` (the source lit by the key light alone, same
spp and seed, the buffer of the `law` light term; `source - key` is the fill light's
part, with Monte Carlo noise of both passes), `fill_light.exr` (camera-space unit vectors
towards the second light, the buffer of the `fill` light term; written into the pairs
rendered before it existed by `make_synthetic.py --fill-light-only`, from their
`scene.json` and `depth.exr`), in the pairs rendered since the transmission term's
buffers exist `thickness.exr`, `thickness_normal.exr` and `key_irradiance.exr` (the key
light's path inside the skin and its unshadowed irradiance, docs/scenes.md) and
`scene.json` (the resolved scene, seeds, spp, render times and the noise estimate).
There are no true screen-space parameters: these pairs measure how well the model can
match real light transport (`experiments/fidelity.py`).

**Tuning and held-out pairs.** `SPLIT.toml` says which pairs a method may be tuned on
(`tuning`) and which are only measured on (`held-out`); it was committed before any fit
was made on the new pairs. Choose nothing by looking at a held-out pair's results
(docs/scenes.md, which also says what each pair varies and how much of its mask has
normals facing away from the camera).

A rough-dielectric boundary (refraction and Fresnel reflection at the surface, the
reflection subtracted from the target) converges far more slowly than an index-matched
one, so those targets have more noise for their samples: the noise ceiling column is
the best PSNR any noise-free prediction can reach against the target, and the two
rough-dielectric pairs were noise-limited at 2048 spp (about 21.5 dB) and were
rendered again at 16384 (about 28 dB, `variant = "llvm_ad_rgb"`). Render times are
the wall times `scene.json` records (the pairs added for issue 29 on two cores shared with
other work).

| pair | split | object | key light | boundary | medium | size | spp | noise ceiling (dB) | render (min) |
|---|---|---|---|---|---|---|---|---|---|
"""


def make_path_traced(name: str, out: Path) -> None:
    """Render one path-traced pair from its scene description (minutes)."""
    config = load_config(SCENE_CONFIGS / PATH_TRACED[name])
    result = render_scene(config, progress=lambda line: print(f"{name}: {line}", flush=True))
    write_scene_folder(result, out / name, overwrite=True)
    print(f"{name}: {result.info['render_seconds']['total']:.0f} s, noise ceiling "
          f"{result.info['noise']['noise_ceiling_db']:.1f} dB", flush=True)


def add_fill_light(name: str, out: Path) -> None:
    """Write ``fill_light.exr`` into a path-traced pair rendered before that buffer existed.

    It is the direction towards the scene's second light, computed from the folder's
    own ``scene.json`` and ``depth.exr`` exactly as :func:`invsss.scenes.write_scene`
    computes it now, so nothing is rendered; the folder's manifest gains the file.
    """
    from invsss.io import read_image, write_image
    from invsss.io.result_dir import MANIFEST_NAME
    from invsss.scenes import parse_config
    from invsss.scenes.path_tracing import fill_light_directions

    folder = out / name
    config = parse_config(json.loads((folder / "scene.json").read_text())["config"], "scene.json")
    fill = fill_light_directions(config, read_image(folder / "depth.exr")[..., 0])
    if fill is None:
        return
    write_image(folder / "fill_light.exr", fill)
    manifest = json.loads((folder / MANIFEST_NAME).read_text())
    if "fill_light.exr" not in manifest["files"]:
        manifest["files"].insert(manifest["files"].index("scene.json"), "fill_light.exr")
        (folder / MANIFEST_NAME).write_text(json.dumps(manifest, indent=2) + "\n")
    print(f"{name}: wrote fill_light.exr", flush=True)


def _object_label(info: dict) -> str:
    obj = info["config"]["object"]
    if obj.get("primitive") == "face":
        coarse = f", buffers from the {obj['buffers_cell']:g} mm head" if obj.get("buffers_cell") else ""
        return (f"procedural head, {obj.get('cell') or 1.0:g} mm grid" + (", ears" if obj.get("ears") is not False else "")
                + coarse)
    if obj.get("primitive"):
        return obj["primitive"]
    name = Path(obj["mesh"]).name
    label = {"LeePerrySmith.glb": "Lee Perry-Smith", "fran_closed.ply": "fran (closed)"}.get(name, name)
    levels = obj.get("subdivisions") or 0
    return label + (f", {levels} Loop subdivisions" if levels else "")


def path_traced_section(out: Path) -> str:
    """The README section on the path-traced pairs, from the scene.json files in ``out`` and SPLIT.toml."""
    from invsss.scenes.split import read_split

    split = read_split(out / "SPLIT.toml") if (out / "SPLIT.toml").is_file() else {}
    rows = []
    for name, config in PATH_TRACED.items():
        info_path = out / name / "scene.json"
        if not info_path.is_file():
            continue
        info = json.loads(info_path.read_text())
        medium = info["medium"]
        camera = info["config"]["camera"]
        preset = info["config"]["medium"].get("preset") or "custom"
        rows.append(
            f"| `{name}` | {split.get(name, '-')} | {_object_label(info)} | {info['config']['lights'][0]['type']} | "
            f"{medium['boundary']} | {preset} | {camera['width']}x{camera['height']} | {info['spp']['target']} | "
            f"{info['noise']['noise_ceiling_db']:.1f} | {info['render_seconds']['total'] / 60:.1f} |"
        )
    return PATH_TRACED_HEAD + "\n".join(rows) + "\n" if rows else ""


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "data_synthetic")
    every = list(SCENES) + list(PATH_TRACED)
    parser.add_argument("--scenes", nargs="+", choices=every, default=every)
    parser.add_argument("--skip-path-traced", action="store_true",
                        help="make the model-made pairs only (the path-traced ones take minutes each)")
    parser.add_argument("--fill-light-only", action="store_true",
                        help="render nothing: write fill_light.exr into the chosen path-traced pairs already "
                        "in --out from their scene.json and depth.exr")
    args = parser.parse_args(argv)
    if args.fill_light_only:
        for name in (n for n in args.scenes if n in PATH_TRACED and (args.out / n / "scene.json").is_file()):
            add_fill_light(name, args.out)
        return 0
    chosen = [name for name in args.scenes if not (args.skip_path_traced and name in PATH_TRACED)]
    for name in chosen:
        if name in SCENES:
            make_scene(name, args.out)
    for name in chosen:
        if name in PATH_TRACED:
            make_path_traced(name, args.out)
    # The README describes the whole set, so it is written from the files on disk
    # once every model-made pair is there (made now or before).
    on_disk = {name: json.loads((args.out / name / "truth.json").read_text())
               for name in SCENES if (args.out / name / "truth.json").is_file()}
    if set(on_disk) == set(SCENES):
        write_readme(args.out, on_disk)
    return 0


if __name__ == "__main__":
    sys.exit(main())
