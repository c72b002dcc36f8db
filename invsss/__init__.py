"""invsss: differentiable inverse rendering of screen-space subsurface scattering.

The forward model (:func:`render`, docs/model.md, section 5) and its pieces are pure
JAX functions; :mod:`invsss.torch` is the PyTorch twin used to cross-check them.

Importing :mod:`invsss` loads only the forward model. The file readers
(OpenImageIO), the estimator (optimistix, scikit-image) and the exporters are
imported the first time one of their names is used (PEP 562), so a script that
only renders arrays does not pay for them.
"""

# First of all, before JAX is imported (a second or more): in the `invsss` command's
# own process, a Ctrl-C from here on ends it with one line and status 130 instead of
# a KeyboardInterrupt traceback. Nothing changes for any other process. That is why the
# imports below come after a statement ("noqa: E402" on each).
from .runtime.interrupts import guard_command_line as _guard_command_line

_guard_command_line()

import importlib  # noqa: E402

from .forward.light_terms import LightBuffers, LightTerms, apply_law, apply_light_terms  # noqa: E402
from .forward.models import MODEL_NAMES, ScreenSpaceModel, get_model  # noqa: E402
from .forward.params import SSSParams  # noqa: E402
from .forward.passes import TAP_WEIGHTS, directional_pass, sample_along, tap_spread, tap_weights  # noqa: E402
from .forward.profiles import (  # noqa: E402
    DEON_SKIN_RGB,
    JENSEN_SKIN1,
    JENSEN_SKIN1_SOG,
    PROFILE_NAMES,
    THESIS_NIR_940,
    SumOfGaussians,
    burley,
    gaussian,
    jensen_dipole,
    jensen_dipole_total,
    load_profile,
    sum_of_gaussians,
    total_diffuse_reflectance,
)
from .forward.screen_space import (  # noqa: E402
    MODELS,
    render,
    render_separable,
    render_sog,
    render_thesis,
    separable_kernel,
    sog_layers,
)
from .forward.stretch import depth_slopes, stretch_factors  # noqa: E402
from .validation import InputNotice, InvalidInputError  # noqa: E402

__version__ = "0.1.0"

# Public name -> the submodule that defines it, imported on first access.
_LAZY = {
    **dict.fromkeys(
        (
            "clipping_level",
            "load_pair",
            "read_depth",
            "read_image",
            "read_mask",
            "read_params",
            "write_image",
            "write_params",
        ),
        ".io",
    ),
    **dict.fromkeys(
        ("FitInterrupted", "FitOptions", "FitResult", "build_problem", "fit_pair", "fit_pairs"),
        ".estimator",
    ),
    **dict.fromkeys(("ResultDir", "result_state"), ".io.result_dir"),
    **dict.fromkeys(("export_params", "shader_constants", "to_hlsl", "to_json"), ".io.export"),
    **dict.fromkeys(("ProfileFit", "fit_sum_of_gaussians"), ".measurement.profile_fit"),
    **dict.fromkeys(("MeasuredProfile", "column_average_gain", "measure_profile"), ".measurement.measure"),
    **dict.fromkeys(("DipoleFit", "fit_dipole"), ".measurement.dipole_fit"),
    **dict.fromkeys(("ImagePair", "fill_background_depth"), ".forward.pair"),
    "enable_compile_cache": ".runtime.compile_cache",
}

# Submodules reachable as attributes (``invsss.io.PARAMS_KEYS``) without an import: the
# layer folders (docs/architecture.md).
_SUBMODULES = (
    "cli", "estimator", "experiments", "forward", "io", "measurement", "runtime", "scenes", "shaders", "sweeps",
    "torch",
)

# The names imported above (in their former import order, which this list kept when it
# was read from the module's globals), then the lazy ones. Written out so that ruff sees
# them as re-exports: an import left out of this list is reported as unused (F401).
__all__ = [
    "SSSParams",
    "TAP_WEIGHTS",
    "directional_pass",
    "sample_along",
    "tap_spread",
    "tap_weights",
    "DEON_SKIN_RGB",
    "JENSEN_SKIN1",
    "JENSEN_SKIN1_SOG",
    "PROFILE_NAMES",
    "THESIS_NIR_940",
    "SumOfGaussians",
    "burley",
    "gaussian",
    "jensen_dipole",
    "jensen_dipole_total",
    "load_profile",
    "sum_of_gaussians",
    "total_diffuse_reflectance",
    "MODELS",
    "render",
    "render_separable",
    "render_sog",
    "render_thesis",
    "separable_kernel",
    "sog_layers",
    "LightBuffers",
    "LightTerms",
    "apply_law",
    "apply_light_terms",
    "MODEL_NAMES",
    "ScreenSpaceModel",
    "get_model",
    "depth_slopes",
    "stretch_factors",
    "InputNotice",
    "InvalidInputError",
] + sorted(_LAZY)


def __getattr__(name: str):
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'invsss' has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY) | set(_SUBMODULES))
