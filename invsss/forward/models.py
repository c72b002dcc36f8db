"""The table of screen-space models (docs/model.md, section 5): one entry per model.

Every place that behaves differently per model (the JAX and PyTorch renderers,
the estimator's basis images and parameter roles, the shader-constant export)
reads the entry here instead of comparing model names, so adding a model is
adding one :class:`ScreenSpaceModel` to :data:`MODEL_TABLE`. :data:`MODELS` (as
``invsss.MODELS``) is the tuple of their names.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..validation import InvalidInputError
from .params import PARAM_NAMES
from .pass_plan import LAYOUTS_WITH_PASSES, PassPlan, pass_plan

__all__ = [
    "LAYOUTS",
    "WEIGHTS_ROLES",
    "ScreenSpaceModel",
    "MODEL_TABLE",
    "MODELS",
    "MODEL_NAMES",
    "VARIANCE_MEANINGS",
    "get_model",
    "resolve_tap_weights",
]

#: How the estimator treats the weights of a model: ``"linear"`` (the image is
#: linear in them, so variable projection eliminates them), ``"free"`` (an
#: ordinary nonlinear parameter) or ``"unused"`` (they do not enter the image).
WEIGHTS_ROLES = ("linear", "free", "unused")

#: How a model turns the profile into passes. The JAX renderer, the PyTorch
#: twin and the export each implement a layout once; models share them.
#: ``"layered"``: pass pairs of variance differences whose vertical passes are
#: mixed by the weights; ``"chained"``: K horizontal then K vertical passes of
#: the full variances, the last one the output (both 7-tap, planned by
#: :func:`invsss.forward.pass_plan.pass_plan`); ``"kernel"``: one pass pair with a
#: precomputed N-tap kernel; ``"disk"``: one gather of importance-sampled
#: radii over a disk (:mod:`invsss.forward.burley_screen_space`, issue 34).
LAYOUTS = ("layered", "chained", "kernel", "disk")

#: What a model's ``variances`` are: ``"gaussian"``, the variances of the
#: profile's Gaussians (scene units^2 per unit stretch); ``"burley_d2"``, the
#: square of Burley's shape parameter ``d`` per channel (docs/model.md, section 4).
VARIANCE_MEANINGS = ("gaussian", "burley_d2")


@dataclass(frozen=True)
class ScreenSpaceModel:
    """What distinguishes one screen-space model from another.

    Attributes
    ----------
    name : str
        The name used by ``render(..., model=name)``, params files and the CLI.
    summary : str
        One line for help texts.
    default_tap_weights : {"jimenez", "thesis"} or None
        The 7-tap weight set used when the caller names none; ``None`` for a
        model without 7-tap passes.
    parameters : frozenset of str
        The names from :data:`invsss.forward.params.PARAM_NAMES` that change its image.
    default_gauge : {"variances", "depth"}
        The estimator's gauge when the caller names none (docs/model.md, section 6):
        ``"variances"`` where scaling every variance by ``a^2`` and ``sss_level``
        by ``1 / a`` gives the same image, so the profile's variances are held;
        ``"depth"`` where the image also depends on the variances in scene units
        alone (``burley`` weights its samples by the 3D distance, with the depth
        difference in scene units), so both are estimated.
    weights_role : {"linear", "free", "unused"}
        How the estimator treats the weights (see :data:`WEIGHTS_ROLES`).
    layout : {"layered", "chained", "kernel", "disk"}
        How it turns the profile into passes (see :data:`LAYOUTS`); the JAX and
        PyTorch renderers and the reference shader's dispatch follow it.
    shader : (str, tuple of str)
        The reference shader's HLSL file in ``invsss/shaders`` and its compute
        entry points, in the order a frame dispatches them (:mod:`invsss.shaders`).
    variance_meaning : {"gaussian", "burley_d2"}
        What its variances are (see :data:`VARIANCE_MEANINGS`): the report draws
        the profile, and the export converts it, by this.

    Examples
    --------
    >>> from invsss.forward.models import get_model
    >>> m = get_model("thesis")
    >>> m.default_tap_weights, "weights" in m.parameters, m.weights_role
    ('thesis', False, 'unused')
    """

    name: str
    summary: str
    default_tap_weights: str | None
    parameters: frozenset
    weights_role: str
    layout: str
    shader: tuple[str, tuple[str, ...]]
    default_gauge: str = "variances"
    variance_meaning: str = "gaussian"

    def __post_init__(self):
        # The table is written by hand; catch a typo when the module loads
        # rather than as a silently ignored parameter later.
        unknown = self.parameters - set(PARAM_NAMES)
        if unknown:
            raise ValueError(f"model {self.name}: unknown parameter(s) {sorted(unknown)}")
        if self.weights_role not in WEIGHTS_ROLES:
            raise ValueError(f"model {self.name}: weights_role {self.weights_role!r}")
        if self.layout not in LAYOUTS:
            raise ValueError(f"model {self.name}: layout {self.layout!r}")
        if self.variance_meaning not in VARIANCE_MEANINGS:
            raise ValueError(f"model {self.name}: variance_meaning {self.variance_meaning!r}")
        if self.default_gauge not in ("variances", "depth"):
            raise ValueError(f"model {self.name}: default_gauge {self.default_gauge!r}")
        if (self.weights_role == "unused") == ("weights" in self.parameters):
            raise ValueError(f"model {self.name}: weights_role disagrees with parameters")
        if self.weights_role == "linear" and self.layout != "layered":
            # Only the layered layout's output is a weighted mean of images
            # that do not depend on the weights (the estimator's basis).
            raise ValueError(f"model {self.name}: linear weights need the layered layout")
        if (self.default_tap_weights is None) != (self.layout not in LAYOUTS_WITH_PASSES):
            raise ValueError(f"model {self.name}: 7-tap passes need a default tap weight set")

    def pass_plan(self, variances, spread, xp) -> PassPlan:
        """Its 7-tap passes and their widths per unit stretch (:func:`invsss.forward.pass_plan.pass_plan`).

        Examples
        --------
        >>> import numpy as np
        >>> get_model("thesis").pass_plan(np.array([1.0]), 0.5, np).widths.tolist()
        [2.0, 2.0]
        """
        if self.layout not in LAYOUTS_WITH_PASSES:
            raise ValueError(f"model {self.name}: layout {self.layout!r} has no 7-tap passes")
        return pass_plan(self.layout, variances, spread, xp)


_ALL = frozenset(PARAM_NAMES)

#: The models by name; the first one is the default.
MODEL_TABLE: dict[str, ScreenSpaceModel] = {
    m.name: m
    for m in (
        ScreenSpaceModel(
            name="sog",
            summary="sum of Gaussians as blur layers mixed by the weights (d'Eon & Luebke)",
            default_tap_weights="jimenez",
            parameters=_ALL,
            weights_role="linear",
            layout="layered",
            shader=("invsss_sog.hlsl", ("BlurPassCS", "AccumulateCS")),
        ),
        ScreenSpaceModel(
            name="thesis",
            summary="the thesis's chain of K horizontal then K vertical passes",
            default_tap_weights="thesis",
            parameters=_ALL - {"weights"},
            weights_role="unused",
            layout="chained",
            shader=("invsss_thesis.hlsl", ("BlurPassCS",)),
        ),
        ScreenSpaceModel(
            name="separable",
            summary="Jimenez 2015 separable SSS with a precomputed N-tap kernel",
            default_tap_weights=None,
            # Its taps land at x + o L / d: no slope correction.
            parameters=frozenset({"sss_level", "weights", "variances"}),
            weights_role="free",
            layout="kernel",
            shader=("invsss_separable.hlsl", ("SeparablePassCS",)),
        ),
        # --- issue 34: the engines' model (invsss.forward.burley_screen_space) ---
        ScreenSpaceModel(
            name="burley",
            summary="Burley normalized diffusion sampled over a disk, as Unity HDRP and Unreal do",
            default_tap_weights=None,
            # Its variances are d_c^2, one per channel; samples land at r L / depth.
            parameters=frozenset({"sss_level", "variances"}),
            weights_role="unused",
            layout="disk",
            shader=("invsss_burley.hlsl", ("BurleyDiskCS",)),
            variance_meaning="burley_d2",
            # Its weights see the depth difference in mm: L and d are separable
            # (recovered within 0.2 % on a 64 x 64 model-made pair, issue 46).
            default_gauge="depth",
        ),
        # --- end issue 34 ---
    )
}

#: The model names, default first.
MODEL_NAMES: tuple[str, ...] = tuple(MODEL_TABLE)
#: The same names under the name the package exports (``invsss.MODELS``).
MODELS = MODEL_NAMES


def get_model(name) -> ScreenSpaceModel:
    """The table entry of model ``name``.

    Raises
    ------
    InvalidInputError
        If ``name`` is not in :data:`MODEL_NAMES`.

    Examples
    --------
    >>> get_model("sog").weights_role
    'linear'
    >>> get_model("blur")
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: model: expected one of sog, thesis, separable, burley, got 'blur'
    """
    if isinstance(name, ScreenSpaceModel):
        return name
    if not isinstance(name, str) or name not in MODEL_TABLE:
        raise InvalidInputError(f"model: expected one of {', '.join(MODEL_NAMES)}, got {name!r}", field="model")
    return MODEL_TABLE[name]


def resolve_tap_weights(model, spec=None):
    """The 7-tap weights to use: ``spec`` if given, else the model's default.

    Returns ``None`` for a model without 7-tap passes (``spec`` is ignored).

    Examples
    --------
    >>> resolve_tap_weights("thesis"), resolve_tap_weights("sog", "thesis")
    ('thesis', 'thesis')
    >>> resolve_tap_weights("separable", "jimenez") is None
    True
    """
    entry = get_model(model)
    if entry.default_tap_weights is None:
        return None
    return entry.default_tap_weights if spec is None else spec
