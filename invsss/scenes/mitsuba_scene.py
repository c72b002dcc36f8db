"""A :class:`~invsss.scenes.config.SceneConfig` as Mitsuba 3 scene dictionaries.

One scene description gives several Mitsuba scenes that differ only in the skin
object's material and the integrator (see :func:`scene_dict`):

* ``"source"``: a Lambertian skin, ``path`` integrator;
* ``"target"``: a rough dielectric boundary (Beckmann) around the homogeneous
  medium, ``volpath``;
* ``"specular"``: the same boundary around a black, purely absorbing interior, so
  only the reflection off the boundary is left (subtracted from the target);
* ``"geometry"``: the skin alone with an ``aov`` integrator (position, shading
  normal, and an albedo of 1 whose pixel average is the coverage);
* ``"visible"``: the same with the occluders present, skin albedo 1 and occluder
  albedo 0, so the pixel average is the fraction of the pixel where skin is seen.

Scene units are millimetres. Mitsuba is imported by :func:`import_mitsuba` only.
"""

from __future__ import annotations

import os
import warnings
from typing import Any, cast

import numpy as np

from ..validation import InputNotice, InvalidInputError
from .config import SceneConfig

__all__ = ["import_mitsuba", "scene_dict", "medium_dict", "boundary_bsdf", "load_mesh_ply", "bumped_normals",
           "write_mesh_ply", "pigmented_mesh", "write_attribute_ply", "SCENE_KINDS"]

SCENE_KINDS = ("source", "target", "specular", "geometry", "visible")

#: Absorption (1/mm) of the black interior of the specular-only scene: light that
#: refracts in is gone within a few micrometres.
_BLACK_INTERIOR_SIGMA_T = 1e4


def import_mitsuba(variant: str):
    """Import Mitsuba 3 and select ``variant``; one line naming the fix if it cannot be.

    Raises
    ------
    InvalidInputError
        Mitsuba is not installed (``pip install "invsss[scenes]"``), or the variant
        is not available on this machine.

    Examples
    --------
    >>> import_mitsuba("scalar_rgb").variant()
    'scalar_rgb'
    """
    try:
        import mitsuba as mi
    except ImportError:
        raise InvalidInputError(
            'rendering scenes needs Mitsuba 3 and trimesh: pip install "invsss[scenes]"'
        ) from None
    try:
        mi.set_variant(variant)
    except (ImportError, AttributeError, RuntimeError) as err:
        reason = " ".join(str(err).split())
        raise InvalidInputError(
            f"variant: Mitsuba variant {variant!r} is not available here ({reason}); "
            'scalar_rgb needs nothing else'
        ) from None
    if variant.startswith("llvm"):
        _check_llvm(variant)
    return mi


def _check_llvm(variant: str) -> None:
    """Refuse an LLVM that aborts the process on Mitsuba 3.9's kernels, before it does."""
    import drjit

    version = tuple(drjit.detail.llvm_version())
    # Seen with the system libLLVM 15: "LLVM ERROR: Cannot select ... fminimum" kills
    # the interpreter (no exception to catch). Debian's libllvm19 works.
    if version and version[0] <= 15:
        raise InvalidInputError(
            f"variant: {variant} with libLLVM {'.'.join(map(str, version))} aborts on Mitsuba 3.9's "
            "kernels ('Cannot select ... fminimum'); install a newer libLLVM (e.g. Debian's libllvm19) "
            "and set DRJIT_LIBLLVM_PATH to it, or use scalar_rgb"
        )


def _colour(value) -> dict:
    """A number or an RGB triple as a Mitsuba spectrum."""
    return {"type": "rgb", "value": [float(v) for v in value] if isinstance(value, list) else float(value)}


def _pose(mi, config: SceneConfig):
    pose = config.object.pose
    rx, ry, rz = pose.rotate
    # Rotations about x, then y, then z (world axes), then the translation.
    return (
        mi.ScalarTransform4f()
        .translate(pose.translate)
        .rotate([0, 0, 1], rz)
        .rotate([0, 1, 0], ry)
        .rotate([1, 0, 0], rx)
    )


#: The bump pattern's wavelength (mm, in the mesh's own frame after scaling to mm).
BUMP_WAVELENGTH_MM = 25.0


def bumped_normals(vertices, normals, degrees: float) -> np.ndarray:
    """Unit normals tilted by a smooth, fixed pattern of at most ``degrees`` (a normal map's effect).

    The tilt at a vertex ``p`` (mm) is the part of ``g(p) = (sin(k p_y + 1), sin(k p_z + 2),
    sin(k p_x + 3)) / sqrt(3)``, ``k = 2 pi / BUMP_WAVELENGTH_MM``, that lies in the tangent
    plane, times ``tan(degrees)``: no randomness, the same mesh gives the same normals.

    Examples
    --------
    >>> n = np.tile([0.0, 0.0, 1.0], (50, 1))
    >>> p = np.random.default_rng(0).uniform(-50, 50, (50, 3))
    >>> tilted = bumped_normals(p, n, 30.0)
    >>> bool(np.allclose(np.linalg.norm(tilted, axis=1), 1.0)), bool(np.degrees(np.arccos(tilted[:, 2].min())) <= 30.0)
    (True, True)
    """
    p = np.asarray(vertices, np.float64)
    n = np.asarray(normals, np.float64)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    k = 2.0 * np.pi / BUMP_WAVELENGTH_MM
    g = np.stack([np.sin(k * p[:, 1] + 1.0), np.sin(k * p[:, 2] + 2.0), np.sin(k * p[:, 0] + 3.0)], axis=1)
    g = g / np.sqrt(3.0)
    tangent = g - n * np.sum(g * n, axis=1, keepdims=True)  # |tangent| <= |g| <= 1
    tilted = n + np.tan(np.radians(degrees)) * tangent
    return tilted / np.linalg.norm(tilted, axis=1, keepdims=True)


def write_mesh_ply(mesh, folder: str, *, bumps: float = 0.0, mm_per_unit: float = 1.0) -> str:
    """Save a closed trimesh as ``folder/object.ply``; with ``bumps`` > 0 its vertex normals are tilted.

    Without bumps the file has no normals and Mitsuba interpolates its own smooth
    vertex normals. With them it carries :func:`bumped_normals` of trimesh's smooth
    vertex normals (the pattern laid out in mm: ``mm_per_unit`` scales the positions),
    which Mitsuba interpolates instead.
    """
    path = os.path.join(folder, "object.ply")
    if bumps > 0:
        normals = bumped_normals(np.asarray(mesh.vertices) * mm_per_unit, mesh.vertex_normals, bumps)
        mesh = mesh.copy()
        mesh.vertex_normals = normals
        mesh.export(path, file_type="ply", vertex_normal=True, include_attributes=False)
    else:
        mesh.export(path, file_type="ply")
    return path


def load_mesh_ply(mesh_path: str, folder: str, *, bumps: float = 0.0, mm_per_unit: float = 1.0,
                  subdivisions: int = 0) -> str:
    """Load a mesh with trimesh, check that it is closed, and save it as PLY in ``folder``.

    Vertices that coincide are merged first (seams of texture coordinates or
    normals split a closed surface into open pieces); the surface must then be
    watertight with outward normals, since it is the boundary of the medium.
    ``subdivisions``: that many levels of Loop subdivision (trimesh's), after the
    check. ``bumps`` and ``mm_per_unit``: see :func:`write_mesh_ply`.

    Raises
    ------
    InvalidInputError
        Unreadable file, or a surface that does not enclose a volume.

    Examples
    --------
    >>> import os, tempfile, trimesh
    >>> folder = tempfile.mkdtemp()
    >>> _ = trimesh.creation.icosphere().export(os.path.join(folder, "ball.obj"))
    >>> os.path.basename(load_mesh_ply(os.path.join(folder, "ball.obj"), folder))
    'object.ply'
    >>> _ = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]).export(os.path.join(folder, "tri.ply"))
    >>> load_mesh_ply(os.path.join(folder, "tri.ply"), folder)
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: object.mesh: ...tri.ply is not closed; the medium needs a surface that encloses a volume (close its holes first)
    """  # noqa: E501
    try:
        import trimesh
    except ImportError:
        raise InvalidInputError('loading meshes needs trimesh: pip install "invsss[scenes]"') from None
    try:
        mesh = trimesh.load(mesh_path, force="mesh", process=True)
    except Exception as err:  # trimesh raises many types for bad files
        raise InvalidInputError(f"object.mesh: cannot read {mesh_path} ({' '.join(str(err).split())})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InvalidInputError(f"object.mesh: {mesh_path} holds no triangles")
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    if not mesh.is_watertight:
        raise InvalidInputError(
            f"object.mesh: {mesh_path} is not closed; the medium needs a surface that "
            "encloses a volume (close its holes first)"
        )
    if mesh.volume < 0:
        mesh.invert()  # inward-facing triangles would swap the inside and outside of the medium
    if subdivisions:
        mesh = mesh.subdivide_loop(iterations=subdivisions)
    return write_mesh_ply(mesh, folder, bumps=bumps, mm_per_unit=mm_per_unit)


_CHANNEL_WEIGHTS = {"red": (1.0, 0.0, 0.0), "green": (0.0, 1.0, 0.0), "blue": (0.0, 0.0, 1.0),
                    "luminance": (0.2126, 0.7152, 0.0722)}


def pigmented_mesh(mesh_path: str, pigment) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """The closed mesh split ``pigment.subdivide`` times, and its pigment at every vertex.

    ``pigment`` is a :class:`~invsss.scenes.config.Pigment`. The mesh is read with its
    texture coordinates (seams keep their own vertices), split (each triangle into
    four; the surface does not change), the map sampled at every vertex, and then the
    coincident vertices merged (their pigment averaged) so that the surface is closed.

    Returns
    -------
    vertices : (N, 3) float64, the mesh's units
    faces : (F, 3) int64, outward winding
    transmittance : (N,) float64 in [0, 1]
        ``P ** strength``: what the pigment leaves of light that enters and leaves there.
    info : dict
        For ``scene.json``: the map's SHA-256, ``c_ref``, the vertex and triangle counts
        and the transmittance's mean, 5th and 95th percentiles over the vertices.

    Raises
    ------
    InvalidInputError
        A mesh without texture coordinates, an unreadable map, or a surface that is not closed.
    """
    import hashlib

    import trimesh
    from trimesh.remesh import subdivide

    from ..io import read_image

    try:
        # force="mesh" returns a Trimesh (trimesh annotates load() as any Geometry).
        mesh = cast("trimesh.Trimesh", trimesh.load(mesh_path, force="mesh", process=False))
    except Exception as err:  # trimesh raises many types for bad files
        raise InvalidInputError(f"object.mesh: cannot read {mesh_path} ({' '.join(str(err).split())})") from None
    uv = getattr(mesh.visual, "uv", None)
    if uv is None or len(uv) != len(mesh.vertices):
        raise InvalidInputError(f"object.pigment: {mesh_path} has no texture coordinates to sample the map at")
    vertices, faces = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
    uv = np.asarray(uv, np.float64)
    for _ in range(pigment.subdivide):
        vertices, faces, attributes = subdivide(vertices, faces, vertex_attributes={"uv": uv})
        uv = attributes["uv"]
    with warnings.catch_warnings():
        # A colour map is sRGB-coded by convention: the decoding notice says nothing new.
        warnings.simplefilter("ignore", InputNotice)
        image = read_image(pigment.map, linear=False).astype(np.float64)
    if image.ndim == 2:
        image = image[..., None]
    image = np.repeat(image, 3, axis=2) if image.shape[2] == 1 else image[..., :3]
    value = _bilinear(image @ np.asarray(_CHANNEL_WEIGHTS[pigment.channel]), uv)
    # Merge the seams' copies: the medium needs one closed surface.
    key = np.round(vertices, 6)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    merged_value = np.bincount(inverse, weights=value) / np.bincount(inverse)
    vertices, faces = vertices[first], inverse[faces]
    closed = trimesh.Trimesh(vertices, faces, process=False)
    if not closed.is_watertight:
        raise InvalidInputError(f"object.mesh: {mesh_path} is not closed once its seams are merged")
    if closed.volume < 0:
        faces = faces[:, ::-1]
    reference = float(np.percentile(merged_value, 99.0))
    pattern = np.clip(merged_value / reference, 0.0, 1.0)
    transmittance = pattern ** pigment.strength
    with open(pigment.map, "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()
    info = {"map": os.path.basename(pigment.map), "sha256": digest, "channel": pigment.channel,
            "strength": pigment.strength, "subdivide": pigment.subdivide, "c_ref": reference,
            "vertices": int(len(vertices)), "triangles": int(len(faces)),
            "transmittance_mean": float(transmittance.mean()),
            "transmittance_p5_p95": [float(np.percentile(transmittance, 5)), float(np.percentile(transmittance, 95))]}
    return vertices, faces, transmittance, info


def _bilinear(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup of a (H, W) image at ``uv`` (N, 2), v up, clamped to the edge."""
    h, w = image.shape
    x = np.clip(uv[:, 0] * w - 0.5, 0, w - 1)
    y = np.clip((1.0 - uv[:, 1]) * h - 0.5, 0, h - 1)
    x0 = np.minimum(np.floor(x).astype(int), w - 2)
    y0 = np.minimum(np.floor(y).astype(int), h - 2)
    fx, fy = x - x0, y - y0
    top = image[y0, x0] * (1 - fx) + image[y0, x0 + 1] * fx
    bottom = image[y0 + 1, x0] * (1 - fx) + image[y0 + 1, x0 + 1] * fx
    return top * (1 - fy) + bottom * fy


def write_attribute_ply(path: str, vertices, faces, attributes: dict) -> str:
    """A binary PLY with float per-vertex attributes that Mitsuba reads as ``vertex_<name>``.

    ``attributes`` maps a name to an (N,) array (one channel, stored as ``<name>_x``) or
    an (N, 3) array (stored as ``<name>_r``, ``_g``, ``_b``); Mitsuba's
    ``mesh_attribute`` texture then looks them up as ``vertex_<name>`` (one channel) or
    ``vertex_<name>_color`` (three; Mitsuba 3.9's PLY reader names them so). Floats, not
    bytes: a trimesh colour would round them to 8 bits.
    """
    vertices = np.asarray(vertices, np.float32)
    fields = [("position", "<f4", (3,))]
    header = ["property float x", "property float y", "property float z"]
    for name, values in attributes.items():
        values = np.asarray(values, np.float32)
        suffixes = ("x",) if values.ndim == 1 else ("r", "g", "b")
        fields.append((name, "<f4", (len(suffixes),)))
        header += [f"property float {name}_{s}" for s in suffixes]
    data = np.zeros(len(vertices), dtype=fields)
    data["position"] = vertices
    for name, values in attributes.items():
        data[name] = np.asarray(values, np.float32).reshape(len(vertices), -1)
    triangles = np.zeros(len(faces), dtype=[("count", "u1"), ("index", "<i4", (3,))])
    triangles["count"], triangles["index"] = 3, faces
    text = "\n".join(["ply", "format binary_little_endian 1.0", f"element vertex {len(vertices)}", *header,
                      f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]) + "\n"
    with open(path, "wb") as f:
        f.write(text.encode("ascii"))
        f.write(data.tobytes())
        f.write(triangles.tobytes())
    return path


def medium_dict(sigma_s_prime, sigma_a) -> dict:
    """A homogeneous, isotropic Mitsuba medium from ``sigma_s'`` and ``sigma_a`` (1/mm, 1 or 3 values).

    Examples
    --------
    >>> medium = medium_dict([0.75], [0.25])
    >>> medium["scale"], medium["sigma_t"], medium["albedo"]
    (1.0, 1.0, {'type': 'rgb', 'value': 0.75})
    """
    s = np.asarray(sigma_s_prime, np.float64)
    a = np.asarray(sigma_a, np.float64)
    sigma_t = s + a
    # Mitsuba reads an RGB sigma_t as a reflectance (each value <= 1): give it as
    # sigma_t / max times the medium's scale, max.
    scale = float(sigma_t.max())
    relative = sigma_t / scale
    return {
        "type": "homogeneous",
        "scale": scale,
        "sigma_t": _colour(relative.tolist()) if sigma_t.size > 1 else 1.0,
        # With an isotropic phase function sigma_s is sigma_s' (no anisotropy to reduce).
        "albedo": _colour((s / sigma_t).tolist() if sigma_t.size > 1 else float((s / sigma_t).item())),
        "phase": {"type": "isotropic"},
    }


def boundary_bsdf(medium: dict) -> dict:
    """The BSDF of the medium's surface: a rough dielectric (Beckmann), or ``null`` if index-matched.

    ``medium`` is :meth:`~invsss.scenes.config.Medium.coefficients`.

    Examples
    --------
    >>> boundary_bsdf({"boundary": "index-matched", "eta": 1.0, "roughness": None})
    {'type': 'null'}
    """
    if medium["boundary"] == "index-matched":
        return {"type": "null"}
    return {"type": "roughdielectric", "distribution": "beckmann", "alpha": medium["roughness"],
            "int_ior": medium["eta"], "ext_ior": 1.0}


def _object_shape(mi, config: SceneConfig, mesh_ply: str | None) -> dict:
    obj = config.object
    pose = _pose(mi, config)
    if obj.primitive == "sphere":
        return {"type": "sphere", "to_world": pose.scale(obj.radius)}
    if obj.primitive == "slab":
        assert obj.size is not None  # the config requires a slab's size
        width, height, thickness = obj.size
        # Mitsuba's cube spans [-1, 1]^3; the slab's front face is z = 0.
        return {"type": "cube",
                "to_world": pose.translate([0, 0, -thickness / 2]).scale([width / 2, height / 2, thickness / 2])}
    # Meshed in mm already when a face; a mesh file is in its own units.
    shape = {"type": "ply", "filename": mesh_ply, "to_world": pose if obj.primitive == "face"
             else pose.scale(obj.mm_per_unit)}
    if obj.face_normals:
        shape["face_normals"] = True
    return shape


def _frame(mi, center, normal, along, half_u: float, half_v: float):
    """The transform that maps Mitsuba's rectangle ([-1, 1]^2, normal +z) onto a placed rectangle."""
    n = np.asarray(normal, np.float64)
    n /= np.linalg.norm(n)
    v = np.asarray(along, np.float64)
    v -= n * (v @ n)
    if np.linalg.norm(v) < 1e-9:
        raise InvalidInputError("occluders: along must not be parallel to normal")
    v /= np.linalg.norm(v)
    u = np.cross(v, n)
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2], matrix[:3, 3] = u * half_u, v * half_v, n, center
    return mi.ScalarTransform4f(matrix.tolist()), u


def _occluder_shapes(mi, config: SceneConfig) -> dict:
    shapes = {}
    black = {"type": "diffuse", "reflectance": _colour(0.0)}
    for k, occ in enumerate(config.occluders):
        period = occ.width / occ.count
        _, across = _frame(mi, occ.center, occ.normal, occ.along, 1.0, 1.0)
        for i in range(occ.count):
            offset = (-occ.width / 2 + (i + 0.5) * period) * across
            transform, _ = _frame(mi, np.asarray(occ.center) + offset, occ.normal, occ.along,
                                  occ.duty * period / 2, occ.length / 2)
            shapes[f"occluder_{k}_{i}"] = {"type": "rectangle", "to_world": transform, "bsdf": black}
    return shapes


def _some_up(direction) -> list[float]:
    """An up vector not parallel to ``direction`` (for look_at frames where roll does not matter)."""
    d = np.asarray(direction, np.float64)
    d /= np.linalg.norm(d)
    return [1.0, 0.0, 0.0] if abs(d[1]) > 0.9 else [0.0, 1.0, 0.0]


def _lights(mi, config: SceneConfig) -> dict:
    lights: dict[str, dict[str, Any]] = {}
    for k, light in enumerate(config.lights):
        if light.type == "point":
            lights[f"light_{k}"] = {"type": "point", "position": light.position,
                                    "intensity": _colour(light.intensity)}
        elif light.type == "spot":
            axis = np.subtract(light.look_at, light.position)
            lights[f"light_{k}"] = {
                "type": "spot",
                "to_world": mi.ScalarTransform4f().look_at(origin=light.position, target=light.look_at,
                                                            up=_some_up(axis)),
                "intensity": _colour(light.intensity),
                "cutoff_angle": light.cutoff,
                "beam_width": light.beam_width if light.beam_width is not None else 0.75 * light.cutoff,
            }
        elif light.type == "area":
            axis = np.subtract(light.look_at, light.center)
            lights[f"light_{k}"] = {
                "type": "rectangle",
                "to_world": mi.ScalarTransform4f()
                .look_at(origin=light.center, target=light.look_at, up=_some_up(axis))
                .scale([light.width / 2, light.height / 2, 1.0]),
                "emitter": {"type": "area", "radiance": _colour(light.radiance)},
            }
        else:
            lights[f"light_{k}"] = {"type": "directional", "direction": light.direction,
                                    "irradiance": _colour(light.irradiance)}
    return lights


def _sensor(mi, config: SceneConfig, sampler: dict, pixel_format: str) -> dict:
    camera = config.camera
    return {
        "type": "perspective",
        "fov": camera.fov_deg,
        "fov_axis": "x",
        "near_clip": 1e-2,
        "far_clip": 1e7,
        "to_world": mi.ScalarTransform4f().look_at(origin=camera.position, target=camera.look_at, up=camera.up),
        # Mitsuba's offset is a fraction of the film, and moving the principal point
        # that way moves the picture the other way.
        "principal_point_offset_x": -camera.principal_offset_px[1] / camera.width,
        "principal_point_offset_y": -camera.principal_offset_px[0] / camera.height,
        # A box filter: each pixel is the plain average over its own area, so coverage
        # and depth are per-pixel quantities and nothing bleeds into neighbours.
        "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height,
                 "rfilter": {"type": "box"}, "pixel_format": pixel_format},
        "sampler": sampler,
    }


def scene_dict(mi, config: SceneConfig, kind: str, *, albedo=None, mesh_ply: str | None = None,
               coefficients: dict | None = None, spp: int | None = None) -> dict:
    """The Mitsuba scene dictionary of one pass (``kind`` in :data:`SCENE_KINDS`).

    Parameters
    ----------
    mi : module
        Mitsuba, variant already set (:func:`import_mitsuba`).
    config : SceneConfig
    kind : str
        Which pass (see the module docstring).
    albedo : float or list of float
        The Lambertian albedo of ``"source"``.
    mesh_ply : str
        The object's mesh as PLY (:func:`load_mesh_ply`, or
        :func:`~invsss.scenes.procedural.write_face_ply` for ``primitive = "face"``).
    coefficients : dict
        :meth:`~invsss.scenes.config.Medium.coefficients`, for ``"target"`` and ``"specular"``.
    spp : int
        Samples per pixel (the renders override it per call).

    Examples
    --------
    >>> from invsss.scenes import parse_config
    >>> config = parse_config({"object": {"primitive": "sphere", "radius": 40.0},
    ...     "camera": {"position": [0.0, 0.0, 300.0], "look_at": [0.0, 0.0, 0.0],
    ...                "fov": 20.0, "width": 16, "height": 16},
    ...     "lights": [{"type": "point", "position": [0.0, 100.0, 300.0], "intensity": 1e5}],
    ...     "medium": {"preset": "thesis-940"}})
    >>> scene = scene_dict(import_mitsuba("scalar_rgb"), config, "target",
    ...                    coefficients=config.medium.coefficients())
    >>> scene["integrator"], scene["object"]["bsdf"]["type"], sorted(scene)
    ({'type': 'volpath', 'max_depth': 256}, 'roughdielectric', ['integrator', 'light_0', 'object', 'sensor', 'type'])
    """
    if kind not in SCENE_KINDS:
        raise ValueError(f"kind {kind!r}: expected one of {SCENE_KINDS}")
    shape = _object_shape(mi, config, mesh_ply)
    geometry = kind in ("geometry", "visible")
    if geometry:
        shape["bsdf"] = {"type": "diffuse", "reflectance": _colour(1.0)}
        integrator: dict[str, Any] = {"type": "aov", "aovs": "pos:position,nn:sh_normal,cov:albedo"}
        # Stratified samples give the pixel averages of coverage and depth with little noise.
        sampler = {"type": "stratified", "sample_count": spp or config.geometry_spp}
    else:
        sampler = {"type": "independent", "sample_count": spp or config.spp}
        pigment = config.object.pigment is not None
        if kind == "source":
            # With a pigment the albedo map (albedo times the pigment) is in the mesh's vertices.
            reflectance = {"type": "mesh_attribute", "name": "vertex_albedo_color"} if pigment else _colour(albedo)
            shape["bsdf"] = {"type": "diffuse", "reflectance": reflectance}
            integrator = {"type": "path", "max_depth": config.max_depth}
        elif coefficients is None:
            raise ValueError(f"kind {kind!r}: needs the medium's coefficients (Medium.coefficients())")
        elif pigment and kind == "target":
            # The pigment layer: each crossing of the (index-matched) surface is absorbed
            # with probability vertex_absorb, passed unchanged otherwise.
            shape["bsdf"] = {"type": "mask", "opacity": {"type": "mesh_attribute", "name": "vertex_absorb"},
                             "material": {"type": "diffuse", "reflectance": _colour(0.0)}}
            shape["interior"] = medium_dict(coefficients["sigma_s_prime"], coefficients["sigma_a"])
            integrator = {"type": "volpath", "max_depth": config.max_depth}
        else:
            shape["bsdf"] = boundary_bsdf(coefficients)
            if kind == "target":
                shape["interior"] = medium_dict(coefficients["sigma_s_prime"], coefficients["sigma_a"])
            else:
                shape["interior"] = {"type": "homogeneous", "sigma_t": _BLACK_INTERIOR_SIGMA_T,
                                     "albedo": _colour(0.0)}
            integrator = {"type": "volpath", "max_depth": config.max_depth}
    scene = {
        "type": "scene",
        "integrator": integrator,
        "sensor": _sensor(mi, config, sampler, "rgb"),
        "object": shape,
    }
    if kind != "geometry":
        scene.update(_occluder_shapes(mi, config))
    if not geometry:
        scene.update(_lights(mi, config))
    return scene

