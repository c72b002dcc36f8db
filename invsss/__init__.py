"""invsss: differentiable inverse rendering of screen-space subsurface scattering.

The forward model (:func:`render`, MODEL.md section 5) and its pieces are pure
JAX functions; :mod:`invsss.torch` is the PyTorch twin used to cross-check them.
"""

from .params import SSSParams
from .passes import TAP_WEIGHTS, directional_pass, sample_along, tap_spread, tap_weights
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
from .validation import InvalidInputError

__version__ = "0.1.0"
