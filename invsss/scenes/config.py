"""The scene description of ``invsss scene``: a TOML file checked by a pydantic model.

Lengths are millimetres throughout (a mesh is scaled into mm by ``mm_per_unit``),
angles degrees, scattering coefficients 1/mm. A minimal file::

    spp = 64
    seed = 1

    [object]
    primitive = "sphere"        # or "slab" (with size), "face", or mesh = "head.glb" with mm_per_unit
    radius = 40.0

    [camera]
    position = [0.0, 0.0, 400.0]
    look_at = [0.0, 0.0, 0.0]
    fov = 20.0                  # horizontal, degrees; or focal_px
    width = 64
    height = 64
    # principal_offset_px = [0.0, 0.0]   # (rows, cols) from the image centre; set by `scene --warp`

    [[lights]]
    type = "point"              # point, spot, area or directional
    position = [100.0, 150.0, 300.0]
    intensity = 2e5

    [medium]
    preset = "thesis-940"       # or sigma_s_prime, sigma_a (1/mm) and eta

Every key is checked: an unknown or misspelt key, a string where a number belongs, a
missing field, each gives one line naming the key (as a dotted path) and, for an
unknown key, the nearest valid one. Numbers are strict: ``true`` or ``"3"`` is not a
number.
"""

from __future__ import annotations

import math
import os
import tomllib
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from ..validation import InvalidInputError
from .config_errors import pydantic_error_line
from .media import MEDIUM_PRESETS

__all__ = [
    "VARIANTS",
    "SceneConfig",
    "SceneObject",
    "Pose",
    "Camera",
    "PointLight",
    "SpotLight",
    "AreaLight",
    "DirectionalLight",
    "Occluder",
    "Medium",
    "Pigment",
    "load_config",
    "parse_config",
]

#: Mitsuba variants a scene may ask for; ``scalar_rgb`` needs nothing but the wheel.
VARIANTS = ("scalar_rgb", "llvm_ad_rgb", "cuda_ad_rgb")

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Vec2 = Annotated[list[float], Field(min_length=2, max_length=2)]
Positive = Annotated[float, Field(gt=0)]
# A light's power: one number (grey) or one per RGB channel.
Colour = (
    Annotated[float, Field(ge=0)]
    | Annotated[list[Annotated[float, Field(ge=0)]], Field(min_length=3, max_length=3)]
)
Coefficient = Positive | Annotated[list[Positive], Field(min_length=3, max_length=3)]


class _Strict(BaseModel):
    # strict: TOML's true or "3" never becomes a number; forbid: a misspelt key is an error.
    model_config = ConfigDict(strict=True, extra="forbid", frozen=True)


class Pose(_Strict):
    """Where the object sits: rotated about the world x, then y, then z axis (degrees), then moved (mm)."""

    translate: Vec3 = [0.0, 0.0, 0.0]
    rotate: Vec3 = [0.0, 0.0, 0.0]


class Pigment(_Strict):
    """A pigment layer on the skin's surface: melanin in the epidermis, above the scattering.

    The colour map ``map`` (an image file, relative to the scene file; sampled at the
    mesh's texture coordinates, v up, bilinearly) gives a pattern ``P = min(c / c_ref, 1)``
    from one ``channel`` of its linear values (``c_ref`` the 99th percentile over the
    mesh's vertices). Light that enters and leaves the skin there is multiplied by
    ``P ** strength``: each crossing of the surface by ``P ** (strength / 2)``, as a
    thin absorbing layer acts. ``strength`` 1 gives the map's own contrast (visible
    light); melanin absorbs far less at 940 nm, so a near-infrared render of the same
    skin takes a smaller ``strength`` (docs/capture.md). The Lambertian source is the
    same surface with albedo ``a * P ** strength`` (``a`` the calibrated albedo), as a
    renderer's albedo map holds it. The mesh is split ``subdivide`` times (each splits
    every triangle into four; the surface is unchanged) so that the pattern, carried
    by the vertices, is finer than a pixel. Needs a mesh with texture coordinates and an
    index-matched boundary.
    """

    map: str
    channel: Literal["red", "green", "blue", "luminance"] = "green"
    strength: Annotated[float, Field(ge=0.0, le=4.0)] = 1.0
    subdivide: Annotated[int, Field(ge=0, le=3)] = 2


class SceneObject(_Strict):
    """The skin object: a closed mesh file, or a built-in primitive.

    ``primitive = "slab"``: a box of ``size = [width, height, thickness]`` mm whose
    front face is the plane z = 0 (facing +z), centred on the z axis.
    ``primitive = "sphere"``: a sphere of ``radius`` mm about the origin.
    ``primitive = "face"``: a procedural closed head with nose, chin, eye sockets,
    and optionally thin ear flaps (``ears``, default true) and forehead furrows
    (``wrinkles``, default true), meshed by marching cubes at ``cell`` mm (default
    1; 8-12 gives a low-poly head whose smoothed shading normals disagree with its
    triangles). Head centre at the origin, y up, face towards +z, 144 x 190 x 176
    mm (:mod:`invsss.scenes.procedural`).
    A ``mesh`` (any format trimesh reads; a relative path is relative to the
    config file) is scaled by ``mm_per_unit`` and must be closed, since it holds
    the medium. ``pose`` then places it.

    ``bumps`` (degrees, default 0) tilts the shading normals of a mesh or face, and
    not its surface, by up to that angle in a smooth pattern 25 mm across, as a
    normal map does (:func:`~invsss.scenes.mitsuba_scene.bumped_normals`): the
    normal buffer and the Lambertian source show bumps that the medium's boundary
    does not have, and near the silhouette some normals face away from the camera.

    ``buffers_cell`` (mm, only for ``primitive = "face"``) renders what a renderer
    would have (the source, the key light's part, depth, normals, mask) from the face
    meshed at this grid, and the target's medium from the face at ``cell``: a game's
    low-poly model of a face whose photograph shows no facets.

    ``subdivisions`` (0-3, default 0; only for a ``mesh``) refines the mesh by Loop
    subdivision this many times before anything is rendered: each level splits every
    triangle in four and moves the vertices towards a smooth surface, so a scan's facets
    (the medium's flat boundary, which its interpolated shading normals do not show)
    shrink below a pixel and the buffers agree with the medium, as for a photographed
    face. The fran scan's facets lie 4.4 degrees from its shading normals on the median
    triangle, 0.6 after two levels.

    ``face_normals`` (default false) shades a mesh or face with each triangle's own
    normal (Mitsuba's ``face_normals``) instead of the interpolated vertex normals,
    in every pass: the normal buffer and the source then agree with the flat
    triangles that bound the medium (``experiments/layers_probe.py --facet-normals``
    measures what the difference costs a fit).
    """

    mesh: str | None = None
    mm_per_unit: Positive | None = None
    primitive: Literal["slab", "sphere", "face"] | None = None
    size: Annotated[list[Positive], Field(min_length=3, max_length=3)] | None = None
    radius: Positive | None = None
    # The face's grid is held to 1 mm or coarser: at 1 mm it already has 290 000 triangles.
    cell: Annotated[float, Field(ge=1.0, le=20.0)] | None = None
    buffers_cell: Annotated[float, Field(ge=1.0, le=20.0)] | None = None
    ears: bool | None = None
    wrinkles: bool | None = None
    bumps: Annotated[float, Field(ge=0.0, lt=60.0)] = 0.0
    face_normals: bool = False
    subdivisions: Annotated[int, Field(ge=0, le=3)] = 0
    pose: Pose = Pose()
    pigment: Pigment | None = None

    @model_validator(mode="after")
    def _one_kind(self):
        if (self.mesh is None) == (self.primitive is None):
            raise ValueError("give either mesh (with mm_per_unit) or primitive, not both or neither")
        if self.mesh is not None and self.mm_per_unit is None:
            raise ValueError("mesh needs mm_per_unit (millimetres per mesh unit)")
        if self.primitive == "slab" and self.size is None:
            raise ValueError('primitive "slab" needs size = [width, height, thickness] in mm')
        if self.primitive == "sphere" and self.radius is None:
            raise ValueError('primitive "sphere" needs radius in mm')
        face_keys = [k for k in ("cell", "buffers_cell", "ears", "wrinkles") if getattr(self, k) is not None]
        if face_keys and self.primitive != "face":
            raise ValueError(f'{", ".join(face_keys)}: only for primitive "face"')
        if self.bumps > 0 and self.primitive in ("slab", "sphere"):
            raise ValueError('bumps: only for a mesh or primitive "face" '
                             "(Mitsuba's slab and sphere have their own normals)")
        if self.face_normals and (self.primitive in ("slab", "sphere") or self.bumps > 0):
            raise ValueError('face_normals: only for a mesh or primitive "face" without bumps '
                             "(the bumps tilt the vertex normals that face normals ignore)")
        if self.subdivisions and (self.mesh is None or self.pigment is not None):
            raise ValueError("subdivisions: only for a mesh without a pigment "
                             "(subdivision drops the texture coordinates)")
        if self.pigment is not None and (self.mesh is None or self.bumps > 0):
            raise ValueError("pigment: only for a mesh (with texture coordinates) without bumps")
        if self.primitive == "face" and (self.size is not None or self.radius is not None):
            raise ValueError('primitive "face" has a fixed size: leave out size and radius (scale it with the camera)')
        return self

    @property
    def cell_mm(self) -> float:
        """The face's marching-cubes grid spacing (mm), 1 unless given."""
        return 1.0 if self.cell is None else self.cell

    @property
    def ears_on(self) -> bool:
        return True if self.ears is None else self.ears

    @property
    def wrinkles_on(self) -> bool:
        return True if self.wrinkles is None else self.wrinkles


class Camera(_Strict):
    """A pinhole camera with square pixels.

    Give the horizontal field of view ``fov`` in degrees or the focal length
    ``focal_px`` in pixels (``focal_px = width / 2 / tan(fov / 2)``).
    ``principal_offset_px`` (rows down, columns right) is where the optical axis
    meets the image, measured from the image centre: an offset moves the whole
    picture by that much, as a shifted lens does. :meth:`SceneConfig.with_warp`
    sets it, with the roll and focal length, to render the view a fit's
    registration found.
    """

    position: Vec3
    look_at: Vec3
    up: Vec3 = [0.0, 1.0, 0.0]
    fov: Annotated[float, Field(gt=0, lt=180)] | None = None
    focal_px: Positive | None = None
    width: Annotated[int, Field(ge=2)]
    height: Annotated[int, Field(ge=2)]
    principal_offset_px: Vec2 = [0.0, 0.0]

    def frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Origin and the right, up and forward unit vectors, as Mitsuba's ``look_at`` builds them."""
        origin = np.asarray(self.position, np.float64)
        forward = np.asarray(self.look_at, np.float64) - origin
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, np.asarray(self.up, np.float64))
        right /= np.linalg.norm(right)
        return origin, right, np.cross(right, forward), forward

    @model_validator(mode="after")
    def _one_focal(self):
        if (self.fov is None) == (self.focal_px is None):
            raise ValueError("give either fov (horizontal, degrees) or focal_px, not both or neither")
        return self

    @property
    def fov_deg(self) -> float:
        """The horizontal field of view in degrees, whichever way it was given."""
        if self.fov is not None:
            return self.fov
        assert self.focal_px is not None  # the validator requires fov or focal_px
        return math.degrees(2.0 * math.atan(self.width / 2.0 / self.focal_px))

    @property
    def focal_length_px(self) -> float:
        """The focal length in pixels, whichever way it was given."""
        if self.focal_px is not None:
            return self.focal_px
        assert self.fov is not None  # the validator requires fov or focal_px
        return self.width / 2.0 / math.tan(math.radians(self.fov) / 2.0)


class PointLight(_Strict):
    """An isotropic point light; ``intensity`` in W/sr (radiance scale is arbitrary but shared)."""

    type: Literal["point"]
    position: Vec3
    intensity: Colour


class SpotLight(_Strict):
    """A spot light at ``position`` aimed at ``look_at``; full intensity inside ``beam_width``
    degrees of its axis, falling to zero at ``cutoff`` degrees."""

    type: Literal["spot"]
    position: Vec3
    look_at: Vec3
    intensity: Colour
    cutoff: Annotated[float, Field(gt=0, le=90)] = 20.0
    beam_width: Annotated[float, Field(gt=0, le=90)] | None = None


class AreaLight(_Strict):
    """A rectangle of ``width`` x ``height`` mm at ``center``, emitting ``radiance`` towards ``look_at``."""

    type: Literal["area"]
    center: Vec3
    look_at: Vec3
    width: Positive
    height: Positive
    radiance: Colour


class DirectionalLight(_Strict):
    """A light at infinity shining along ``direction`` with ``irradiance`` on a facing surface."""

    type: Literal["directional"]
    direction: Vec3
    irradiance: Colour


Light = Annotated[PointLight | SpotLight | AreaLight | DirectionalLight, Field(discriminator="type")]


class Occluder(_Strict):
    """Opaque black stripes that cast sharp shadows (shadow edges are where scattering shows).

    ``count`` parallel stripes fill a ``width`` x ``length`` mm rectangle at
    ``center`` whose plane faces ``normal``; the stripes run along ``along`` and
    each covers ``duty`` of its period across them.
    """

    center: Vec3
    normal: Vec3
    along: Vec3 = [0.0, 1.0, 0.0]
    width: Positive
    length: Positive
    count: Annotated[int, Field(ge=1)] = 4
    duty: Annotated[float, Field(gt=0, lt=1)] = 0.5


class Medium(_Strict):
    """The homogeneous medium inside a rough dielectric boundary.

    Either a ``preset`` (see :data:`invsss.scenes.media.MEDIUM_PRESETS`) or
    ``sigma_s_prime`` and ``sigma_a`` in 1/mm (one number, or three for RGB) with
    ``eta``. ``roughness`` is the boundary's Beckmann alpha: a smooth boundary lets
    no point light into the medium by next-event estimation, about 0.5 works.

    ``boundary = "index-matched"`` drops the dielectric (a Mitsuba ``null``
    surface, eta 1: no refraction, no Fresnel reflection). Less like skin, but
    next-event estimation then reaches the light from inside the medium and the
    target converges about 50 times faster (per-sample noise about 1x the mean
    instead of 7.5x on a slab of the 940 nm medium); ``eta`` must then be left out.
    """

    preset: Literal[tuple(MEDIUM_PRESETS)] | None = None  # type: ignore[valid-type]
    sigma_s_prime: Coefficient | None = None
    sigma_a: Coefficient | None = None
    eta: Annotated[float, Field(gt=1.0, lt=3.0)] | None = None
    roughness: Annotated[float, Field(gt=0.0, le=1.0)] = 0.5
    boundary: Literal["rough-dielectric", "index-matched"] = "rough-dielectric"

    @model_validator(mode="after")
    def _preset_or_coefficients(self):
        if self.boundary == "index-matched" and self.eta is not None:
            raise ValueError('an index-matched boundary has eta 1: leave eta out, or use boundary = "rough-dielectric"')
        given = [k for k in ("sigma_s_prime", "sigma_a", "eta") if getattr(self, k) is not None]
        if self.preset is not None and given:
            raise ValueError(f"give either preset or coefficients, not both (also got {', '.join(given)})")
        if self.preset is None and (self.sigma_s_prime is None or self.sigma_a is None):
            raise ValueError("give a preset, or sigma_s_prime and sigma_a (1/mm)")
        return self

    def coefficients(self) -> dict:
        """``{"sigma_s_prime": [...], "sigma_a": [...], "eta", "boundary", "roughness", "source"}``.

        The coefficient lists hold 1 or 3 values; ``eta`` is 1 for an index-matched
        boundary (whatever a preset says) and ``roughness`` is then None.
        """
        if self.preset is not None:
            preset = MEDIUM_PRESETS[self.preset]
            values = {k: preset[k] for k in ("sigma_s_prime", "sigma_a", "eta")}
            source = f"preset {self.preset}: {preset['source']}"
        else:
            values = {"sigma_s_prime": self.sigma_s_prime, "sigma_a": self.sigma_a,
                      "eta": 1.3 if self.eta is None else self.eta}
            source = "given in the scene file"
        s, a = (v if isinstance(v, list) else [v] for v in (values["sigma_s_prime"], values["sigma_a"]))
        if len(s) != len(a):
            s, a = (v * 3 if len(v) == 1 else v for v in (s, a))
        matched = self.boundary == "index-matched"
        return {"sigma_s_prime": [float(x) for x in s], "sigma_a": [float(x) for x in a],
                "eta": 1.0 if matched else float(values["eta"]), "boundary": self.boundary,
                "roughness": None if matched else self.roughness, "source": source}


class SceneConfig(_Strict):
    """A whole scene: object, camera, lights, optional occluders, medium and render settings.

    The target's ``spp`` is split into two independently seeded halves (seeds
    ``2 seed`` and ``2 seed + 1``, so neighbouring seeds share no samples) whose
    difference gives the noise estimate; ``geometry_spp`` samples the depth, normal
    and coverage passes (stratified). ``max_depth`` bounds the path length: with
    sigma_s' = 2.4/mm a slab's diffuse albedo at 64 is 1 % (sigma_a = 0.1/mm) to 7 %
    (sigma_a = 0.01/mm) below its value at 256, and 256 and 1024 agree (measured with
    Mitsuba 3.9.1): keep 256 for low-absorption media.
    """

    variant: Literal[VARIANTS] = "scalar_rgb"  # type: ignore[valid-type]
    spp: Annotated[int, Field(ge=2)] = 64
    seed: Annotated[int, Field(ge=0, lt=2**31)] = 0
    max_depth: Annotated[int, Field(ge=1)] = 256
    geometry_spp: Annotated[int, Field(ge=1)] = 64
    object: SceneObject
    camera: Camera
    lights: Annotated[list[Light], Field(min_length=1)]
    occluders: list[Occluder] = []
    medium: Medium

    @model_validator(mode="after")
    def _pigment_needs_index_matching(self):
        if self.object.pigment is not None and self.medium.boundary != "index-matched":
            raise ValueError('object.pigment: needs medium.boundary = "index-matched" (the pigment layer is the '
                             "medium's surface)")
        return self

    @field_validator("spp")
    @classmethod
    def _even_spp(cls, spp: int) -> int:
        if spp % 2:
            raise ValueError(f"expected an even number (it is split into two equally sampled halves), got {spp}")
        return spp

    def with_overrides(self, *, width: int | None = None, height: int | None = None,
                       spp: int | None = None, seed: int | None = None,
                       name: str = "overrides") -> SceneConfig:
        """A copy with another resolution, spp or seed, checked like the file.

        Giving only one of ``width``, ``height`` keeps the aspect ratio. The view
        stays the same: a camera given by ``focal_px`` has it scaled with the width.
        ``name`` says where the overrides came from, in messages.

        Examples
        --------
        >>> config = parse_config({"object": {"primitive": "sphere", "radius": 10.0},
        ...     "camera": {"position": [0.0, 0.0, 100.0], "look_at": [0.0, 0.0, 0.0],
        ...                "focal_px": 100.0, "width": 64, "height": 32},
        ...     "lights": [{"type": "point", "position": [0.0, 0.0, 100.0], "intensity": 1.0}],
        ...     "medium": {"preset": "thesis-940"}})
        >>> small = config.with_overrides(width=32)
        >>> small.camera.width, small.camera.height, small.camera.focal_px
        (32, 16, 50.0)
        """
        camera = self.camera.model_dump()
        old_width, old_height = camera["width"], camera["height"]
        if width is not None and height is None:
            height = max(2, round(old_height * width / old_width))
        elif height is not None and width is None:
            width = max(2, round(old_width * height / old_height))
        if width is not None:
            camera.update(width=width, height=height)
            if camera["focal_px"] is not None:
                camera["focal_px"] = camera["focal_px"] * width / old_width
            camera["principal_offset_px"] = [v * width / old_width for v in camera["principal_offset_px"]]
        content = self.model_dump()
        content["camera"] = camera
        if spp is not None:
            content["spp"] = spp
        if seed is not None:
            content["seed"] = seed
        return parse_config(content, name)

    def with_warp(self, warp) -> SceneConfig:
        """The scene seen by the camera that puts this config's render where ``warp`` maps it.

        ``warp`` is a fit's registration (an :class:`invsss.estimator.registration.Warp`, or a
        params.json ``alignment`` entry) from this scene's pixels to a
        photograph's. The returned camera is rolled by its rotation, has its focal
        length multiplied by its scale and its principal point moved by its shift
        (taken about the principal point, where a camera rolls and zooms), so its
        source, depth and mask land on the photograph's pixel grid without
        resampling. Only ``translation`` and ``similarity`` warps are camera moves.

        Examples
        --------
        >>> import numpy as np
        >>> from invsss.estimator.registration import Warp
        >>> config = parse_config({"object": {"primitive": "sphere", "radius": 10.0},
        ...     "camera": {"position": [0.0, 0.0, 100.0], "look_at": [0.0, 0.0, 0.0],
        ...                "focal_px": 100.0, "width": 64, "height": 32},
        ...     "lights": [{"type": "point", "position": [0.0, 0.0, 100.0], "intensity": 1.0}],
        ...     "medium": {"preset": "thesis-940"}})
        >>> camera = config.with_warp(Warp("similarity", (1.5, -2.0, 0.0, float(np.log(1.01))),
        ...                                (15.5, 31.5))).camera
        >>> camera.principal_offset_px, round(camera.focal_px, 6)
        ([1.5, -2.0], 101.0)
        """
        from ..estimator.registration import Warp

        warp = warp if isinstance(warp, Warp) else Warp.from_dict(warp)
        if warp.kind not in ("translation", "similarity"):
            raise InvalidInputError(f"warp: a {warp.kind} warp is not a camera move; expected a translation or "
                                    "similarity (fit with --align similarity)")
        camera = self.camera
        principal = np.array([(camera.height - 1) / 2.0, (camera.width - 1) / 2.0]) + camera.principal_offset_px
        about = warp.recentred(tuple(principal)).to_dict()
        # The picture turns by +a (counter-clockwise as displayed) when the camera
        # rolls the other way: its up vector turns towards its right.
        angle = math.radians(about.get("rotation_deg", 0.0))
        _, right, up, _ = camera.frame()
        content = self.model_dump()
        content["camera"].update(
            up=(math.cos(angle) * up + math.sin(angle) * right).tolist(),
            fov=None,
            focal_px=camera.focal_length_px * about.get("scale", 1.0),
            principal_offset_px=(np.asarray(camera.principal_offset_px) + about["shift_px"]).tolist(),
        )
        return parse_config(content, "the config moved by the warp")


# ------------------------------------------------------------------ reading


def load_config(path) -> SceneConfig:
    """Read and check a scene TOML file; a relative mesh path becomes relative to the file.

    Raises
    ------
    InvalidInputError
        An unreadable file, bad TOML, or a bad key or value (one line naming it),
        or a mesh file that does not exist.

    Examples
    --------
    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "scene.toml")
    >>> _ = open(path, "w").write('sppp = 4\\n')
    >>> load_config(path)
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: ...scene.toml: sppp: unknown key, did you mean 'spp'? (valid: variant, spp, seed, max_depth, geometry_spp, object, camera, lights, occluders, medium)
    """  # noqa: E501
    name = os.fspath(path)
    try:
        with open(name, "rb") as f:
            content = tomllib.load(f)
    except OSError as err:
        raise InvalidInputError(f"{name}: cannot read the scene file ({err.strerror})", field=name) from None
    except tomllib.TOMLDecodeError as err:
        raise InvalidInputError(f"{name}: not valid TOML ({err})", field=name) from None
    config = parse_config(content, name)
    if config.object.mesh is not None:
        mesh = os.path.join(os.path.dirname(os.path.abspath(name)), os.path.expanduser(config.object.mesh))
        if not os.path.isfile(mesh):
            raise InvalidInputError(f"{name}: object.mesh: file {config.object.mesh} not found (looked at {mesh})",
                                    field=name)
        update: dict[str, object] = {"mesh": mesh}
        pigment = config.object.pigment
        if pigment is not None:
            image = os.path.join(os.path.dirname(os.path.abspath(name)), os.path.expanduser(pigment.map))
            if not os.path.isfile(image):
                raise InvalidInputError(f"{name}: object.pigment.map: file {pigment.map} not found (looked at {image})",
                                        field=name)
            update["pigment"] = pigment.model_copy(update={"map": image})
        config = config.model_copy(update={"object": config.object.model_copy(update=update)})
    return config


def parse_config(content: dict, name: str = "scene") -> SceneConfig:
    """Check a scene description already parsed into a dict (``name`` is used in messages).

    Examples
    --------
    >>> parse_config({"spp": True}, "demo")
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: demo: spp: expected an integer, got true
    """
    try:
        return SceneConfig.model_validate(content)
    except ValidationError as err:
        errors = err.errors()
        # A misspelt key also makes the real one "missing": name the misspelling first.
        unknown = [e for e in errors if e["type"] == "extra_forbidden"]
        raise InvalidInputError(pydantic_error_line((unknown or errors)[0], name, SceneConfig)) from None
