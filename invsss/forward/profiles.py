"""Radial diffusion profiles R(r) (docs/model.md, section 4).

A diffusion profile ``R(r)`` is the light leaving a surface at distance ``r`` from a
point of entry, per unit area and per unit of entering power (thesis 3.2.4). Its
integral over the plane, ``2 pi int_0^inf R(r) r dr``, is the total diffuse
reflectance. Three analytic families live here:

* the sum of Gaussians (thesis eq. 4.1-4.2, d'Eon & Luebke 2007), the form every
  screen-space model uses, with its published tables and a small pytree type;
* Jensen et al.'s 2001 dipole (thesis eq. 3.4, written as in docs/model.md);
* Christensen & Burley's 2015 normalized diffusion.

Distances are in millimetres throughout (so variances are in mm^2 and profiles in
mm^-2), the unit of every published table below. All functions are pure JAX and
compose with ``jit``, ``grad`` and ``vmap``.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..validation import InvalidInputError, is_concrete, number_array
from .arrays import float_array

__all__ = [
    "gaussian",
    "sum_of_gaussians",
    "jensen_dipole",
    "jensen_dipole_total",
    "burley",
    "total_diffuse_reflectance",
    "THESIS_NIR_940",
    "DEON_SKIN_RGB",
    "JENSEN_SKIN1",
    "JENSEN_SKIN1_SOG",
    "PROFILE_NAMES",
    "SumOfGaussians",
    "check_profile_arrays",
    "load_profile",
]


def _namespace(*arrays):
    # All NumPy in, NumPy out: host-side callers (the report's profile plot) then
    # pay no JAX dispatch or compilation. Anything else goes through jax.numpy.
    return np if all(isinstance(a, np.ndarray) for a in arrays) else jnp


def gaussian(variance, r):
    """Normalised 2D Gaussian ``G(v, r) = exp(-r^2 / (2 v)) / (2 pi v)`` (thesis eq. 4.1).

    NumPy arrays in give a NumPy array out; otherwise a JAX array.
    """
    xp = _namespace(variance, r)
    return xp.exp(-(r**2) / (2.0 * variance)) / (2.0 * np.pi * variance)


def sum_of_gaussians(
    r: Float[Array, "*N"], weights: Float[Array, " K *C"], variances: Float[Array, " K"]
) -> Float[Array, "*N *C"]:
    """``R(r) = sum_i w_i G(v_i, r)`` (thesis eq. 4.2, d'Eon & Luebke 2007).

    With per-channel weights of shape (K, C) the result gains a trailing C axis.
    Three NumPy arrays in give a NumPy array out (computed by NumPy); otherwise
    the result is a JAX array.

    Examples
    --------
    >>> import jax.numpy as jnp, numpy as np
    >>> float(sum_of_gaussians(jnp.array(0.0), jnp.array([1.0]), jnp.array([1.0 / (2 * jnp.pi)])))
    1.0
    >>> sum_of_gaussians(np.array([0.0, 1.0]), np.array([0.5, 0.5]), np.array([1.0, 2.0])).round(4)
    array([0.1194, 0.0793])
    """
    xp = _namespace(r, weights, variances)
    r, weights, variances = xp.asarray(r), xp.asarray(weights), xp.asarray(variances)
    g = gaussian(variances, r[..., None])  # (*N, K)
    if weights.ndim == 1:
        return xp.sum(g * weights, axis=-1)
    return xp.einsum("...k,kc->...c", g, weights)


# --------------------------------------------------------------------------- dipole


def _with_coefficient_axes(r, *coefficients):
    # Coefficients of shape (*C,) (e.g. one per colour channel) broadcast against
    # each other and add trailing axes to r, so R has shape (*N, *C).
    coefficients = [jnp.asarray(c) for c in coefficients]
    shape = jnp.broadcast_shapes(*(c.shape for c in coefficients))
    r = jnp.asarray(r)
    return r.reshape(r.shape + (1,) * len(shape)), coefficients


def _diffuse_fresnel_boundary(eta):
    # F_dr is Egan & Hilgeman's fit of the diffuse Fresnel reflectance used by
    # Jensen et al. 2001; A is the boundary mismatch that places the virtual source.
    f_dr = -1.440 / eta**2 + 0.710 / eta + 0.668 + 0.0636 * eta
    return (1.0 + f_dr) / (1.0 - f_dr)


def jensen_dipole(
    r: Float[Array, "*N"], sigma_s_prime, sigma_a, eta=1.3
) -> Float[Array, "*N *C"]:
    """Jensen et al. 2001 dipole diffuse reflectance ``R_d(r)`` (docs/model.md, section 4).

    ``sigma_t' = sigma_s' + sigma_a``, ``alpha' = sigma_s' / sigma_t'``,
    ``sigma_tr = sqrt(3 sigma_a sigma_t')``, ``z_r = 1 / sigma_t'``,
    ``z_v = z_r (1 + 4 A / 3)``, ``d_{r,v} = sqrt(r^2 + z_{r,v}^2)`` and::

        R_d(r) = alpha' / (4 pi) [ z_r (sigma_tr d_r + 1) exp(-sigma_tr d_r) / d_r^3
                                 + z_v (sigma_tr d_v + 1) exp(-sigma_tr d_v) / d_v^3 ]

    (the thesis's eq. 3.4 is the same expression with ``d^2`` factored out).

    Parameters
    ----------
    r : array, shape (*N)
        Distance from the point of entry, mm (>= 0; the profile is finite at 0).
    sigma_s_prime, sigma_a : float or array, shape (*C)
        Reduced scattering and absorption coefficients, mm^-1. Arrays (e.g. one
        value per colour channel) broadcast together and add trailing axes.
    eta : float or array, shape (*C)
        Relative index of refraction.

    Returns
    -------
    array, shape (*N, *C)
        ``R_d(r)`` in mm^-2.

    Examples
    --------
    >>> import jax.numpy as jnp
    >>> skin1 = jensen_dipole(jnp.array([0.0, 1.0]), jnp.array([0.74, 0.88, 1.01]),
    ...                       jnp.array([0.032, 0.17, 0.48]))
    >>> skin1.shape
    (2, 3)
    """
    r, (sigma_s_prime, sigma_a, eta) = _with_coefficient_axes(r, sigma_s_prime, sigma_a, eta)
    sigma_t = sigma_s_prime + sigma_a
    albedo = sigma_s_prime / sigma_t
    sigma_tr = jnp.sqrt(3.0 * sigma_a * sigma_t)
    boundary = _diffuse_fresnel_boundary(eta)
    z_r = 1.0 / sigma_t
    z_v = z_r * (1.0 + 4.0 * boundary / 3.0)

    def source(z):
        d = jnp.sqrt(r**2 + z**2)  # >= z > 0: no singularity, r = 0 included
        return z * (sigma_tr * d + 1.0) * jnp.exp(-sigma_tr * d) / d**3

    return albedo / (4.0 * jnp.pi) * (source(z_r) + source(z_v))


def jensen_dipole_total(sigma_s_prime, sigma_a, eta=1.3) -> Float[Array, "*C"]:
    """Total diffuse reflectance of the dipole, ``2 pi int_0^inf R_d(r) r dr``, closed form.

    ``R_d = (alpha' / 2) (1 + exp(-(4/3) A sqrt(3 (1 - alpha')))) exp(-sqrt(3 (1 - alpha')))``
    (Jensen et al. 2001, eq. 7 in their notation). It follows from
    ``2 pi int_z^inf z (s d + 1) exp(-s d) / d^2 dd = 2 pi exp(-s z)`` with
    ``sigma_tr z_r = sqrt(3 (1 - alpha'))``.

    Examples
    --------
    >>> round(float(jensen_dipole_total(0.74, 0.032)), 3)
    0.436
    """
    sigma_s_prime, sigma_a, eta = (jnp.asarray(x) for x in (sigma_s_prime, sigma_a, eta))
    albedo = sigma_s_prime / (sigma_s_prime + sigma_a)
    boundary = _diffuse_fresnel_boundary(eta)
    root = jnp.sqrt(3.0 * (1.0 - albedo))
    return 0.5 * albedo * (1.0 + jnp.exp(-4.0 / 3.0 * boundary * root)) * jnp.exp(-root)


# --------------------------------------------------------------------------- Burley

#: Burley's profile is evaluated at ``max(r, BURLEY_R_FLOOR * d)``; see :func:`burley`.
BURLEY_R_FLOOR = 1e-6


def burley(r: Float[Array, "*N"], d, A=1.0) -> Float[Array, "*N *C"]:
    """Christensen & Burley 2015 normalized diffusion ``A (e^{-r/d} + e^{-r/(3d)}) / (8 pi d r)``.

    It integrates to ``A`` over the plane for every shape parameter ``d``.

    Parameters
    ----------
    r : array, shape (*N)
        Distance, mm. The profile has an integrable ``1/r`` singularity at 0 (``r R(r)``
        tends to ``A / (4 pi d)``). To stay finite and differentiable there, ``r`` is
        clamped to ``BURLEY_R_FLOOR * d`` (1e-6 d), as production renderers clamp: at
        ``r = 0`` the value is large (about ``A / (4 pi d^2) * 1e6``) but finite, its
        derivative with respect to ``r`` is 0 and with respect to ``d`` and ``A`` finite.
        The disc the clamp changes holds a fraction ~1e-6 of the energy. Sample
        ``r > 0`` when fitting or integrating.
    d : float or array, shape (*C)
        Shape parameter, mm (> 0); per-channel arrays add a trailing axis.
    A : float or array, shape (*C)
        Total diffuse reflectance (surface albedo).

    Examples
    --------
    >>> import jax.numpy as jnp
    >>> bool(jnp.isfinite(burley(jnp.array(0.0), 1.0)))
    True
    """
    r, (d, A) = _with_coefficient_axes(r, d, A)
    r = jnp.maximum(r, BURLEY_R_FLOOR * d)
    return A * (jnp.exp(-r / d) + jnp.exp(-r / (3.0 * d))) / (8.0 * jnp.pi * d * r)


# --------------------------------------------------------------------------- integral


def total_diffuse_reflectance(
    profile_fn, *, r_min: float = 1e-6, r_max: float = 100.0, num: int = 4097
) -> Float[Array, "*C"]:
    """Numerical ``2 pi int_0^r_max R(r) r dr`` of a radial profile.

    The integral is taken in ``u = log r`` (``R r^2 du``) with the trapezoid rule on
    ``num`` points between ``r_min`` and ``r_max``: profiles span decades in ``r``
    (d'Eon's narrowest Gaussian has a 0.08 mm deviation, the dipole's red tail reaches
    30 mm), and in ``log r`` the integrand decays smoothly at both ends, where the
    trapezoid rule converges fast. The disc ``r < r_min`` adds ``pi r_min^2 R(r_min)``.

    Closed forms to compare with: the weights' sum for a sum of Gaussians (each
    ``G(v, .)`` integrates to 1), ``A`` for :func:`burley`, and
    :func:`jensen_dipole_total` for the dipole.

    Parameters
    ----------
    profile_fn : callable
        ``r (N,) -> R (N,) or (N, C)``, e.g. a :class:`SumOfGaussians` or
        ``functools.partial(jensen_dipole, sigma_s_prime=..., sigma_a=...)``.
    r_min, r_max : float
        Integration range in the profile's distance unit (mm).
    num : int
        Number of samples.

    Returns
    -------
    array, shape (*C)

    Examples
    --------
    >>> import functools
    >>> round(float(total_diffuse_reflectance(functools.partial(burley, d=0.5, A=0.8))), 3)
    0.8
    """
    u = jnp.linspace(jnp.log(r_min), jnp.log(r_max), num)
    r = jnp.exp(u)
    values = profile_fn(r)
    r_cols = r.reshape(r.shape + (1,) * (jnp.ndim(values) - 1))
    integrand = values * r_cols**2
    ring = jnp.trapezoid(integrand, u, axis=0)
    disc = 0.5 * r_min**2 * values[0]
    return 2.0 * jnp.pi * (ring + disc)


# --------------------------------------------------------------------------- tables

# The thesis's 940 nm inner-forearm fit, its Table 5.1 ("8,749" there is 8.749 with a
# decimal comma). Variances mm^2. The two Gaussians at 0.549 and 0.5574 nearly coincide.
THESIS_NIR_940 = MappingProxyType(
    {
        "variances": (8.749, 2.099, 0.549, 0.5574, 1.194),
        "weights": (0.1478, 0.1323, 0.0004, 0.0527, 0.090),
        "source": "thesis Table 5.1 (940 nm, inner forearm)",
    }
)

# d'Eon & Luebke 2007, "Advanced Techniques for Realistic Real-Time Skin Rendering",
# GPU Gems 3 ch. 14, Figure 14-13: six Gaussians fitted to a three-layer skin model.
# Variances mm^2; weights (red, green, blue) per Gaussian.
DEON_SKIN_RGB = MappingProxyType(
    {
        "variances": (0.0064, 0.0484, 0.187, 0.567, 1.99, 7.41),
        "weights": (
            (0.233, 0.455, 0.649),
            (0.100, 0.336, 0.344),
            (0.118, 0.198, 0.0),
            (0.113, 0.007, 0.007),
            (0.358, 0.004, 0.0),
            (0.078, 0.0, 0.0),
        ),
        "source": "d'Eon & Luebke 2007, GPU Gems 3 ch. 14 (three-layer skin, RGB)",
    }
)

# Jensen, Marschner, Levoy & Hanrahan 2001, "A Practical Model for Subsurface Light
# Transport", Figure 5: measured skin1, per mm, (red, green, blue); the thesis's
# Figure 3.6 plots the dipole with these values.
JENSEN_SKIN1: Mapping[str, Any] = MappingProxyType(
    {
        "sigma_s_prime": (0.74, 0.88, 1.01),
        "sigma_a": (0.032, 0.17, 0.48),
        "eta": 1.3,
        "source": "Jensen et al. 2001, skin1 (per mm, RGB)",
    }
)


# Five Gaussians fitted to the skin1 dipole above, shared variances and RGB weights, by
# experiments/fit_profiles.py (invsss.fit_sum_of_gaussians, r in [0, 8] mm, 121
# samples, r-weighted). Within 1.8 % of the dipole wherever it is above 1 % of its peak
# (tests/forward/test_profiles.py checks); the red total is 3 % low, the tail past 8 mm.
JENSEN_SKIN1_SOG = MappingProxyType(
    {
        "variances": (0.097571, 0.293648, 0.887742, 3.107986, 14.331783),
        "weights": (
            (0.0, 0.006022, 0.02921),
            (0.028093, 0.062157, 0.061987),
            (0.114227, 0.092254, 0.034522),
            (0.137687, 0.058494, 0.005349),
            (0.143826, 0.009137, 0.0),
        ),
        "source": "5-Gaussian fit of Jensen et al. 2001 skin1 dipole (experiments/fit_profiles.py)",
    }
)


# --------------------------------------------------------------------------- type


_PROFILE_KEYS = ("weights", "variances")
_OPTIONAL_KEYS = ("source", "fit")


def check_profile_arrays(
    weights, variances, name: str = "profile", *, zero_variances: bool = False, values: bool = True
) -> None:
    """Check sum-of-Gaussians weights and variances: shapes always, values when concrete.

    The one check behind :class:`SumOfGaussians` and :class:`~invsss.forward.params.SSSParams`.
    Weights are (K,) or (K, C) for K variances; weights >= 0 with a positive
    sum (per channel); variances > 0, or >= 0 with ``zero_variances`` (the
    screen-space model takes a zero-variance Gaussian as "no blur"). ``values=False``
    checks shapes only.

    Examples
    --------
    >>> check_profile_arrays([0.4, 0.6], [0.5, 2.0, 8.0], "params.json")
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: params.json: weights must have shape (3,) or (3, C) to match the 3 variances, got 2 weights of shape (2,)
    """  # noqa: E501
    w_shape, v_shape = tuple(np.shape(weights)), tuple(np.shape(variances))
    if len(v_shape) != 1 or v_shape[0] == 0:
        raise InvalidInputError(f"{name}: variances must be a non-empty list, got shape {v_shape}", field=name)
    if len(w_shape) not in (1, 2) or w_shape[0] != v_shape[0]:
        count = f"{w_shape[0]} weights of shape " if w_shape else ""
        raise InvalidInputError(
            f"{name}: weights must have shape ({v_shape[0]},) or ({v_shape[0]}, C) to "
            f"match the {v_shape[0]} variances, got {count}{w_shape}",
            field=name,
        )
    if not (values and is_concrete(weights) and is_concrete(variances)):
        return
    w, v = np.asarray(weights), np.asarray(variances)
    for key, x in (("weights", w), ("variances", v)):
        if not np.all(np.isfinite(x)):
            raise InvalidInputError(f"{name}: {key} contains NaN or infinite values", field=name)
    if zero_variances and np.any(v < 0):
        raise InvalidInputError(f"{name}: variances must be >= 0, min is {float(v.min()):g}", field=name)
    if not zero_variances and np.any(v <= 0):
        raise InvalidInputError(f"{name}: variances must be > 0, min is {float(v.min()):g}", field=name)
    if np.any(w < 0) or np.any(w.sum(axis=0) <= 0):
        raise InvalidInputError(f"{name}: weights must be >= 0 with a positive sum", field=name)


class SumOfGaussians(eqx.Module):
    """A sum-of-Gaussians diffusion profile ``R(r) = sum_i w_i G(v_i, r)`` as a pytree.

    Parameters
    ----------
    weights : array, shape (K,) or (K, C)
        Non-negative weights, one per Gaussian or one per Gaussian and channel. Their
        sum (per channel) is the profile's total diffuse reflectance.
    variances : array, shape (K,)
        Variances ``v_i > 0`` in mm^2.
    source : str
        Where the numbers come from (kept in the JSON file; static, not a leaf).

    Examples
    --------
    >>> import invsss
    >>> p = invsss.load_profile("deon-skin")
    >>> p.weights.shape, p(0.5).shape
    ((6, 3), (3,))
    >>> [round(x, 3) for x in p.total_reflectance().tolist()]
    [1.0, 1.0, 1.0]
    """

    weights: Float[Array, " K *C"] = eqx.field(converter=float_array)
    variances: Float[Array, " K"] = eqx.field(converter=float_array)
    source: str = eqx.field(static=True, default="")

    def __call__(self, r: Float[Array, "*N"]) -> Float[Array, "*N *C"]:
        """``R(r)``, mm^-2, for distances ``r`` in mm."""
        return sum_of_gaussians(r, self.weights, self.variances)

    @property
    def num_gaussians(self) -> int:
        return int(self.variances.shape[0])

    @property
    def num_channels(self) -> int | None:
        """C for per-channel weights, None for one weight per Gaussian."""
        return int(self.weights.shape[1]) if self.weights.ndim == 2 else None

    def total_reflectance(self) -> Float[Array, "*C"]:
        """Closed-form integral over the plane: the sum of the weights (per channel)."""
        return jnp.sum(self.weights, axis=0)

    def sorted(self) -> SumOfGaussians:
        """The same profile with the Gaussians in increasing variance."""
        order = jnp.argsort(self.variances)
        return SumOfGaussians(self.weights[order], self.variances[order], self.source)

    def to_dict(self) -> dict:
        """The JSON profile format: ``{"weights": [...], "variances": [...], "source": "..."}``."""
        return {
            "weights": np.asarray(self.weights).tolist(),
            "variances": np.asarray(self.variances).tolist(),
            "source": self.source,
        }

    @classmethod
    def from_dict(cls, d, source: str = "profile") -> SumOfGaussians:
        """Build from the JSON profile format, checking every value.

        ``source`` names the input in error messages (e.g. the file path). An optional
        ``"fit"`` entry (diagnostics written by the fitter) is accepted and ignored.
        """
        if not hasattr(d, "keys"):
            raise InvalidInputError(f"{source}: expected a mapping with weights and variances", field=source)
        missing = [k for k in _PROFILE_KEYS if k not in d]
        if missing:
            raise InvalidInputError(f"{source}: missing key(s) {', '.join(missing)}", field=source)
        unknown = sorted(set(d) - set(_PROFILE_KEYS) - set(_OPTIONAL_KEYS))
        if unknown:
            raise InvalidInputError(
                f"{source}: unknown key(s) {', '.join(map(str, unknown))}; expected "
                "weights, variances and optionally source",
                field=source,
            )
        weights = number_array(d["weights"], "weights", source)
        variances = number_array(d["variances"], "variances", source)
        label = d.get("source", "") or ""
        if not isinstance(label, str):
            raise InvalidInputError(f"{source}: source must be a string", field=source)
        profile = cls(weights, variances, label)  # type: ignore[arg-type]  # the fields' converters take array-likes
        profile.check(source)
        return profile

    def check(self, name: str = "profile") -> None:
        """Raise :class:`InvalidInputError` on bad shapes or values (concrete arrays only)."""
        check_profile_arrays(self.weights, self.variances, name)


#: One Gaussian of 1 mm^2: the profile whose one unknown, its scale (``sss_level`` in the
#: default gauge), a blur of a few pixels can determine. A richer shape needs a blur
#: that spans several pixels (issue 47: on a 0.3 px blur every weight of thesis-nir
#: was undetermined). The photo route's default (``invsss fit --distance``).
SINGLE_GAUSSIAN = MappingProxyType(
    {"variances": (1.0,), "weights": (1.0,), "source": "one Gaussian, its scale to be fitted"}
)

#: A sharp core (a tenth of the Gaussian's width: under a pixel wherever the Gaussian
#: spans a few) and one Gaussian, their weights and the scale to be fitted. The extra
#: blur between a visible and a 940 nm image of path-traced skin keeps about half its
#: contrast at every scale the pixels resolve, which one Gaussian cannot describe
#: (docs/capture.md, "What the two routes agree on"). Needs a blur of several pixels.
CORE_AND_GAUSSIAN = MappingProxyType(
    {"variances": (0.01, 1.0), "weights": (0.5, 0.5),
     "source": "a sharp core and one Gaussian, their weights and scale to be fitted"}
)

_NAMED_PROFILES = MappingProxyType(
    {"thesis-nir": THESIS_NIR_940, "deon-skin": DEON_SKIN_RGB, "jensen-skin1": JENSEN_SKIN1_SOG,
     "single": SINGLE_GAUSSIAN, "core-gaussian": CORE_AND_GAUSSIAN}
)
#: Names :func:`load_profile` knows (besides JSON file paths).
PROFILE_NAMES = tuple(_NAMED_PROFILES)


def load_profile(name_or_path) -> SumOfGaussians:
    """A named published profile or a JSON profile file as a :class:`SumOfGaussians`.

    Parameters
    ----------
    name_or_path : str or os.PathLike
        ``"thesis-nir"`` (thesis Table 5.1, weights (5,)), ``"deon-skin"`` (d'Eon &
        Luebke, weights (6, 3)), ``"jensen-skin1"`` (a 5-Gaussian fit of Jensen's skin1
        dipole, weights (5, 3)), ``"single"`` (one Gaussian of 1 mm^2), ``"core-gaussian"`` (a
        sharp core and a Gaussian, weights (2,)), or the path of a JSON file
        ``{"weights": [...], "variances": [...], "source": "..."}``.

    Raises
    ------
    InvalidInputError
        Unknown name, missing or unreadable file, invalid JSON or bad values.

    Examples
    --------
    >>> load_profile("thesis-nir").num_gaussians
    5
    """
    key = os.fspath(name_or_path) if isinstance(name_or_path, (str, os.PathLike)) else None
    if key is None:
        raise InvalidInputError(
            f"profile: expected a name or a JSON file path, got {type(name_or_path).__name__}",
            field="profile",
        )
    if isinstance(name_or_path, str) and key in _NAMED_PROFILES:
        table = _NAMED_PROFILES[key]
        return SumOfGaussians.from_dict(table, source=key)
    looks_like_path = (
        not isinstance(name_or_path, str) or key.lower().endswith(".json") or os.sep in key
    )
    if not looks_like_path and not os.path.exists(key):
        raise InvalidInputError(
            f"profile: unknown name {key!r}; expected one of {', '.join(PROFILE_NAMES)} "
            "or a JSON file path",
            field="profile",
        )
    if not os.path.isfile(key):
        raise InvalidInputError(f"{key}: profile file not found", field=key)
    try:
        with open(key, encoding="utf-8") as f:
            data = json.load(f)
    except json.JSONDecodeError as e:
        raise InvalidInputError(f"{key}: not valid JSON ({e.msg} at line {e.lineno})", field=key) from None
    except (OSError, UnicodeDecodeError) as e:
        raise InvalidInputError(f"{key}: cannot read profile file ({e.__class__.__name__})", field=key) from None
    return SumOfGaussians.from_dict(data, source=key)
