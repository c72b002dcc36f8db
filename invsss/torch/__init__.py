"""PyTorch twin of the invsss forward model, used to cross-check the JAX core.

Every function here computes the same thing as its JAX namesake (docs/model.md is the
single definition both follow), module for module:

=====================================  ==========================================
``invsss.torch``                        JAX core
=====================================  ==========================================
:class:`SSSParams` (dataclass)          :class:`invsss.SSSParams` (``eqx.Module``)
:func:`depth_slopes`,                   :mod:`invsss.forward.stretch`
:func:`stretch_factors`
:func:`sample_along`,                   :mod:`invsss.forward.passes`
:func:`directional_pass`, ...
:func:`gaussian`,                       :mod:`invsss.forward.profiles`
:func:`sum_of_gaussians`
:func:`render`, :func:`sog_layers`,     :mod:`invsss.forward.screen_space`
:func:`separable_kernel`, ...
:func:`render_burley`                   :mod:`invsss.forward.burley_screen_space`
:func:`apply_light_terms`,              :mod:`invsss.forward.light_terms`
:func:`shift_image`, ...
=====================================  ==========================================

Only the tap constants (``TAP_OFFSETS``, ``TAP_WEIGHTS``), the model names and the
array validators are shared with the JAX code. The part most likely to hide a bug
is implemented independently: the JAX core interpolates with a flat gather and
explicit clamping, while this twin samples with :func:`kornia.geometry.transform.remap`
(``grid_sample``, bilinear, ``padding_mode="border"``, ``align_corners=True``)
at the pixel's own row or column; depth slopes come from :func:`torch.gradient`,
and the sum-of-Gaussians layers are a Python loop rather than ``lax.scan``.
Gradients come from ``torch.autograd``, so agreement with ``jax.grad`` checks both
the derivatives and the conventions at the identity pass (a zero variance
difference has zero derivative, like the JAX ``_safe_sqrt``).

Requires the optional extra ``torch`` (``torch`` and ``kornia``); ``import invsss``
never imports it.

Examples
--------
>>> import torch
>>> import invsss.torch as itorch
>>> image = torch.ones(8, 8, 3); depth = torch.full((8, 8), 500.0); mask = torch.ones(8, 8)
>>> p = itorch.SSSParams(1000.0, 0.0, 1.0, [0.5, 0.5], [0.5, 2.0])
>>> bool(torch.allclose(itorch.render(image, depth, mask, p), torch.ones(8, 8, 3)))
True
"""

try:
    import kornia  # noqa: F401
    import torch  # noqa: F401
except ImportError as err:  # pragma: no cover - exercised only without the extra
    raise ImportError(
        "invsss.torch needs the optional dependencies torch and kornia "
        "(pip install 'invsss[torch]')"
    ) from err

from .burley_screen_space import render_burley
from .light_terms import (
    apply_law,
    apply_light_terms,
    apply_transmission,
    burley_transmittance,
    chandrasekhar_h,
    grazing_field,
    incidence_field,
    law_source,
    propagation_offsets,
    reflectance_law,
    shift_image,
    wrapped_back_lighting,
)
from .params import SSSParams
from .passes import TAP_OFFSETS, TAP_WEIGHTS, directional_pass, sample_along, tap_spread, tap_weights
from .profiles import gaussian, sum_of_gaussians
from .screen_space import (
    MODELS,
    render,
    render_separable,
    render_sog,
    render_thesis,
    separable_kernel,
    sog_layers,
)
from .stretch import depth_slopes, stretch_factors

__all__ = [
    "SSSParams",
    "apply_light_terms",
    "apply_law",
    "apply_transmission",
    "burley_transmittance",
    "wrapped_back_lighting",
    "chandrasekhar_h",
    "reflectance_law",
    "law_source",
    "grazing_field",
    "incidence_field",
    "propagation_offsets",
    "shift_image",
    "TAP_OFFSETS",
    "TAP_WEIGHTS",
    "tap_weights",
    "tap_spread",
    "sample_along",
    "directional_pass",
    "gaussian",
    "sum_of_gaussians",
    "depth_slopes",
    "stretch_factors",
    "MODELS",
    "render",
    "render_sog",
    "render_thesis",
    "render_separable",
    "render_burley",
    "sog_layers",
    "separable_kernel",
]
