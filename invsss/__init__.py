"""invsss: differentiable inverse rendering of screen-space subsurface scattering.

The forward model (:func:`render`, MODEL.md section 5) and its pieces are pure
JAX functions; :mod:`invsss.torch` is the PyTorch twin used to cross-check them.
"""

from .io import (
    ImagePair,
    load_pair,
    read_depth,
    read_image,
    read_mask,
    read_params,
    write_image,
    write_params,
)
from .estimator import FitResult, fit_pair, fit_pairs
from .export import export_params, shader_constants, to_hlsl, to_json
from .params import SSSParams
from .passes import TAP_WEIGHTS, directional_pass, sample_along, tap_spread, tap_weights
from .profiles import gaussian, sum_of_gaussians
from .profiles import (
    DEON_SKIN_RGB,
    JENSEN_SKIN1,
    JENSEN_SKIN1_SOG,
    PROFILE_NAMES,
    THESIS_NIR_940,
    SumOfGaussians,
    burley,
    jensen_dipole,
    jensen_dipole_total,
    load_profile,
    total_diffuse_reflectance,
)
from .profile_fit import ProfileFit, fit_sum_of_gaussians
from .measure import MeasuredProfile, column_average_gain, measure_profile
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
