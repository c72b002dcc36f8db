"""A procedural, closed, face-like shape for path-traced scenes (``primitive = "face"``).

The shape is the zero set of a signed distance field, meshed by marching cubes,
so it is closed by construction (a medium needs a boundary that encloses a volume)
and the same numbers give the same mesh on every run. In millimetres, head centre
at the origin, y up, face towards +z:

* the head: an ellipsoid of half-axes 72 x 95 x 88 mm (144 mm wide at the ears'
  roots, 190 mm tall, 176 mm deep), with a chin joined to it smoothly;
* a nose: a smaller ellipsoid joined smoothly, its tip 100 mm in front of the centre;
* two eye sockets: spheres carved smoothly out of the front, so the surface has
  concave parts whose normals turn towards each other;
* ``ears``: two thin flaps (5 mm thick, 60 mm tall, 36 mm long), standing out
  backwards from the sides of the head at 25 degrees, thin enough for light from
  behind to shine through them;
* ``wrinkles``: fine horizontal furrows on the forehead (0.35 mm deep, 5 mm apart):
  detail finer than the blur, in the geometry rather than in a texture.

``cell`` is the marching-cubes grid spacing in mm. At 1 mm the surface has about
200 000 triangles and follows the field closely; at 8-10 mm it is a low-poly mesh
of a few thousand triangles whose smoothed shading normals (Mitsuba interpolates
vertex normals) disagree with the flat triangles the medium is bounded by, as a
game's low-poly head does, including normals that face away from the camera near
the silhouette. The ears and wrinkles need a fine grid (they are thinner than 2
cells); a coarse grid should leave them out.
"""

from __future__ import annotations

import functools
import hashlib

import numpy as np

__all__ = ["FACE_EXTENT_MM", "face_mesh", "face_sdf", "write_face_ply"]

#: Half-axes (x, y, z) of the head ellipsoid, mm.
HEAD_RADII = (72.0, 95.0, 88.0)
#: The box (min corner, max corner) in mm that holds the whole shape, ears included.
FACE_EXTENT_MM = ((-96.0, -100.0, -92.0), (96.0, 100.0, 104.0))
EAR_FLARE_DEG = 25.0
WRINKLE_DEPTH_MM = 0.35
WRINKLE_PERIOD_MM = 5.0


def _ellipsoid(x, y, z, centre, radii):
    """A field whose zero set is the ellipsoid (exact there; scaled by the smallest half-axis elsewhere)."""
    cx, cy, cz = centre
    rx, ry, rz = radii
    return (np.sqrt(((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2 + ((z - cz) / rz) ** 2) - 1.0) * min(radii)


def _smooth_union(a, b, k: float):
    """The polynomial smooth minimum (Quilez): a union with a fillet of about ``k`` mm."""
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)


def _smooth_subtract(a, b, k: float):
    """``a`` with ``b`` carved out of it, the edge rounded over about ``k`` mm."""
    return -_smooth_union(-a, b, k)


def _smoothstep(edge0: float, edge1: float, x):
    t = np.clip((x - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def face_sdf(x, y, z, *, ears: bool = True, wrinkles: bool = True):
    """The face's field at points (mm): negative inside, positive outside.

    Examples
    --------
    >>> float(face_sdf(0.0, 0.0, 0.0)) < 0.0, float(face_sdf(0.0, 0.0, 150.0)) > 0.0
    (True, True)
    >>> tip = [z for z in np.linspace(80.0, 110.0, 3001) if face_sdf(0.0, -5.0, z) < 0.0][-1]
    >>> round(float(tip))  # the nose tip, in front of the head's 88 mm
    100
    """
    x, y, z = (np.asarray(v, np.float32) for v in (x, y, z))
    d = _ellipsoid(x, y, z, (0.0, 0.0, 0.0), HEAD_RADII)
    d = _smooth_union(d, _ellipsoid(x, y, z, (0.0, -72.0, 52.0), (28.0, 20.0, 22.0)), 14.0)  # chin
    d = _smooth_union(d, _ellipsoid(x, y, z, (0.0, -5.0, 84.0), (11.0, 24.0, 16.0)), 10.0)  # nose
    for side in (-1.0, 1.0):
        socket = np.sqrt((x - side * 30.0) ** 2 + (y - 20.0) ** 2 + (z - 82.0) ** 2) - 15.0
        d = _smooth_subtract(d, socket, 6.0)
    if ears:
        flare = np.radians(EAR_FLARE_DEG)
        for side in (-1.0, 1.0):
            # The flap's frame: normal n (mostly sideways), length along t (backwards and outwards).
            n = np.array([np.cos(flare) * side, 0.0, np.sin(flare)], np.float32)
            t = np.array([np.sin(flare) * side, 0.0, -np.cos(flare)], np.float32)
            cx, cy, cz = 74.0 * side, 0.0, -18.0
            across = (x - cx) * n[0] + (z - cz) * n[2]
            along = (x - cx) * t[0] + (z - cz) * t[2]
            flap = (np.sqrt((across / 2.5) ** 2 + ((y - cy) / 30.0) ** 2 + (along / 18.0) ** 2) - 1.0) * 2.5
            d = _smooth_union(d, flap, 3.0)
    if wrinkles:
        forehead = (_smoothstep(32.0, 45.0, y) * (1.0 - _smoothstep(62.0, 72.0, y))
                    * (1.0 - _smoothstep(30.0, 48.0, np.abs(x))) * _smoothstep(40.0, 60.0, z))
        d = d + WRINKLE_DEPTH_MM * np.sin(2.0 * np.pi * y / WRINKLE_PERIOD_MM) * forehead
    return d


@functools.lru_cache(maxsize=4)
def _cached_mesh(cell: float, ears: bool, wrinkles: bool):
    import trimesh
    from skimage.measure import marching_cubes

    low, high = (np.asarray(c, np.float64) for c in FACE_EXTENT_MM)
    # Whole cells, with a cell of air on every side so the surface closes inside the grid.
    counts = np.ceil((high - low) / cell).astype(int) + 3
    start = low - cell
    axes = [start[i] + cell * np.arange(counts[i]) for i in range(3)]
    x, y, z = np.meshgrid(*axes, indexing="ij", sparse=True)
    field = face_sdf(x, y, z, ears=ears, wrinkles=wrinkles).astype(np.float32)
    # A grid value exactly on the surface makes triangles of zero area; nudged outside,
    # and with degenerate triangles left out, the surface stays closed once merged.
    field[field == 0.0] = np.float32(1e-6)
    vertices, faces, _, _ = marching_cubes(field, level=0.0, spacing=(cell, cell, cell), allow_degenerate=False)
    mesh = trimesh.Trimesh(vertices + start, faces, process=True)
    mesh.merge_vertices()
    mesh.remove_unreferenced_vertices()
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def face_mesh(cell: float = 1.0, *, ears: bool = True, wrinkles: bool = True):
    """The face as a closed :class:`trimesh.Trimesh` in mm (outward normals), meshed at ``cell`` mm.

    Examples
    --------
    >>> mesh = face_mesh(8.0, ears=False, wrinkles=False)
    >>> mesh.is_watertight, 1000 < len(mesh.faces) < 10000
    (True, True)
    """
    return _cached_mesh(float(cell), bool(ears), bool(wrinkles)).copy()


def write_face_ply(obj, folder: str) -> tuple[str, dict]:
    """Mesh the ``primitive = "face"`` object ``obj`` and save it as ``folder/object.ply``.

    Returns the path and a record for ``scene.json``: the triangle count and a
    SHA-256 of the vertex and face arrays (float32 and int32, little-endian), which
    pins the geometry whatever PLY writer trimesh uses.
    """
    mesh = face_mesh(obj.cell_mm, ears=obj.ears_on, wrinkles=obj.wrinkles_on)
    if not mesh.is_watertight:  # marching cubes inside a padded grid is closed; a guard, not an expected path
        raise RuntimeError(f"the procedural face at cell {obj.cell_mm} mm is not closed")
    digest = hashlib.sha256(np.ascontiguousarray(mesh.vertices, "<f4").tobytes()
                            + np.ascontiguousarray(mesh.faces, "<i4").tobytes()).hexdigest()
    from .mitsuba_scene import write_mesh_ply

    path = write_mesh_ply(mesh, folder, bumps=obj.bumps)
    return path, {"file": None, "procedural": "face", "cell_mm": obj.cell_mm, "ears": obj.ears_on,
                  "wrinkles": obj.wrinkles_on, "triangles": int(len(mesh.faces)), "sha256": digest}
