"""Which parameters are solved, fixed or eliminated, and the unconstrained unknowns.

Every parameter of the model (docs/model.md, section 6) gets one *role*:

``"free"``
    solved by the nonlinear solver through an unconstrained unknown ``z`` of
    order one (constraints by reparametrisation, below);
``"linear"``
    eliminated by linear least squares inside the residual (the ``sog`` weights,
    see :mod:`invsss.estimator.projection`);
``"fixed"``
    given by the user (``fix=``) or by the gauge;
``"unused"``
    the chosen model ignores it (the ``thesis`` chain has no weights, the
    ``separable`` model no correction term), so the data cannot determine it.

Reparametrisation (each unknown is 0 at its reference value ``ref``):

=============  ====================================  ===============================
parameter      natural value                         reference ``ref``
=============  ====================================  ===============================
sss_level      ``ref * exp(z)``                      blurs the widest Gaussian by
                                                     ~2 px at the median depth
correction     ``ref * softplus(z)``                 ``c * slope_ref = d_ref``: the
                                                     correction halves the stretch
                                                     at a typical slope
maxdd          ``ref * exp(z)``                      median masked depth slope
variances      ``ref_i * exp(z_i)``                  the profile's variances
weights        ``softmax([0, z])`` per channel       (``separable`` only)
mix            ``softmax([0, z_1, z_2])``            equal mix
gain_ratio     ``exp(z)``                            1 (pair p's gain / pair 0's)
vignetting     ``z``                                 0 (no fall-off; see
                                                     :mod:`invsss.estimator.vignetting`)
light_shift    ``ref * z``                           the scene length one pixel
                                                     covers at the start (docs/model.md,
                                                     section 8)
grazing        ``z``                                 0 (no grazing-view gain)
incidence      ``z``                                 0 (no incidence gain)
law            ``sigmoid(ref + z)``, one per source   ``logit(0.9)``: an albedo
               channel                               between the 940 nm and the
                                                     visible skins of docs/model.md,
                                                     section 8
law_strength   ``z``                                 0 (Lambert: the plain model)
fill_strength  ``z``                                 0 (the other lights Lambertian)
transmission   ``ref * z^2``, one per source channel  1; ``z = 0`` adds no light (a tint
                                                     is >= 0: light crossing skin adds)
thickness_     ``ref * exp(z)``                      one over the median thickness
scale                                                behind the key light's terminator
=============  ====================================  ===============================

``softplus`` keeps the correction non-negative while letting it approach 0
smoothly (its floor is 0, reached only in the limit ``z -> -inf``); the logs make
multiplicative uncertainty additive, which is what the solver's steps and the
Gauss-Newton covariance assume. Each ``exp`` holds ``z`` within ``+-LOG_LIMIT``: an
unknown the data bound on one side only may otherwise walk off to infinity.

The gauge (docs/model.md, section 6): scaling every variance by ``a^2`` and ``L`` by
``1 / a`` gives the same image, so one of them must be fixed: ``gauge="variances"``
takes the variances from a profile, ``gauge="sss_level"`` takes ``L`` from ``fix``.
A model whose image also sees the variances in scene units (``burley``: its
samples are weighted by the 3D distance, the depth difference in mm) has no such
degeneracy; ``gauge="depth"`` estimates both, and is that model's default.
"""

from __future__ import annotations

import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..forward.models import get_model
from ..forward.params import PARAM_NAMES
from ..forward.profiles import SumOfGaussians, load_profile
from ..validation import InvalidInputError

__all__ = [
    "PARAM_NAMES",
    "GAUGES",
    "LIGHT_UNKNOWNS",
    "by_unknown",
    "resolve_profile",
    "softplus_inverse",
    "logit",
    "check_fix",
    "assign_roles",
    "Parametrisation",
]

GAUGES = ("variances", "sss_level", "depth")

#: The estimator's unknown for each light-aware term (docs/model.md, section 8);
#: ``shift`` is ``light_shift`` here so that it is not read as a warp's shift. The
#: law has two: its albedo and its strength (0 is the identity, so that a fit with
#: the law contains the fit without it); ``fill``, the law on the other lights, has
#: a strength of its own and shares the albedo.
LIGHT_UNKNOWNS = {"shift": "light_shift", "grazing": "grazing", "incidence": "incidence", "law": "law",
                  "law_strength": "law_strength", "fill": "fill_strength", "transmission": "transmission",
                  "thickness_scale": "thickness_scale"}



def by_unknown(entries: dict) -> dict:
    """``{term: x}`` of the light terms (a fit's ``light_terms`` record, or its
    ``stderr``) keyed by the names of their unknowns; other keys are dropped.

    Examples
    --------
    >>> by_unknown({"shift": 1.2, "grazing": 0.3, "stderr": {}, "fixed": []})
    {'light_shift': 1.2, 'grazing': 0.3}
    """
    return {LIGHT_UNKNOWNS[term]: value for term, value in entries.items() if term in LIGHT_UNKNOWNS}


#: Blocks that are ``ref * z`` with 0 a value like any other (no fall-off, no
#: shift, no gain): the vignetting coefficients and the light terms but the law
#: (an albedo in (0, 1), a logit block).
SCALED_BLOCKS = ("vignetting", "pigment",
                 *(name for term, name in LIGHT_UNKNOWNS.items()
                   if term not in ("law", "thickness_scale", "transmission")))
#: Blocks that are ``ref * exp(z)``: positive, their uncertainty relative.
LOG_BLOCKS = ("sss_level", "maxdd", "variances", "thickness_scale")
#: How far a ``ref * exp(z)`` unknown may go from its reference: ``|z|`` beyond this
#: (a factor of 1e26) maps to the value at the limit. Such a value is only bounded
#: by the data, not measured (maxdd where no depth slope reaches it, once the
#: correction has gone to 0, walks off without changing the loss: 5.9e44 on
#: pt_proc_ear_glow_940's plain fit), and ``exp`` overflows near 710, and float32,
#: which the fit's result is returned in, near 88. An unknown at the limit stays
#: there (its column of the Jacobian is 0) and is reported as undetermined.
LOG_LIMIT = 60.0
_SCALARS = ("sss_level", "correction", "maxdd")


def resolve_profile(profile) -> tuple[np.ndarray, np.ndarray]:
    """``(weights, variances)`` from a profile name, JSON path, mapping or SumOfGaussians."""
    if isinstance(profile, (str, os.PathLike)):
        profile = load_profile(profile)
    elif hasattr(profile, "keys"):
        profile = SumOfGaussians.from_dict(profile, source="profile")
    elif not isinstance(profile, SumOfGaussians):
        raise InvalidInputError(
            "profile: expected a profile name, a JSON path, a mapping with weights and "
            f"variances, or an invsss SumOfGaussians, got {type(profile).__name__}",
            field="profile",
        )
    profile.check("profile")
    return np.asarray(profile.weights, np.float64), np.asarray(profile.variances, np.float64)


def check_fix(fix) -> dict[str, np.ndarray]:
    """Validate ``fix=`` (names and values) and return float64 arrays."""
    if fix is None:
        return {}
    if not hasattr(fix, "items"):
        raise InvalidInputError(f"fix: expected a mapping of parameter names to values, got {type(fix).__name__}",
                                field="fix")
    unknown = sorted(set(fix) - set(PARAM_NAMES))
    if unknown:
        raise InvalidInputError(
            f"fix: unknown parameter(s) {', '.join(map(repr, unknown))}; expected some of "
            + ", ".join(PARAM_NAMES)
        )
    out = {}
    for k, v in fix.items():
        if np.asarray(v).dtype.kind in "US":  # NumPy would read "0.5" as 0.5
            raise InvalidInputError(f"fix[{k!r}]: expected numbers, got the text {v!r}", field="fix")
        try:
            a = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError):
            raise InvalidInputError(f"fix[{k!r}]: expected numbers, got {v!r}", field="fix") from None
        if not np.all(np.isfinite(a)):
            raise InvalidInputError(f"fix[{k!r}]: contains NaN or infinite values", field="fix")
        if k in _SCALARS and a.ndim != 0:
            raise InvalidInputError(f"fix[{k!r}]: expected a single number, got shape {a.shape}", field="fix")
        if k in ("sss_level", "maxdd") and a <= 0:
            raise InvalidInputError(f"fix[{k!r}]: expected a value > 0, got {float(a):g}", field="fix")
        if k == "correction" and a < 0:
            raise InvalidInputError(f"fix['correction']: expected a value >= 0, got {float(a):g}", field="fix")
        if k == "variances" and (a.ndim != 1 or a.size == 0 or np.any(a <= 0)):
            raise InvalidInputError("fix['variances']: expected a non-empty list of values > 0", field="fix")
        if k == "weights" and (a.ndim not in (1, 2) or np.any(a < 0) or np.any(a.sum(axis=0) <= 0)):
            raise InvalidInputError("fix['weights']: expected a (K,) or (K, C) array >= 0 with a positive sum",
                                    field="fix")
        out[k] = a
    if "weights" in out and "variances" in out and out["weights"].shape[0] != out["variances"].shape[0]:
        raise InvalidInputError(
            f"fix['weights']: expected {out['variances'].shape[0]} rows, one per fixed variance, "
            f"got shape {out['weights'].shape}",
            field="fix",
        )
    return out


def assign_roles(model: str, gauge: str, fixed: dict) -> dict[str, str]:
    """The role ("free", "linear", "fixed", "unused") of each parameter."""
    if gauge not in GAUGES:
        raise InvalidInputError(f"gauge: expected one of {', '.join(GAUGES)}, got {gauge!r}", field="gauge")
    if gauge == "sss_level" and "sss_level" not in fixed:
        raise InvalidInputError(
            "gauge: 'sss_level' needs the value of sss_level in fix= (e.g. the focal length in pixels)",
            field="gauge",
        )
    entry = get_model(model)
    if gauge == "depth" and entry.default_gauge != "depth":
        raise InvalidInputError(
            f"gauge: 'depth' estimates sss_level and the variances together, which model {model} cannot tell "
            "apart (scaling one scales the other away); use variances or sss_level",
            field="gauge",
        )
    roles = {}
    roles["sss_level"] = "fixed" if "sss_level" in fixed else "free"
    roles["variances"] = "fixed" if ("variances" in fixed or gauge == "variances") else "free"
    for k in ("correction", "maxdd"):
        roles[k] = "fixed" if k in fixed else ("free" if k in entry.parameters else "unused")
    roles["weights"] = "fixed" if "weights" in fixed else entry.weights_role
    return roles


def _softplus(z, xp=jnp):
    return xp.logaddexp(z, 0.0)


def softplus_inverse(x):
    """``z`` with ``softplus(z) = x`` for ``x > 0`` (numerically stable for small x)."""
    x = np.asarray(x, np.float64)
    return x + np.log(-np.expm1(-x))


def _sigmoid(z, xp=jnp):
    return jax.nn.sigmoid(z) if xp is jnp else 1.0 / (1.0 + np.exp(-z))


def logit(x):
    """``log(x / (1 - x))``, the inverse of the sigmoid, for ``x`` in (0, 1)."""
    x = np.asarray(x, np.float64)
    return np.log(x) - np.log1p(-x)


def _simplex(z, axis=0, xp=jnp):
    """``softmax`` of ``[0, z]`` along ``axis``: a point of the simplex, no redundancy."""
    pad = [(0, 0)] * z.ndim
    pad[axis] = (1, 0)
    if xp is jnp:
        return jax.nn.softmax(jnp.pad(z, pad), axis=axis)
    e = np.exp(np.pad(z, pad) - np.max(z, axis=axis, keepdims=True).clip(0.0, None))
    return e / e.sum(axis=axis, keepdims=True)


class Parametrisation(eqx.Module):
    """Maps the unknown vector ``z`` to natural parameter values and back.

    Attributes
    ----------
    blocks : tuple of (name, shape), static
        The free blocks in the order they occupy ``z``.
    reference : dict[str, array]
        The reference scale of each free block (``ref`` above).
    values : dict[str, array]
        The value of every non-free parameter (fixed, or carried for unused ones).
    """

    blocks: tuple = eqx.field(static=True)
    reference: dict
    values: dict

    @property
    def size(self) -> int:
        return sum(int(np.prod(shape)) for _, shape in self.blocks)

    @property
    def free(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.blocks)

    def layout(self) -> dict[str, tuple[int, int]]:
        """Where each free block lies in ``z``: ``{name: (first, stop)}``."""
        out, i = {}, 0
        for name, shape in self.blocks:
            n = int(np.prod(shape))
            out[name] = (i, i + n)
            i += n
        return out

    def split(self, z: Float[Array, " n"]) -> dict[str, Array]:
        """The free blocks of ``z`` by name, reshaped."""
        shapes = dict(self.blocks)
        return {name: z[first:stop].reshape(shapes[name]) for name, (first, stop) in self.layout().items()}

    def natural(self, z: Float[Array, " n"]) -> dict[str, Array]:
        """Every parameter's natural value (free ones from ``z``, the rest as given).

        A NumPy ``z`` (the host's reading of a result) is mapped with NumPy, so that
        it costs no compilation of JAX's eager operations; anything else with JAX.
        """
        xp = np if isinstance(z, np.ndarray) else jnp
        out = dict(self.values)
        for name, u in self.split(z).items():
            ref = self.reference[name] if xp is jnp else np.asarray(self.reference[name])
            if name in LOG_BLOCKS:
                out[name] = ref * xp.exp(xp.clip(u, -LOG_LIMIT, LOG_LIMIT))
            elif name == "correction":
                out[name] = ref * _softplus(u, xp)
            elif name in ("weights", "mix"):
                out[name] = _simplex(u, 0, xp)
            elif name == "gain_ratio":
                out[name] = xp.exp(xp.clip(u, -LOG_LIMIT, LOG_LIMIT))
            elif name in SCALED_BLOCKS:
                out[name] = ref * u
            elif name == "law":
                out[name] = _sigmoid(ref + u, xp)
            elif name == "transmission":
                out[name] = ref * u * u
            else:  # pragma: no cover - blocks are built by this module
                raise AssertionError(name)
        return out

    def unknowns(self, natural: dict) -> Float[Array, " n"]:
        """The inverse of :meth:`natural` for the free blocks (values must be in range)."""
        parts = []
        for name, shape in self.blocks:
            x = np.asarray(natural[name], np.float64)
            ref = np.asarray(self.reference[name], np.float64)
            if name in LOG_BLOCKS:
                u = np.clip(np.log(x / ref), -LOG_LIMIT, LOG_LIMIT)
            elif name == "correction":
                u = softplus_inverse(np.maximum(x / ref, 1e-12))
            elif name in ("weights", "mix"):
                logs = np.log(np.maximum(x, 1e-12))
                u = (logs - logs[:1])[1:]
            elif name in SCALED_BLOCKS:
                u = x / ref
            elif name == "law":
                u = logit(np.clip(x, 1e-12, 1.0 - 1e-12)) - ref
            elif name == "transmission":
                u = np.sqrt(np.maximum(x, 0.0) / ref)
            else:  # gain_ratio
                u = np.clip(np.log(x), -LOG_LIMIT, LOG_LIMIT)
            parts.append(np.broadcast_to(u, shape).ravel())
        # device_put, not jnp.asarray: that compiles a small copy for every new shape.
        return jax.device_put(np.concatenate(parts) if parts else np.zeros(0))
