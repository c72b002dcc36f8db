"""Physically based scene pairs: render a source/target pair with Mitsuba 3.

``invsss scene CONFIG.toml --out DIR`` (and :func:`render_scene`) renders, from a
scene description (:mod:`invsss.scenes.config`), a Lambertian source image and a
path-traced target of the same scene with a homogeneous scattering medium behind a
rough dielectric boundary, plus eye-space depth, mask, normals, light directions, coverage,
the transmission term's thicknesses and key light irradiance (:mod:`invsss.scenes.transmission`) and a
``scene.json`` with everything needed to reproduce it. Mitsuba and trimesh are an
optional extra (``pip install "invsss[scenes]"``) and are imported only when a
scene is rendered: :mod:`invsss.scenes.config` works without them.
"""

from .config import SceneConfig, load_config, parse_config
from .media import MEDIUM_PRESETS

__all__ = [
    "MEDIUM_PRESETS", "SceneConfig", "camera_points", "light_directions", "load_config", "parse_config", "render_scene",
    "write_scene",
]


def __getattr__(name: str):
    # The renderer needs Mitsuba: import it on first use only.
    if name in ("render_scene", "write_scene", "SceneRender", "light_directions", "camera_points"):
        from . import path_tracing

        return getattr(path_tracing, name)
    raise AttributeError(f"module 'invsss.scenes' has no attribute {name!r}")
