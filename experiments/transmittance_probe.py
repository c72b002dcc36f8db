"""Would a thickness-based transmittance term close the gap to the path tracer? (issue 10)

Real-time renderers add light that crosses thin parts of the head (ears, the nose's
flank) from a thickness ``s``: the distance the key light travels inside the skin
before it reaches the shaded point, with a transmittance that falls off with ``s``
(Jimenez et al. 2010, "Real-time realistic skin translucency": ``T(s)`` a sum of
Gaussians in ``s`` times ``E = max(0.3 - n . l, 0)``). Before building that term
into the model, its PyTorch twin and the exporter, this script measures what it
could buy on a path-traced pair, post hoc: the best multiple of a candidate
field, added to the three-term fit's image, and the PSNR it gains.

For each seen pixel facing away from the key light, a ray from the surface point
towards the light is traced through the pair's own mesh (Mitsuba 3, the scene
recorded in the pair's ``scene.json``) to where it leaves the skin; that distance
is ``s``. Pixels facing the light get no transmitted light (``s`` = 0, field 0).
The fit is the default fit with ``--light-terms shift,grazing,incidence``; PSNR is
over the mask eroded by 2 px, as in ``fidelity.py``::

    python experiments/transmittance_probe.py [data_synthetic/pt_face_940 ...]

It prints, per pair, how many pixels the key light reaches only through the skin,
their share of the residual, and for each width ``v`` (mm^2) the fitted coefficient
and the gain in dB of ``E exp(-s^2 / v)``. A coefficient below 0 means the fit is
already too bright where such light would go.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
from scipy import ndimage

import invsss
from invsss.scenes.config import parse_config
from invsss.scenes.mitsuba_scene import import_mitsuba, load_mesh_ply, scene_dict

WIDTHS_MM2 = (1.0, 4.0, 16.0, 64.0, 256.0)
#: The ray starts this far (mm) inside the surface, past the pixel's averaged point.
INSET_MM = 0.05


def thickness_to_key_light(folder: Path) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel, the distance (mm) the key light travels inside the skin to reach
    the seen point (0 where the point faces the light), and ``n . l``."""
    config = parse_config(json.loads((folder / "scene.json").read_text())["config"])
    mi = import_mitsuba(config.variant)
    with tempfile.TemporaryDirectory() as scratch:
        mesh = load_mesh_ply(config.object.mesh, scratch) if config.object.mesh else None
        scene = mi.load_dict(scene_dict(mi, config, "geometry", mesh_ply=mesh,
                                        coefficients=config.medium.coefficients()))
    mi.render(scene)
    aovs = {name: np.asarray(c, np.float64) for name, c in scene.sensors()[0].film().bitmap().split()}
    coverage = aovs["cov"][..., 0]
    seen = coverage > 0.5
    # The AOVs are averaged over the pixel, misses counting 0: divide by the coverage.
    position = aovs["pos"] / np.where(seen, coverage, 1.0)[..., None]
    normal = aovs["nn"] / np.maximum(np.linalg.norm(aovs["nn"], axis=-1, keepdims=True), 1e-12)
    light = np.asarray(config.lights[0].position, np.float64)
    thickness, facing = np.zeros(coverage.shape), np.zeros(coverage.shape)
    for y, x in zip(*np.nonzero(seen)):
        towards = light - position[y, x]
        towards /= np.linalg.norm(towards)
        facing[y, x] = normal[y, x] @ towards
        if facing[y, x] >= 0.0:
            continue
        origin = position[y, x] + INSET_MM * towards
        hit = scene.ray_intersect(mi.Ray3f(mi.Point3f(*origin), mi.Vector3f(*towards)))
        if hit.is_valid():
            thickness[y, x] = float(hit.t) + INSET_MM
    return thickness, facing


def probe(folder: Path) -> None:
    thickness, facing = thickness_to_key_light(folder)
    pair = invsss.load_pair(*(folder / f for f in ("source.exr", "target.exr", "depth.exr", "mask.png")))
    buffers = invsss.LightBuffers(invsss.read_image(folder / "normal.exr"), invsss.read_image(folder / "light.exr"))
    fit = invsss.fit_pair(pair.source, pair.target, pair.depth, pair.mask,
                          light_terms="shift,grazing,incidence", light_buffers=buffers)
    target = np.asarray(pair.target, np.float64)
    fitted = np.asarray(fit.fitted[0], np.float64).reshape(target.shape)
    keep = ndimage.binary_erosion(np.asarray(pair.mask) > 0, iterations=2)
    residual = (target - fitted)[keep]  # (N, C)
    before = float(np.mean(residual**2))
    peak = float(target[keep].max())
    through = (thickness > 0)[keep]
    print(f"{folder.name}: three-term fit {10 * np.log10(peak**2 / before):.2f} dB; the key light reaches "
          f"{through.mean():.1%} of the pixels only through the skin (thickness median "
          f"{np.median(thickness[thickness > 0]):.1f} mm), {np.sum(residual[through] ** 2) / np.sum(residual**2):.1%} "
          f"of the residual energy, mean residual there {residual[through].mean():+.5f}")
    exposure = np.clip(0.3 - facing, 0.0, None)
    for width in WIDTHS_MM2:
        field = (exposure * np.exp(-(thickness**2) / width) * (thickness > 0))[keep][:, None]
        field = np.broadcast_to(field, residual.shape)
        coefficient = float(np.sum(field * residual) / np.sum(field * field))
        after = float(np.mean((residual - coefficient * field) ** 2))
        print(f"  v {width:5.0f} mm^2: coefficient {coefficient:+.4f}, gain {10 * np.log10(before / after):.3f} dB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pairs", nargs="*", type=Path,
                        default=[Path("data_synthetic") / n for n in ("pt_face_940", "pt_face_940_turned",
                                                                       "pt_face_skin1")])
    for folder in parser.parse_args().pairs:
        if not (folder / "scene.json").is_file():
            parser.error(f"{folder}: no scene.json (a path-traced pair written by invsss scene is needed)")
        probe(folder)


if __name__ == "__main__":
    main()
