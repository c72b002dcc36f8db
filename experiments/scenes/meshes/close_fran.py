"""Close the open face scan ``fran_cut.ply`` into ``fran_closed.ply``, a solid a medium can fill.

``fran_cut.ply`` is a face cut from a head: one surface with one boundary loop
(184 edges) around its rim, which wraps round the sides of the face. The scan
looks along +x with y up; this script turns it to look along +z (a rotation of
-90 degrees about y) and closes it with a cone: one triangle from each rim edge
to an apex about where the centre of the head would be (70 mm behind the nose
tip, 20 mm above the middle of the scan's height). The face's triangles are
unchanged. The result is moved so that its bounding box is centred on x = y = 0
with the front (the nose tip) at z = 0 (it is then 123 mm wide, 154 mm tall and
106 mm deep), and
written in millimetres as a binary PLY without texture coordinates (the
path-traced scenes do not use the texture). It is deterministic: run again, it
writes the same file::

    python experiments/scenes/meshes/close_fran.py

The cone is flat-sided: a scene should look at the face from its front half. The
script checks that the result is closed, consistently wound with outward normals,
and that the segment from the apex to each rim vertex and to 4 points along each
rim edge crosses no triangle of the face (so the cone cuts no part of it). The
face itself is not star-shaped from the apex (nostrils, lips and eyelids fold), nor
does it need to be.
"""

from __future__ import annotations

import sys
from pathlib import Path

import networkx as nx
import numpy as np
import trimesh

HERE = Path(__file__).resolve().parent


def boundary_loop(mesh: trimesh.Trimesh) -> list[int]:
    """The vertices of the mesh's single boundary loop, in order."""
    edges = mesh.edges_sorted
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    rim = unique[counts == 1]
    graph = nx.Graph()
    graph.add_edges_from(rim.tolist())
    loops = nx.cycle_basis(graph)
    if len(loops) != 1 or len(loops[0]) != len(rim):
        raise SystemExit(f"expected one boundary loop, found {len(loops)}")
    return loops[0]


#: The cone's apex, from the turned scan's bounding box: (mm from the middle of x, from the middle of y, behind the front).
APEX_MM = (0.0, 20.0, 70.0)


def close(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, np.ndarray]:
    """The closed mesh (mm, moved as the module says) and its apex."""
    # metres -> mm, and turned from looking along +x to looking along +z: (x, y, z) -> (-z, y, x).
    vertices = np.asarray(mesh.vertices, np.float64)[:, [2, 1, 0]] * [-1000.0, 1000.0, 1000.0]
    faces = np.asarray(mesh.faces, np.int64)
    loop = boundary_loop(mesh)
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    apex = np.array([(low[0] + high[0]) / 2 + APEX_MM[0], (low[1] + high[1]) / 2 + APEX_MM[1], high[2] - APEX_MM[2]])
    n, k = len(vertices), len(loop)
    cone = [[loop[i], loop[(i + 1) % k], n] for i in range(k)]
    closed = trimesh.Trimesh(np.vstack([vertices, apex[None]]), np.vstack([faces, cone]), process=False)
    # The cone was wound one way; make the whole surface agree and face outwards.
    trimesh.repair.fix_winding(closed)
    if closed.volume < 0:
        closed.invert()
    low, high = closed.bounds
    shift = np.array([-(low[0] + high[0]) / 2, -(low[1] + high[1]) / 2, -high[2]])
    closed.apply_translation(shift)
    return closed, apex + shift


def crossings(start: np.ndarray, ends: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """How many of ``triangles`` each segment from ``start`` to a row of ``ends`` crosses (Moller-Trumbore)."""
    a = triangles[:, 0]
    e1, e2 = triangles[:, 1] - a, triangles[:, 2] - a
    counts = np.zeros(len(ends), int)
    for i, end in enumerate(ends):
        d = end - start
        pv = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, pv)
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tv = start - a
        u = np.einsum("ij,ij->i", tv, pv) * inv
        qv = np.cross(tv, e1)
        v = (qv @ d) * inv
        t = np.einsum("ij,ij->i", e2, qv) * inv
        counts[i] = np.count_nonzero(ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6) & (t < 1.0))
    return counts


def check(closed: trimesh.Trimesh, apex: np.ndarray, face: trimesh.Trimesh) -> None:
    if not closed.is_watertight or not closed.is_winding_consistent or closed.volume <= 0:
        raise SystemExit("the closed mesh is not a closed, consistently wound solid")
    count = len(face.faces)
    surface = closed.triangles[:count]  # the face's own triangles come first, unchanged
    rim = closed.vertices[boundary_loop(face)]
    ends = np.vstack([rim + f * (np.roll(rim, -1, axis=0) - rim) for f in (0.0, 0.2, 0.4, 0.6, 0.8)])
    # Stop just short of each end, which lies on the surface itself.
    bad = np.count_nonzero(crossings(apex, apex + 0.999 * (ends - apex), surface))
    if bad:
        raise SystemExit(f"{bad} of {len(ends)} segments from the apex to the rim cross the face: the cone cuts it")


def main() -> int:
    face = trimesh.load(HERE / "fran_cut.ply", process=False)
    face.merge_vertices(merge_tex=True, merge_norm=True)
    closed, apex = close(face)
    check(closed, apex, face)
    out = HERE / "fran_closed.ply"
    closed.export(out, file_type="ply", encoding="binary", include_attributes=False)
    print(f"{out}: {len(closed.vertices)} vertices, {len(closed.faces)} triangles, "
          f"{closed.extents.round(1).tolist()} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
