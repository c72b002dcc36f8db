"""Make the bundled synthetic photo pairs in ``data_synthetic/`` (seeded, reproducible).

Each scene is a face (or a flat card) seen by a pinhole camera, rasterised here in
plain NumPy, giving

* ``source.exr``  linear RGB without scattering: albedo times Lambert shading,
* ``depth.exr``   linear eye-space depth in mm (the distance along the optical axis),
* ``mask.png``    8-bit skin mask,
* ``target.exr``  ``gain * (channels_mix . render(source, depth, mask, truth)) + offset`` plus
  Gaussian noise, where ``render`` is :func:`invsss.render` with ``model="sog"``,
* ``truth.json``  the parameters and everything else needed to rebuild the target,
* ``preview.png`` source | depth | mask | target, for people.

Run from the repository root::

    python experiments/make_synthetic.py            # all scenes into data_synthetic/
    python experiments/make_synthetic.py --scenes fran_front --out /tmp/synth

Every random draw comes from ``numpy.random.default_rng`` seeded per scene, so running
it again writes the same numbers (on the same platform: the blur runs in float32).

Mesh readers: a legacy VTK polydata reader (ASCII or binary, POINTS + POLYGONS +
TEXTURE_COORDINATES) and a glTF binary (.glb) reader for one triangle primitive; both
only cover what the two bundled meshes use.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import struct
import sys
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
from scipy import ndimage

import invsss
from invsss.io import read_image, srgb_to_linear, write_image

REPO = Path(__file__).resolve().parent.parent
SHARED_DATA = REPO.parent / "shared" / "data"
IMAGE_SIZE = 224  # pixels, square
NOISE_FRACTION = 0.01  # noise std as a fraction of the mean masked target

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


# ----------------------------------------------------------------------------- meshes


@dataclasses.dataclass
class Mesh:
    """A triangle mesh with per-vertex texture coordinates, positions in mm."""

    vertices: np.ndarray  # (N, 3) float64, mm
    triangles: np.ndarray  # (M, 3) int64
    uv: np.ndarray  # (N, 2) float64, v up (row 0 of the texture image is v = 1)
    normals: np.ndarray | None = None  # (N, 3), unit; computed from the triangles if absent


def read_vtk_polydata(path: Path) -> Mesh:
    """Read a legacy VTK ``DATASET POLYDATA`` file (ASCII or BINARY) with triangles.

    Units are kept as stored; polygons with more than three corners are fanned. Only
    the classic cell layout (a count before each cell's indices, not the OFFSETS /
    CONNECTIVITY arrays of file version 5.1) is read. Binary files store big-endian
    values right after each section's header line.
    """
    data = path.read_bytes()
    lines = data.split(b"\n", 4)
    if not lines[0].startswith(b"# vtk DataFile"):
        raise ValueError(f"{path}: not a legacy VTK file")
    binary = lines[2].strip().upper() == b"BINARY"
    if lines[3].split()[:2] != [b"DATASET", b"POLYDATA"]:
        raise ValueError(f"{path}: expected DATASET POLYDATA, got {lines[3]!r}")
    dtypes = {b"float": ">f4", b"double": ">f8", b"int": ">i4", b"vtktypeint64": ">i8"}
    pos = len(b"\n".join(lines[:4])) + 1
    points = polygons = uv = None

    def read_values(pos, count, dtype):
        # Returns (values, new position); ASCII values are whitespace separated.
        if binary:
            dt = np.dtype(dtypes[dtype])
            end = pos + count * dt.itemsize
            return np.frombuffer(data[pos:end], dt).astype(np.float64), end
        values, n = [], 0
        while n < count:
            nl = data.index(b"\n", pos)
            row = data[pos:nl].split()
            values.extend(row)
            n += len(row)
            pos = nl + 1
        return np.array(values[:count], dtype=np.float64), pos

    while pos < len(data):
        nl = data.find(b"\n", pos)
        nl = len(data) if nl < 0 else nl
        header = data[pos:nl].split()
        pos = nl + 1
        if not header:
            continue
        key = header[0].upper()
        if key == b"POINTS":
            n = int(header[1])
            flat, pos = read_values(pos, 3 * n, header[2].lower())
            points = flat.reshape(n, 3)
        elif key == b"POLYGONS":
            size = int(header[2])
            flat, pos = read_values(pos, size, b"int")
            flat = flat.astype(np.int64)
            tris, i = [], 0
            while i < size:
                k = flat[i]
                corners = flat[i + 1 : i + 1 + k]
                tris.extend((corners[0], corners[j], corners[j + 1]) for j in range(1, k - 1))
                i += k + 1
            polygons = np.array(tris, dtype=np.int64)
        elif key == b"TEXTURE_COORDINATES":
            dim, dtype = int(header[2]), header[3].lower()
            flat, pos = read_values(pos, dim * len(points), dtype)
            uv = flat.reshape(len(points), dim)[:, :2]
        elif key in (b"POINT_DATA", b"CELL_DATA"):
            continue  # section markers; their arrays follow as their own headers
        elif binary:
            raise ValueError(f"{path}: binary section {key!r} is not supported")
        # other ASCII sections (LINES, NORMALS, ...) are skipped line by line.
    if points is None or polygons is None or uv is None:
        raise ValueError(f"{path}: needs POINTS, POLYGONS and TEXTURE_COORDINATES")
    return Mesh(points, polygons, uv)


_GLTF_COMPONENTS = {5120: "i1", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_GLTF_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def read_glb_mesh(path: Path) -> Mesh:
    """Read the first triangle primitive of a glTF 2.0 binary (no node transforms applied).

    Texture coordinates are returned as stored. The glTF specification puts v = 0 at
    the top of the image, but the three.js LeePerrySmith asset was made for three.js's
    default ``flipY`` loading, so its v points up as :class:`Mesh` expects (checked in
    shared/data/leeperrysmith/SOURCE.md and on the previews).
    """
    data = path.read_bytes()
    magic, version, _ = struct.unpack_from("<4sII", data, 0)
    if magic != b"glTF" or version != 2:
        raise ValueError(f"{path}: not a glTF 2.0 binary")
    chunks, pos = {}, 12
    while pos < len(data):
        length, kind = struct.unpack_from("<I4s", data, pos)
        chunks[kind] = data[pos + 8 : pos + 8 + length]
        pos += 8 + length
    gltf = json.loads(chunks[b"JSON"])
    blob = chunks[b"BIN\x00"]

    def accessor(index):
        acc = gltf["accessors"][index]
        view = gltf["bufferViews"][acc["bufferView"]]
        dtype = np.dtype(_GLTF_COMPONENTS[acc["componentType"]])
        width = _GLTF_WIDTH[acc["type"]]
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        stride = view.get("byteStride", dtype.itemsize * width)
        rows = np.ndarray(
            (acc["count"], width), dtype, buffer=blob, offset=start,
            strides=(stride, dtype.itemsize),
        )
        return rows.astype(np.float64 if dtype.kind == "f" else np.int64)

    primitive = gltf["meshes"][0]["primitives"][0]
    if primitive.get("mode", 4) != 4:
        raise ValueError(f"{path}: only triangle lists are supported")
    attributes = primitive["attributes"]
    return Mesh(
        vertices=accessor(attributes["POSITION"]),
        triangles=accessor(primitive["indices"]).reshape(-1, 3),
        uv=accessor(attributes["TEXCOORD_0"]),
        normals=accessor(attributes["NORMAL"]),
    )


def vertex_normals(mesh: Mesh) -> np.ndarray:
    """Area-weighted vertex normals from the triangle winding, unit length."""
    v = mesh.vertices
    a, b, c = (v[mesh.triangles[:, i]] for i in range(3))
    face = np.cross(b - a, c - a)  # length = twice the area: area weighting for free
    normals = np.zeros_like(v)
    for i in range(3):
        np.add.at(normals, mesh.triangles[:, i], face)
    return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)


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


# ----------------------------------------------------------------------------- camera


@dataclasses.dataclass
class Camera:
    """A pinhole camera: eye axes X right, Y up, Z forward (depth = Z, mm)."""

    position: np.ndarray  # (3,) mm, world
    rotation: np.ndarray  # (3, 3), rows are the eye X, Y, Z axes in world coordinates
    focal_px: float
    size: int

    @classmethod
    def look_at(cls, position, target, up, focal_px, size) -> "Camera":
        position, target, up = (np.asarray(x, np.float64) for x in (position, target, up))
        forward = target - position
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, up)
        right /= np.linalg.norm(right)
        true_up = np.cross(right, forward)
        return cls(position, np.stack([right, true_up, forward]), float(focal_px), size)

    @property
    def principal_point(self) -> float:
        return (self.size - 1) / 2.0  # pixel centres at integer coordinates

    def to_eye(self, points: np.ndarray) -> np.ndarray:
        return (points - self.position) @ self.rotation.T

    def project(self, eye: np.ndarray) -> np.ndarray:
        """Eye coordinates (N, 3) to pixel coordinates (N, 2) as (column, row)."""
        c = self.principal_point
        return np.stack(
            [c + self.focal_px * eye[:, 0] / eye[:, 2], c - self.focal_px * eye[:, 1] / eye[:, 2]],
            axis=1,
        )


# ----------------------------------------------------------------------------- rasteriser


def rasterise(pixels: np.ndarray, depth: np.ndarray, triangles: np.ndarray, size: int):
    """Z-buffer rasterisation of triangles sampled at pixel centres.

    Parameters
    ----------
    pixels : (N, 2) vertex positions in pixels (column, row)
    depth : (N,) vertex eye depth, > 0
    triangles : (M, 3) vertex indices (either winding)
    size : image height = width

    Returns
    -------
    zbuffer : (size, size) linear eye depth (inf where empty)
    face : (size, size) triangle index (-1 where empty)
    bary : (size, size, 3) perspective-correct barycentric weights
    """
    zbuffer = np.full((size, size), np.inf)
    face = np.full((size, size), -1, np.int64)
    bary = np.zeros((size, size, 3))
    corners = pixels[triangles]  # (M, 3, 2)
    lo = np.maximum(np.ceil(corners.min(axis=1)), 0).astype(int)
    hi = np.minimum(np.floor(corners.max(axis=1)), size - 1).astype(int)
    visible = np.all(hi >= lo, axis=1) & np.all(depth[triangles] > 0, axis=1)
    for t in np.flatnonzero(visible):
        (x0, y0), (x1, y1), (x2, y2) = corners[t]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if abs(area) < 1e-12:
            continue
        xs = np.arange(lo[t, 0], hi[t, 0] + 1)
        ys = np.arange(lo[t, 1], hi[t, 1] + 1)[:, None]
        # Screen-space barycentrics from edge functions; dividing by the signed area
        # makes the inside test independent of the winding.
        b0 = ((x1 - xs) * (y2 - ys) - (x2 - xs) * (y1 - ys)) / area
        b1 = ((x2 - xs) * (y0 - ys) - (x0 - xs) * (y2 - ys)) / area
        b2 = 1.0 - b0 - b1
        inside = (b0 >= 0) & (b1 >= 0) & (b2 >= 0)
        if not inside.any():
            continue
        # Depth is not linear in screen space, its reciprocal is.
        z = depth[triangles[t]]
        inv_z = b0 / z[0] + b1 / z[1] + b2 / z[2]
        z_pix = 1.0 / inv_z
        window = (slice(lo[t, 1], hi[t, 1] + 1), slice(lo[t, 0], hi[t, 0] + 1))
        closer = inside & (z_pix < zbuffer[window])
        if not closer.any():
            continue
        zbuffer[window][closer] = z_pix[closer]
        face[window][closer] = t
        weights = np.stack([b0 / z[0], b1 / z[1], b2 / z[2]], axis=-1) * z_pix[..., None]
        bary[window][closer] = weights[closer]
    return zbuffer, face, bary


def interpolate(attribute: np.ndarray, triangles: np.ndarray, face: np.ndarray, bary: np.ndarray):
    """Per-pixel attribute (size, size, D) from per-vertex ``attribute`` (N, D); 0 where empty."""
    out = np.zeros(face.shape + attribute.shape[1:])
    hit = face >= 0
    corners = attribute[triangles[face[hit]]]  # (P, 3, D)
    out[hit] = np.einsum("pk,pkd->pd", bary[hit], corners)
    return out


# ----------------------------------------------------------------------------- scenes


@dataclasses.dataclass
class Lighting:
    """Directional lights in eye space plus ambient light."""

    directions: list  # of (3,), pointing towards each light; normalised when used
    intensities: list  # of float
    ambient: float

    def shade(self, normals: np.ndarray) -> np.ndarray:
        total = np.full(normals.shape[:-1], self.ambient)
        for d, k in zip(self.directions, self.intensities):
            d = np.asarray(d, np.float64) / np.linalg.norm(d)
            total += k * np.clip(normals @ d, 0.0, None)
        return total[..., None]

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
    depth: np.ndarray  # (H, W) mm
    mask: np.ndarray  # (H, W) 0 or 1
    camera: dict


def render_mesh(
    mesh: Mesh,
    textures: dict,
    camera: Camera,
    lighting: Lighting,
    background_depth: float,
    background_rgb,
    rng: np.random.Generator,
) -> Rendering:
    """Rasterise ``mesh`` and shade it: albedo x detail x Lambert, on a flat wall.

    ``textures`` holds ``albedo`` (linear RGB), ``detail`` (multiplicative, any
    resolution, same uv) and ``skin`` (1 where the texture shows skin). The mask is
    the skin texture >= 0.5 on front-facing surface. The background is a flat,
    faintly textured wall at ``background_depth`` mm.
    """
    normals = mesh.normals if mesh.normals is not None else vertex_normals(mesh)
    eye = camera.to_eye(mesh.vertices)
    zbuffer, face, bary = rasterise(camera.project(eye), eye[:, 2], mesh.triangles, camera.size)
    hit = face >= 0
    uv = interpolate(mesh.uv, mesh.triangles, face, bary)
    n_eye = interpolate(normals @ camera.rotation.T, mesh.triangles, face, bary)
    n_eye /= np.maximum(np.linalg.norm(n_eye, axis=-1, keepdims=True), 1e-12)
    p_eye = interpolate(eye, mesh.triangles, face, bary)
    front = hit & (np.einsum("hwc,hwc->hw", n_eye, -p_eye) > 0)
    # Back faces seen past the cut edge of an open scan get ambient light only.
    shading = np.where(front[..., None], lighting.shade(n_eye), lighting.ambient)
    albedo = sample_texture(textures["albedo"], uv) * sample_texture(textures["detail"], uv)
    size = camera.size
    wall = np.asarray(background_rgb) * (1.0 + 0.1 * rng.standard_normal((size, size, 1)))
    source = np.where(hit[..., None], albedo * shading, wall)
    mask = front & (sample_texture(textures["skin"], uv)[..., 0] >= 0.5)
    depth = np.where(hit, zbuffer, background_depth)
    return Rendering(source, depth, mask.astype(np.float64), {})


def load_fran() -> tuple[Mesh, dict]:
    """The VTK 'fran' face in mm, its linear albedo and a skin map in texture space.

    The scan is stored in metres with y up; its triangles wind inwards, so the vertex
    normals are flipped. The texture is a photograph; the skin map drops texels much
    darker than their surroundings (eyes, eyebrows, nostrils, the mouth line), found
    with a local-contrast rule and checked by eye on the preview.
    """
    folder = SHARED_DATA / "vtk_fran"
    mesh = read_vtk_polydata(folder / "fran_cut.vtk")
    mesh.vertices = mesh.vertices * 1000.0
    mesh.normals = -vertex_normals(mesh)
    texture = read_texture(folder / "fran_cut.png")
    luminance = texture @ np.array([0.2126, 0.7152, 0.0722])
    dark = luminance < 0.5 * ndimage.gaussian_filter(luminance, 6.0)
    dark = ndimage.binary_closing(ndimage.binary_opening(dark), iterations=2)
    skin = ~ndimage.binary_dilation(dark) & (luminance > 0.01)
    return mesh, {"albedo": texture, "skin": skin.astype(np.float64)[..., None]}


def load_lee_perry_smith(mm_per_unit: float) -> tuple[Mesh, dict]:
    """The Lee Perry-Smith bust (y up, face along +z) in mm; its whole texture is skin."""
    folder = SHARED_DATA / "leeperrysmith"
    mesh = read_glb_mesh(folder / "LeePerrySmith.glb")
    mesh.vertices = mesh.vertices * mm_per_unit
    texture = read_texture(folder / "Map-COL.jpg")
    return mesh, {"albedo": texture, "skin": np.ones(texture.shape[:2] + (1,))}


def rotation_y(degrees: float) -> np.ndarray:
    a = np.radians(degrees)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


HEADS = {
    "fran": {
        "load": lambda spec: load_fran(),
        # The scan's mean outward normal with its small vertical part dropped.
        "facing": [0.8121, 0.0, -0.5835],
        "attribution": FRAN_ATTRIBUTION,
        "files": ["vtk_fran/fran_cut.vtk", "vtk_fran/fran_cut.png"],
    },
    "leeperrysmith": {
        "load": lambda spec: load_lee_perry_smith(spec["mm_per_unit"]),
        "facing": [0.0, 0.0, 1.0],
        "attribution": LEE_PERRY_SMITH_ATTRIBUTION,
        "files": ["leeperrysmith/LeePerrySmith.glb", "leeperrysmith/Map-COL.jpg"],
    },
}


def face_scene(spec: dict, rng: np.random.Generator) -> tuple[Rendering, dict]:
    """Put a pinhole camera in front of the head (turned and tilted) and rasterise."""
    head = HEADS[spec["mesh"]]
    mesh, textures = head["load"](spec)
    textures["detail"] = skin_detail(rng, spec["detail_texels"], spec["detail_strength"])
    centre = np.asarray(spec["look_at_mm"], np.float64)
    view = rotation_y(spec["turn_deg"]) @ np.asarray(head["facing"])
    view = view + np.array([0.0, np.tan(np.radians(spec["tilt_deg"])), 0.0])
    view /= np.linalg.norm(view)
    camera = Camera.look_at(
        centre + spec["distance_mm"] * view, centre, [0, 1, 0], spec["focal_px"], IMAGE_SIZE
    )
    background_depth = spec["distance_mm"] + 350.0
    rendering = render_mesh(
        mesh, textures, camera, Lighting(**spec["lighting"]), background_depth,
        [0.03, 0.035, 0.045], rng,
    )
    rendering.camera = {
        "model": "pinhole",
        "focal_px": spec["focal_px"],
        "principal_point_px": [camera.principal_point, camera.principal_point],
        "distance_mm": spec["distance_mm"],
        "position_mm": np.round(camera.position, 3).tolist(),
        "look_at_mm": centre.tolist(),
        "up": [0.0, 1.0, 0.0],
        "head_turn_deg": spec["turn_deg"],
        "tilt_deg": spec["tilt_deg"],
        "background_depth_mm": background_depth,
    }
    source = {
        "files": [f"shared/data/{f}" for f in head["files"]],
        "attribution": head["attribution"],
    }
    if spec["mesh"] == "leeperrysmith":
        source["mm_per_unit"] = spec["mm_per_unit"]
    return rendering, source


def card_scene(spec: dict, rng: np.random.Generator) -> tuple[Rendering, dict]:
    """A flat card square to the optical axis, printed with a crop of a face texture.

    Every pixel has the same eye depth, so all depth slopes are exactly 0: the
    correction and maxdd have no effect on the target and cannot be estimated.
    The skin mask is an ellipse on the card (the rest stands for cloth or paper).
    """
    albedo = read_texture(SHARED_DATA / "leeperrysmith" / "Map-COL.jpg")
    detail = skin_detail(rng, spec["detail_texels"], spec["detail_strength"])
    size, f, distance = IMAGE_SIZE, spec["focal_px"], spec["distance_mm"]
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float64)
    (u0, u1), (v0, v1) = spec["uv_crop"]
    t = (cols + 0.5) / size, (rows + 0.5) / size
    uv = np.stack([u0 + (u1 - u0) * t[0], v1 - (v1 - v0) * t[1]], axis=-1)
    lighting = Lighting(**spec["lighting"])
    normal = np.broadcast_to(np.array([0.0, 0.0, -1.0]), (size, size, 3))
    source = sample_texture(albedo, uv) * sample_texture(detail, uv) * lighting.shade(normal)
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
        "files": ["shared/data/leeperrysmith/Map-COL.jpg"],
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


def make_target(rendering: Rendering, spec: dict, rng: np.random.Generator):
    """``gain * (channels_mix . render(source)) + offset + noise``; returns (target, sigma).

    The noise is i.i.d. Gaussian with one standard deviation for the whole image:
    ``NOISE_FRACTION`` of the mean noise-free target over the mask.
    """
    params = invsss.SSSParams.from_dict(spec["params"], source=f"scene {spec['name']}")
    scattered = np.asarray(
        invsss.render(rendering.source, rendering.depth, rendering.mask, params, model="sog"),
        np.float64,
    )
    mix = spec["channels_mix"]
    if mix is not None:
        scattered = scattered @ np.asarray(mix, np.float64)[:, None]
    clean = np.asarray(spec["gain"]) * scattered + np.asarray(spec["offset"])
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
        depth_view = np.where(d <= far, np.clip((far - d) / (far - near), 0, 1), 0.0)
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
byte for byte on the same platform. `tests/test_synthetic_data.py` loads every scene
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
`focal_px`) looks at a textured mesh; a z-buffer rasteriser written in NumPy samples each
triangle at pixel centres with perspective-correct barycentric interpolation of texture
coordinates, normals and depth. Texture colours are sRGB-decoded to linear and multiplied
by a seeded two-octave log-normal noise texture (about 12 % std, attached to the surface)
so that there is pore-scale detail for the blur to act on. Shading is Lambert from a key
and a fill light plus a little ambient light. The background is a dim, faintly noisy wall
at a depth of the camera distance plus 350 mm (mask 0 there).

The scattering parameters are the thesis's 940 nm fit (its Table 5.1) for every scene:
variances `[8.749, 2.099, 0.549, 0.5574, 1.194]` mm^2 and weights
`[0.1478, 0.1323, 0.0004, 0.0527, 0.090]` (note the near-equal 0.549/0.5574 pair whose
first weight is almost 0: only their sum is well determined). `sss_level` equals
`focal_px`, so with depth in mm the variances are in true mm^2. `correction` = 800 and
`maxdd` = 0.5 mm per pixel give a real share of skin pixels on each side of `maxdd`
(the table lists the shares of skin pixels with |dd/dx|, |dd/dy| > maxdd).

Skin masks: for the fran scan, front-facing surface whose texture is not much darker than
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

**leeperrysmith, flat_card** use "Infinite, 3D Head Scan" by Lee Perry-Smith
(Infinite-Realities, www.ir-ltd.net), based on a work at www.triplegangers.com, licensed
under Creative Commons Attribution 3.0 Unported
(https://creativecommons.org/licenses/by/3.0/); the licence note asks that users always
say where they got the files. We took the glTF conversion `LeePerrySmith.glb` and its
colour map `Map-COL.jpg` as distributed with the three.js examples
(examples/models/gltf/LeePerrySmith/, via a verbatim copy in
github.com/espisepi/t-shirt-configurator-espinaco). The licence note is copied in
`LICENSES/LeePerrySmith_License.txt`.

Changes made to both (for all scenes): the meshes were re-rendered here with a new camera
and lighting, scaled to millimetres (fran: stored in metres; Lee Perry-Smith: an estimated
45 mm per model unit), their textures were multiplied by synthetic noise, and the targets
add synthetic subsurface scattering, a colour mix and noise. The flat card shows a crop of
the Lee Perry-Smith colour map as a flat picture.
"""

LICENCE_FILES = {
    "vtk-data-Copyright.txt": "vtk_fran/Copyright_vtk-data.txt",
    "vtk-data-LICENSE-Apache-2.0.txt": "vtk_fran/LICENSE_vtk-data.txt",
    "LeePerrySmith_License.txt": "leeperrysmith/LeePerrySmith_License.txt",
}


def write_readme(out: Path, truths: dict) -> None:
    """README.md with a table of the scenes built from their truth records; licence copies."""
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
    text = README_HEAD + "\n".join(about + rows + params) + "\n" + README_ATTRIBUTION
    (out / "README.md").write_text(text)
    licences = out / "LICENSES"
    licences.mkdir(exist_ok=True)
    for copy, original in LICENCE_FILES.items():
        (licences / copy).write_bytes((SHARED_DATA / original).read_bytes())


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "data_synthetic")
    parser.add_argument("--scenes", nargs="+", choices=sorted(SCENES), default=list(SCENES))
    args = parser.parse_args(argv)
    truths = {name: make_scene(name, args.out) for name in args.scenes}
    if set(truths) == set(SCENES):  # the README describes the whole set
        write_readme(args.out, truths)
    return 0


if __name__ == "__main__":
    sys.exit(main())
