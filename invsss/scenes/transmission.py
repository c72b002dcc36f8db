"""The buffers a renderer has for the key light transmitted through thin parts of the skin.

Real-time renderers (HDRP's and Unreal's transmission) add the key light that crosses a
thin part (an ear, a nostril's wing) to the diffuse lighting of its far side, from a
thickness and the light's unshadowed irradiance. :func:`transmission_buffers` makes
them from the skin-only AOV pass (``"geometry"``) that the depth and normals come
from, in millimetres and the source's units, and ``invsss scene`` writes them:

==========================  ========================================================
``thickness.exr``           (H, W, 1) mm: the distance the key light travels inside
                            the skin to reach the seen point (HDRP's "thick object"
                            mode, what its shadow map gives): a ray from the point
                            towards the key light, traced to where it leaves the
                            skin; 0 where the point faces the key light
``thickness_normal.exr``    (H, W, 1) mm: the same along the inward shading normal,
                            whatever the light (a baked thickness map, HDRP's "thin
                            object" mode)
``key_irradiance.exr``      (H, W, C): the source's albedo times the key light's
                            irradiance on a surface facing it, over pi, no occlusion:
                            where the key light reaches a point unshadowed,
                            ``key.exr = key_irradiance.exr * max(n . l, 0)``
==========================  ========================================================

All three are 0 where no skin is seen. A pixel's point and normal are its averages
over the skin samples (the AOVs divided by the coverage), as for the depth and normal
buffers; the key light is the config's first light, taken at its position (a point or
spot light), at its centre (an area light) or along its reversed direction (a
directional light).
"""

from __future__ import annotations

import numpy as np

from .config import SceneConfig

__all__ = ["INSET_MM", "THICKNESS_NO_EXIT_MM", "TRANSMISSION_FILES", "albedo_map", "facing_irradiance",
           "first_hits", "transmission_buffers"]

#: The files :func:`transmission_buffers` fills, in the order a pair folder lists them.
TRANSMISSION_FILES = ("thickness.exr", "thickness_normal.exr", "key_irradiance.exr")
#: The ray starts this far (mm) past the pixel's averaged point, and past each surface
#: it enters: a ray started on a surface could find that surface again (rounding).
INSET_MM = 0.05
#: The thickness (mm) written where the ray finds no way out of the skin (an open
#: mesh; a pixel at the silhouette or the terminator whose averaged point lies outside
#: the skin and whose ray meets none): far thicker than any head, so any
#: transmittance of it is nil (the light is taken as blocked), yet finite, so that
#: sums and fits over the buffer stay finite, and unlike 0, which means the light
#: enters right there.
THICKNESS_NO_EXIT_MM = 1000.0
#: At most this many surfaces met from outside are entered on the way to the exit: one
#: in a closed mesh; more only where coincident triangles catch the ray.
_MAX_ENTRIES = 4
#: Pixels where less of the pixel than this sees skin count as no skin (as for the depth).
_MIN_COVERAGE = 1e-6


def _surface(aovs: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where skin is seen (H, W), and there the averaged world positions and unit
    shading normals (N, 3), from the AOVs of a ``"geometry"`` pass.

    The AOVs of rays that miss are 0 and the box filter averages over all samples,
    so the average over the skin samples is the pixel value divided by the coverage.
    """
    coverage = aovs["cov"][..., 0]
    seen = coverage > _MIN_COVERAGE
    position = aovs["pos"][seen] / coverage[seen][:, None]
    normal = aovs["nn"][seen]
    normal = normal / np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    return seen, position, normal


def _towards(light, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (N, 3) from ``points`` (N, 3, world, mm) towards ``light``, and the
    distances to it (inf for a directional light)."""
    if light.type == "directional":
        direction = -np.asarray(light.direction, np.float64)
        direction = np.broadcast_to(direction / np.linalg.norm(direction), points.shape)
        return direction, np.full(len(points), np.inf)
    place = np.asarray(light.center if light.type == "area" else light.position, np.float64)
    offset = place - points
    distance = np.linalg.norm(offset, axis=-1)
    return offset / distance[:, None], distance


def facing_irradiance(light, points, channels: int) -> np.ndarray:
    """The irradiance (N, C) ``light`` gives a surface at ``points`` (N, 3, world, mm)
    that faces it, with no occlusion, in the units of Mitsuba's emitters as
    :mod:`~invsss.scenes.mitsuba_scene` defines them.

    A point light of intensity ``I`` gives ``I / r^2``; a spot light the same times
    Mitsuba's falloff (1 within ``beam_width`` of its axis, linear in the angle to 0
    at ``cutoff``); a directional light its ``irradiance``. An area light of
    radiance ``L`` and area ``A`` is taken as a point at its centre with the same
    power and the rectangle's cosine-weighted emission, ``L A cos(theta) / r^2``
    (``theta`` from its normal, 0 behind it): approximate, close only for points
    several times its size away.

    Examples
    --------
    >>> from invsss.scenes.config import PointLight
    >>> light = PointLight(type="point", position=[0.0, 0.0, 100.0], intensity=[1e4, 2e4, 3e4])
    >>> facing_irradiance(light, np.zeros((1, 3)), 3)
    array([[1., 2., 3.]])
    """
    points = np.asarray(points, np.float64)
    towards, distance = _towards(light, points)
    if light.type == "directional":
        strength, spread = light.irradiance, np.ones(len(points))
    elif light.type == "point":
        strength, spread = light.intensity, 1.0 / distance**2
    elif light.type == "spot":
        axis = np.subtract(light.look_at, light.position)
        angle = np.degrees(np.arccos(np.clip(-towards @ (axis / np.linalg.norm(axis)), -1.0, 1.0)))
        # The spot's beam_width as mitsuba_scene gives it to Mitsuba.
        beam = light.beam_width if light.beam_width is not None else 0.75 * light.cutoff
        falloff = np.where(angle <= beam, 1.0, (light.cutoff - angle) / max(light.cutoff - beam, 1e-12))
        falloff = np.where(angle < light.cutoff, np.clip(falloff, 0.0, 1.0), 0.0)
        strength, spread = light.intensity, falloff / distance**2
    else:
        axis = np.subtract(light.look_at, light.center)
        cosine = np.clip(-towards @ (axis / np.linalg.norm(axis)), 0.0, None)  # one-sided: Mitsuba's area emitter
        strength, spread = light.radiance, light.width * light.height * cosine / distance**2
    colour = np.broadcast_to(np.atleast_1d(np.asarray(strength, np.float64)), (channels,))
    return spread[:, None] * colour


def first_hits(mi, scene, origins, directions) -> tuple[np.ndarray, np.ndarray]:
    """The distance (N,) along each ray (``origins`` and unit ``directions``, (N, 3),
    world) to the first surface of the loaded Mitsuba ``scene`` it hits (inf where it
    hits none), and whether the ray leaves the object there (N,) (it meets the surface
    from the side its geometric normal points away from: the inside of a closed mesh).

    The scalar variants trace one ray per call; the JIT ones (``llvm_*``, ``cuda_*``)
    all rays as one batch.
    """
    origins, directions = np.asarray(origins, np.float64), np.asarray(directions, np.float64)
    if not mi.variant().startswith("scalar"):
        columns = [[mi.Float(np.ascontiguousarray(a[:, k], np.float32)) for k in range(3)]
                   for a in (origins, directions)]
        hit = scene.ray_intersect(mi.Ray3f(mi.Point3f(*columns[0]), mi.Vector3f(*columns[1])))
        valid = np.asarray(hit.is_valid(), bool).reshape(-1)
        normal = np.asarray(hit.n, np.float64).reshape(3, -1).T
        leaving = valid & (np.sum(normal * directions, axis=-1) > 0.0)
        return np.where(valid, np.asarray(hit.t, np.float64).reshape(-1), np.inf), leaving
    distance, leaving = np.full(len(origins), np.inf), np.zeros(len(origins), bool)
    for k, (origin, direction) in enumerate(zip(origins.tolist(), directions.tolist(), strict=True)):
        hit = scene.ray_intersect(mi.Ray3f(mi.Point3f(*origin), mi.Vector3f(*direction)))
        if hit.is_valid():
            distance[k], leaving[k] = hit.t, np.dot(hit.n, direction) > 0.0
    return distance, leaving


def _thickness(mi, scene, points: np.ndarray, inward: np.ndarray) -> np.ndarray:
    """The distance (N,) from ``points`` along ``inward`` (unit vectors pointing into the
    skin) to the first surface the ray meets from inside, where it leaves the skin;
    :data:`THICKNESS_NO_EXIT_MM` where it meets none.

    The ray starts :data:`INSET_MM` along. A pixel's averaged point can lie just outside
    the surface (a concave patch, a crease between facets): a surface met from outside
    is then entered, and the thickness counted from there (the light's way inside the
    skin; the air before it is no part of it).
    """
    thickness = np.full(len(points), THICKNESS_NO_EXIT_MM)
    origins = points + INSET_MM * inward
    inside = np.full(len(points), INSET_MM)  # from the point or the last entry to the origin
    active = np.arange(len(points))
    for _ in range(_MAX_ENTRIES + 1):
        if len(active) == 0:
            break
        distance, leaving = first_hits(mi, scene, origins[active], inward[active])
        thickness[active[leaving]] = inside[active[leaving]] + distance[leaving]
        entering = np.isfinite(distance) & ~leaving
        active = active[entering]
        origins[active] += (distance[entering] + INSET_MM)[:, None] * inward[active]
        inside[active] = INSET_MM
    return thickness


def albedo_map(mi, scene: dict, coverage) -> np.ndarray:
    """The source's per-pixel albedo (H, W, 3), averaged over the pixel's skin samples,
    where the source's albedo is a map (a pigment: the mesh's ``vertex_albedo_color``).

    ``scene`` is the ``"geometry"`` scene dict of the source's mesh (its albedo in its
    vertices) and ``coverage`` (H, W) that pass's; with the same sampler and geometry
    the albedo's samples are the geometry pass's own. 0 where no skin is seen.
    """
    scene = {**scene, "integrator": {"type": "aov", "aovs": "alb:albedo"},
             "object": {**scene["object"], "bsdf": {"type": "diffuse", "reflectance": {
                 "type": "mesh_attribute", "name": "vertex_albedo_color"}}}}
    loaded = mi.load_dict(scene)
    mi.render(loaded)
    albedo = dict(loaded.sensors()[0].film().bitmap().split())["alb"]
    coverage = np.asarray(coverage, np.float64)
    seen = coverage > _MIN_COVERAGE
    return np.where(seen[..., None], np.asarray(albedo, np.float64) / np.where(seen, coverage, 1.0)[..., None], 0.0)


def transmission_buffers(mi, config: SceneConfig, scene: dict, aovs: dict, albedo, channels: int) -> dict:
    """``thickness.exr``, ``thickness_normal.exr`` and ``key_irradiance.exr`` as float32
    arrays (H, W), (H, W) and (H, W, ``channels``), by file name (see the module docstring).

    Parameters
    ----------
    mi : module
        Mitsuba, variant set.
    config : SceneConfig
    scene : dict
        The ``"geometry"`` scene dict the AOVs were rendered from (the skin alone): the
        rays are traced through it.
    aovs : dict
        That pass's channels (:func:`~invsss.scenes.path_tracing.render_aovs`).
    albedo : array
        The source's albedo: one value or one per channel, or a map (H, W, 3 or C)
        (:func:`albedo_map`).
    channels : int
        The source's channels.

    Notes
    -----
    ``thickness``: with ``l`` the unit vector from the point ``p`` towards the key light
    and ``n`` the shading normal, 0 where ``n . l >= 0``, else ``t + INSET_MM`` with ``t``
    the distance from ``p + INSET_MM l`` along ``l`` to the first surface hit.
    ``thickness_normal``: the same along ``-n`` at every seen point. ``key_irradiance``:
    ``albedo E / pi`` with ``E`` :func:`facing_irradiance`; a Lambertian surface of that
    albedo sends ``albedo / pi`` of its irradiance ``E max(n . l, 0)`` as radiance, which
    is what the source and ``key.exr`` hold.
    """
    seen, points, normal = _surface(aovs)
    key = config.lights[0]
    towards, _ = _towards(key, points)
    loaded = mi.load_dict(scene)
    thickness = np.zeros(len(points))
    behind = np.einsum("nk,nk->n", normal, towards) < 0.0  # the light enters elsewhere
    thickness[behind] = _thickness(mi, loaded, points[behind], towards[behind])
    along_normal = _thickness(mi, loaded, points, -normal)
    albedo = np.asarray(albedo, np.float64)
    if albedo.ndim == 3:
        albedo = albedo[seen][:, :channels]
    irradiance = np.broadcast_to(albedo, (len(points), channels)) * facing_irradiance(key, points, channels) / np.pi
    shape = seen.shape
    out = {"thickness.exr": np.zeros(shape), "thickness_normal.exr": np.zeros(shape),
           "key_irradiance.exr": np.zeros((*shape, channels))}
    out["thickness.exr"][seen] = thickness
    out["thickness_normal.exr"][seen] = along_normal
    out["key_irradiance.exr"][seen] = irradiance
    return {name: value.astype(np.float32) for name, value in out.items()}
