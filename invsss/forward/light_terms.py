"""Light-aware terms around the screen-space blur (docs/model.md, section 8).

The blur of sections 3-5 is radially symmetric: it spreads light equally in every
direction, and it keeps the source's Lambertian shading. Four effects of real
light transport do neither, and each is added here as a switch with fitted
parameters, using per-pixel buffers a deferred renderer already has. One acts on
the source before the blur:

``law`` (``w``, one per source channel in (0, 1), and a strength ``a``; needs the
key, normal and light buffers)
    A scattering medium does not reflect light from one direction as a Lambertian
    surface does. Chandrasekhar's law for a semi-infinite medium of
    single-scattering albedo ``w`` (isotropic scattering, Hapke's ``H``) gives the
    ratio to Lambert's

        f_w(mu, mu0) = H(mu) H(mu0) / (mu + mu0),   H(x) = (1 + 2x) / (1 + 2x sqrt(1 - w))

    with ``mu = n_z`` (the view cosine of a distant camera) and ``mu0 = n . l``.
    Its gain over Lambert, normalised to 1 for light arriving and leaving along
    the normal, is trusted only where the buffers resolve both angles
    (:data:`LAW_TRUST`): ``g = 1 + t (f_w(mu, mu0) / f_w(1, 1) - 1)`` with
    ``t = clip(min(mu, mu0) / LAW_TRUST, 0, 1)``, so that it is 1 (Lambert) where
    the normal faces away from the camera or the light and bounded everywhere.
    It is applied, with strength ``a``, to the key light's part ``K`` of the
    source (a renderer's lighting pass has it; ``invsss scene`` writes it as
    ``key.exr``):

        S' = S + m a K (g - 1)

    so the other lights keep their Lambertian shading. ``a = 0`` is the identity
    (the plain model), ``a = 1`` the law; no ``w`` alone is the identity, which
    is why the strength exists: a fit with the law contains the fit without it.

``fill`` (a strength ``b``; needs the law and the key, normal and fill_light buffers)
    The same law, with the same ``w``, for the other lights: their part ``S - K``
    of the source, with the direction ``l_f`` towards them (one direction stands
    for all of them; ``invsss scene`` writes the second light's as
    ``fill_light.exr``):

        S' = S + m a K (g(n, l) - 1) + m b (S - K) (g(n, l_f) - 1)

    ``b = 0`` (the default) is the identity: the law on the key light alone.

``transmission`` (a tint ``tau``, one or one per channel, and a ``thickness_scale`` ``k``,
1/mm; needs the thickness, key_irradiance, normal and light buffers)
    Light that crosses a thin part (an ear, a nostril's wing) from the key light
    behind it reaches points the key light does not light. The engines add it to
    the diffuse lighting before their blur, as HDRP does (its Lit shader's
    ``EvaluateTransmission`` and ``ComputeTransmittanceDisney``): the key light's
    irradiance times the albedo ``E`` (``key_irradiance``: the source lit by the key
    light alone, unshadowed, on a surface facing it), a wrapped cosine of the back
    side, and the transmittance of Burley's profile through the thickness ``t``
    (mm, the distance the key light travels inside the skin):

        S' = S + m tau T(k t) v(-n . l) E,
        T(x) = (exp(-x) + 3 exp(-x / 3)) / 4,
        v(x) = clip((x + W) / (1 + W)^2, 0, 1),   W = cos(75 deg)

    ``T`` is HDRP's ``ComputeTransmittanceDisney`` with ``S t = k t`` (its shape
    parameter ``S = 1 / d`` times the remapped thickness: ``k`` is the thickness
    remap's slope over the profile's ``d``) and its volume albedo, a quarter of the
    tint, written as ``tau / 4``; ``v`` is its wrapped lighting of the back side
    (``TRANSMISSION_WRAP_LIGHT``, 15 degrees of wrap). ``tau = 0`` is the identity.

The other three act on the blurred image:

``shift`` (``kappa``, scene units, needs the light buffer)
    Light that enters obliquely travels on along its direction before it
    scatters, so it leaves the skin displaced away from the light. The blurred
    image is read at ``x - delta(x)`` with

        delta = kappa * (s_x p_x, s_y p_y)

    where ``(s_x, s_y)`` are the stretch factors of section 2 (pixels per scene
    unit, the same ones that scale the blur) and ``p = (-l_x, l_y)`` are the image
    components of the propagation direction ``-l`` (``l`` the unit vector from the
    surface towards the light in camera space, x right, y up; image rows point
    down, hence the sign of the second component).
``grazing`` (``gamma``, dimensionless, needs the normal buffer)
    The exitant radiance of a scattering medium is not Lambertian; towards grazing
    view it is brighter (no boundary, or a thin one) or darker (Fresnel loss at a
    dielectric boundary). The shifted image is multiplied by
    ``1 + gamma * (1 - n_z)``, with ``n_z`` the camera-space normal's component
    towards the camera (the cosine of the view angle for a distant camera),
    clipped to ``[0, 1]``.
``incidence`` (``beta``, dimensionless, needs the normal and light buffers)
    Nor does a scattering medium reflect the same share of the light at every
    angle of incidence: light that enters obliquely scatters nearer the surface
    and more of it comes back out. The image is multiplied by
    ``1 + beta * (1 - clip(n . l, 0, 1))``: 1 where the key light meets the
    surface head-on, ``1 + beta`` where it grazes it or does not reach it (there
    only the other lights shine, whose balance with the key light the source's
    Lambertian shading also gets wrong).

The three after the blur are linear in the image, so a blurred image and its
layers can be passed through them alike; off the mask the image is returned
unchanged (``out = B + m (T(B) - B)``, as a pass blends).

Examples
--------
>>> import jax.numpy as jnp
>>> from invsss.forward.light_terms import shift_image
>>> image = jnp.arange(4.0).reshape(1, 4, 1)
>>> offset = jnp.zeros((1, 4, 2)).at[..., 0].set(0.5)   # half a pixel to the right
>>> shift_image(image, offset)[0, :, 0].tolist()
[0.0, 0.5, 1.5, 2.5]
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..validation import InvalidInputError, is_concrete
from .arrays import float_array
from .light_buffers import NEEDED_BUFFERS, LightBuffers
from .stretch import stretch_factors

__all__ = [
    "LIGHT_TERM_NAMES",
    "LIGHT_TERM_FIELDS",
    "LightTerms",
    "LightBuffers",
    "NEEDED_BUFFERS",
    "LAW_TRUST",
    "propagation_offsets",
    "grazing_field",
    "incidence_field",
    "chandrasekhar_h",
    "law_trust",
    "reflectance_law",
    "law_excess",
    "law_source",
    "lit_source",
    "shift_image",
    "light_transport",
    "apply_light_terms",
    "apply_law",
]

#: The terms, in the order of docs/model.md, section 8, with the buffers each needs.
LIGHT_TERM_NAMES = ("shift", "grazing", "incidence", "law", "fill", "transmission")
#: The fields of :class:`LightTerms` (a params file's ``light_terms`` keys that set them).
LIGHT_TERM_FIELDS = (*LIGHT_TERM_NAMES, "law_strength", "thickness_scale")
#: The terms applied to the blurred image (``law`` and ``fill`` change the source instead).
AFTER_BLUR = ("shift", "grazing", "incidence")

#: Below this cosine of the view or of the key light's incidence the law's gain
#: fades to Lambert's (docs/model.md, section 8). A pixel's key radiance is an
#: average over its footprint while its normal is taken at the centre; near
#: grazing the two disagree, and ``f_w`` divides by ``mu + mu0``, so an unfaded
#: gain ran to 232 on one silhouette pixel of a scene the terms were not built on.
#: With the fade the gain is below ``1 + 1 / LAW_TRUST`` = 11 for any ``w`` (the
#: bound is approached as ``w -> 0``, Lommel-Seeliger's law) and below 4 at ``w = 0.9``.
LAW_TRUST = 0.1



def _albedo_or_none(x):
    return None if x is None else float_array(x)


class LightTerms(eqx.Module):
    """The parameters of the light-aware terms (0, or None for ``law``, switches a term off).

    Parameters
    ----------
    shift : float
        ``kappa``: how far light travels on along its direction before it
        exits, in scene units (mm); 0 is the symmetric blur.
    grazing : float
        ``gamma``: relative brightening at grazing view (negative: darkening);
        must be > -1 so the gain stays positive.
    incidence : float
        ``beta``: relative brightening where the key light arrives at grazing
        incidence or not at all (negative: darkening); must be > -1.
    law : float or array of shape (C,), optional
        ``w``: the single-scattering albedo of the key light's reflectance law,
        in (0, 1), one for every channel or one per source channel; None (the
        default) leaves the source Lambertian.
    law_strength : float
        ``a``: how much of the key light follows the law (0: Lambert, the
        identity; 1, the default: the law). Values outside [0, 1] extrapolate
        the blend; a fit warns where that gives gains no medium gives
        (:func:`law_excess`).
    fill : float
        ``b``: how much of the other lights' part of the source follows the law
        with the same albedo (0, the default: they stay Lambertian, the identity;
        1: the law). Needs ``law``.
    transmission : float or array of shape (C,)
        ``tau``: the tint of the light transmitted from the key light through the
        thickness, one for every channel or one per source channel, >= 0 (0, the
        default, is the identity); HDRP's transmission tint.
    thickness_scale : float
        ``k`` (1/mm): the thickness buffer's millimetres in units of the
        transmittance's length, > 0 (1, the default); HDRP's thickness remap slope
        over its profile's ``d``.

    Examples
    --------
    >>> from invsss.forward.light_terms import LightTerms
    >>> LightTerms(shift=0.4).grazing.item()
    0.0
    >>> LightTerms(law=[0.93, 0.8, 0.7]).law.shape   # one albedo per channel
    (3,)
    >>> LightTerms(law=0.9, law_strength=0.0).used   # at strength 0 the law changes nothing
    ()
    >>> LightTerms(law=0.9, fill=1.0).used            # the law on every light
    ('law', 'fill')
    >>> LightTerms(transmission=[0.8, 0.3, 0.1]).used  # light through thin parts, red-tinted
    ('transmission',)
    """

    shift: Float[Array, ""] = eqx.field(converter=float_array, default=0.0)
    grazing: Float[Array, ""] = eqx.field(converter=float_array, default=0.0)
    incidence: Float[Array, ""] = eqx.field(converter=float_array, default=0.0)
    law: Float[Array, "*C"] | None = eqx.field(converter=_albedo_or_none, default=None)
    law_strength: Float[Array, ""] = eqx.field(converter=float_array, default=1.0)
    fill: Float[Array, ""] = eqx.field(converter=float_array, default=0.0)
    transmission: Float[Array, "*C"] = eqx.field(converter=float_array, default=0.0)
    thickness_scale: Float[Array, ""] = eqx.field(converter=float_array, default=1.0)

    @property
    def used(self) -> tuple[str, ...]:
        """The terms that change the image (a traced value counts as used)."""
        def nonzero(x):
            return not is_concrete(x) or float(x) != 0.0

        on = [t for t in AFTER_BLUR if nonzero(getattr(self, t))]
        if self.law is not None:
            on += [t for t, strength in (("law", self.law_strength), ("fill", self.fill)) if nonzero(strength)]
        tint = self.transmission
        if not is_concrete(tint) or np.any(np.asarray(tint) != 0.0):
            on.append("transmission")
        return tuple(on)

    def check(self, name: str = "light_terms") -> None:
        """Raise :class:`InvalidInputError` for values outside the model's domain."""
        for field in (*AFTER_BLUR, "law_strength", "fill"):
            value = getattr(self, field)
            if not is_concrete(value):
                continue
            if np.ndim(value) != 0 or not np.isfinite(float(value)):
                raise InvalidInputError(f"{name}.{field}: expected one finite number, got {np.asarray(value)!r}",
                                        field=f"{name}.{field}")
        for field in ("grazing", "incidence"):
            value = getattr(self, field)
            if is_concrete(value) and float(value) <= -1.0:
                raise InvalidInputError(f"{name}.{field}: expected a value > -1, got {float(value):g}",
                                        field=f"{name}.{field}")
        if self.law is not None and is_concrete(self.law):
            w = np.asarray(self.law, np.float64)
            if w.ndim > 1 or not np.all(np.isfinite(w)) or np.any(w <= 0.0) or np.any(w >= 1.0):
                raise InvalidInputError(
                    f"{name}.law: expected an albedo in (0, 1), or one per channel, got {w.tolist()!r}",
                    field=f"{name}.law",
                )
        if is_concrete(self.transmission):
            tau = np.asarray(self.transmission, np.float64)
            if tau.ndim > 1 or not np.all(np.isfinite(tau)) or np.any(tau < 0.0):
                raise InvalidInputError(
                    f"{name}.transmission: expected a tint >= 0, or one per channel, got {tau.tolist()!r}",
                    field=f"{name}.transmission",
                )
        if is_concrete(self.thickness_scale):
            k = np.asarray(self.thickness_scale, np.float64)
            if k.ndim != 0 or not np.isfinite(k) or k <= 0.0:
                raise InvalidInputError(
                    f"{name}.thickness_scale: expected one number > 0 (1/mm), got {k.tolist()!r}",
                    field=f"{name}.thickness_scale",
                )
        if self.law is None and (not is_concrete(self.fill) or float(self.fill) != 0.0):
            raise InvalidInputError(
                f"{name}.fill: the law on the other lights uses the law's albedo; give law too (an albedo in (0, 1))",
                field=f"{name}.fill",
            )

    def to_dict(self) -> dict:
        out = {field: float(getattr(self, field)) for field in AFTER_BLUR}
        if self.law is not None:
            w = np.asarray(self.law, np.float64)
            out["law"] = float(w) if w.ndim == 0 else w.tolist()
            out["law_strength"] = float(self.law_strength)
            if float(self.fill) != 0.0:
                out["fill"] = float(self.fill)
        tau = np.asarray(self.transmission, np.float64)
        if np.any(tau != 0.0):
            out["transmission"] = float(tau) if tau.ndim == 0 else tau.tolist()
            out["thickness_scale"] = float(self.thickness_scale)
        return out


def propagation_offsets(light: Float[Array, "H W 3"]) -> Float[Array, "H W 2"]:
    """``p = (-l_x, l_y)``: the propagation direction's image components (x right, rows down)."""
    return jnp.stack([-light[..., 0], light[..., 1]], axis=-1)


def grazing_field(normal: Float[Array, "H W 3"]) -> Float[Array, "H W"]:
    """``1 - clip(n_z, 0, 1)``: 0 facing the camera, 1 at a silhouette."""
    return 1.0 - jnp.clip(normal[..., 2], 0.0, 1.0)


def incidence_field(normal: Float[Array, "H W 3"], light: Float[Array, "H W 3"]) -> Float[Array, "H W"]:
    """``1 - clip(n . l, 0, 1)``: 0 where the key light meets the surface head-on, 1 where
    it grazes the surface or does not reach it."""
    return 1.0 - jnp.clip(jnp.sum(normal * light, axis=-1), 0.0, 1.0)


def chandrasekhar_h(x, albedo):
    """Hapke's approximation to Chandrasekhar's H function for isotropic scattering,
    ``(1 + 2x) / (1 + 2x sqrt(1 - w))`` (Hapke 1981; Chandrasekhar 1960, section 29)."""
    # The floor keeps the derivative finite where w rounds to 1.
    return (1.0 + 2.0 * x) / (1.0 + 2.0 * x * jnp.sqrt(jnp.maximum(1.0 - albedo, 1e-12)))


def law_trust(normal: Float[Array, "H W 3"], light: Float[Array, "H W 3"]) -> Float[Array, "H W"]:
    """``t = clip(min(n_z, n . l) / LAW_TRUST, 0, 1)``: 0 where the normal faces away
    from the camera or from the key light, 1 where the buffers resolve both angles."""
    return jnp.clip(jnp.minimum(normal[..., 2], jnp.sum(normal * light, axis=-1)) / LAW_TRUST, 0.0, 1.0)


def reflectance_law(
    normal: Float[Array, "H W 3"], light: Float[Array, "H W 3"], albedo: Float[Array, "*C"]
) -> Float[Array, "H W C"]:
    """``g = 1 + t (f_w(mu, mu0) / f_w(1, 1) - 1)``: the law's gain over a Lambertian
    reflection, faded to 1 (:func:`law_trust`) where the buffers cannot resolve it.

    ``mu = clip(n_z, 0, 1)`` and ``mu0 = clip(n . l, 0, 1)``; ``albedo`` is one
    ``w`` or one per channel (the last axis of the result; 1 for one ``w``).
    Bounded: below ``1 + 1 / LAW_TRUST`` for any ``w`` (where ``t < 1``,
    ``t (f_w / f_w(1, 1))`` is at most ``(x / LAW_TRUST) (1 / x)``); at least
    about 0.73 (``w -> 1``, light arriving along the normal seen at grazing).
    """
    w = jnp.atleast_1d(albedo)
    mu = jnp.clip(normal[..., 2], 0.0, 1.0)[..., None]
    mu0 = jnp.clip(jnp.sum(normal * light, axis=-1), 0.0, 1.0)[..., None]
    trust = law_trust(normal, light)[..., None]
    head_on = chandrasekhar_h(1.0, w) ** 2 / 2.0
    # Where t = 0 both cosines may be 0: the floor keeps the (unused) ratio finite,
    # and its derivative too.
    ratio = chandrasekhar_h(mu, w) * chandrasekhar_h(mu0, w) / jnp.maximum(mu + mu0, 1e-6) / head_on
    return 1.0 + trust * (ratio - 1.0)


def law_excess(
    normal: Float[Array, "H W 3"], light: Float[Array, "H W 3"], albedo: Float[Array, "*C"], strength
) -> Float[Array, "H W C"]:
    """How far the blended gain ``1 + a (g_w - 1)`` lies outside every gain that a
    medium could give: those between Lambert's (1) and the law's at any albedo in [0, 1].

    At fixed cosines the law's gain :func:`reflectance_law` is monotone in ``w``
    (each ``H(x) / H(1)`` runs from 1 at ``w = 0`` to ``(1 + 2x) / 3`` at ``w = 1``),
    so the albedos 0 and 1 bound it, and with Lambert's 1 they bound every blend
    with ``a`` in [0, 1]. A strength outside [0, 1] is physical where its blend
    still lies among them (another albedo gives that gain there) and not where it
    leaves them. 0 inside, the distance outside; same axes as :func:`reflectance_law`.
    """
    w = jnp.atleast_1d(albedo)
    blend = 1.0 + strength * (reflectance_law(normal, light, w) - 1.0)
    single = reflectance_law(normal, light, jnp.zeros_like(w))
    conservative = reflectance_law(normal, light, jnp.ones_like(w))
    low = jnp.minimum(jnp.minimum(single, conservative), 1.0)
    high = jnp.maximum(jnp.maximum(single, conservative), 1.0)
    return jnp.maximum(jnp.maximum(low - blend, blend - high), 0.0)


def law_source(
    source: Float[Array, "H W C"], key: Float[Array, "H W C"], mask: Float[Array, "H W"],
    gain: Float[Array, "H W C"], strength=1.0,
) -> Float[Array, "H W C"]:
    """``S + m a K (gain - 1)``: the part ``K`` of the source lit by one light (the
    key's, or ``S - K`` for the other lights) under the law's ``gain``
    (:func:`reflectance_law`) with strength ``a``, the rest of the source as it is."""
    return source + strength * mask[..., None] * key * (gain - 1.0)


def lit_source(source, key, mask, normal, light, albedo, strength, fill_light=None, fill=None):
    """``S + m a K (g(n, l) - 1)``, plus ``m b (S - K) (g(n, l_f) - 1)`` when ``fill_light``
    and ``fill`` (``b``) are given: the source the blur spreads under the ``law`` and
    ``fill`` terms. The traced core that :func:`apply_law` and the estimator share."""
    lit = law_source(source, key, mask, reflectance_law(normal, light, albedo), strength)
    if fill_light is None or fill is None:
        return lit
    return law_source(lit, source - key, mask, reflectance_law(normal, fill_light, albedo), fill)


def shift_image(image: Float[Array, "H W C"], offset: Float[Array, "H W 2"]) -> Float[Array, "H W C"]:
    """``image`` read at ``(x - dx, y - dy)`` per pixel: bilinear, clamped to the edge.

    ``offset[..., 0]`` is ``dx`` (columns), ``offset[..., 1]`` is ``dy`` (rows), in
    pixels; a positive offset moves the content right or down. Pixel centres are
    at integer coordinates, as in :func:`invsss.sample_along`.
    """
    h, w, c = image.shape
    dtype = image.dtype
    cols = jnp.clip(jnp.arange(w, dtype=dtype)[None, :] - offset[..., 0], 0.0, w - 1.0)
    rows = jnp.clip(jnp.arange(h, dtype=dtype)[:, None] - offset[..., 1], 0.0, h - 1.0)
    # The lower neighbour stops one short of the edge so that the upper one
    # exists; at the edge the fraction is then 1.
    c0 = jnp.clip(jnp.floor(cols).astype(jnp.int32), 0, max(w - 2, 0))
    r0 = jnp.clip(jnp.floor(rows).astype(jnp.int32), 0, max(h - 2, 0))
    fc = (cols - c0)[..., None]
    fr = (rows - r0)[..., None]
    c1 = jnp.minimum(c0 + 1, w - 1)
    r1 = jnp.minimum(r0 + 1, h - 1)
    flat = image.reshape(h * w, c)

    def at(r, col):
        return flat.at[r * w + col].get(mode="promise_in_bounds")

    top = at(r0, c0) + fc * (at(r0, c1) - at(r0, c0))
    bottom = at(r1, c0) + fc * (at(r1, c1) - at(r1, c0))
    return top + fr * (bottom - top)


#: :func:`shift_image` as a jitted function: a fit traces the terms once per blurred
#: layer and per Jacobian, and a jitted call with the same shapes is traced once
#: (as the passes' tap sum, :mod:`invsss.forward.passes`).
_shift_image_traced_once = jax.jit(shift_image)


def light_transport(
    blurred: Float[Array, "H W C"],
    mask: Float[Array, "H W"],
    stretch: tuple[Float[Array, "H W"], Float[Array, "H W"]],
    terms: LightTerms,
    offsets: Float[Array, "H W 2"] | None = None,
    grazing: Float[Array, "H W"] | None = None,
    incidence: Float[Array, "H W"] | None = None,
) -> Float[Array, "H W C"]:
    """The terms of section 8 on a blurred image, from precomputed fields.

    ``offsets`` is :func:`propagation_offsets` of the light buffer, ``grazing``
    is :func:`grazing_field` of the normals and ``incidence`` is
    :func:`incidence_field` of both; a term whose field is None is off.
    This is the traced core the estimator calls once per basis image.
    """
    out = blurred
    if offsets is not None:
        s_x, s_y = stretch
        delta = terms.shift * jnp.stack([s_x * offsets[..., 0], s_y * offsets[..., 1]], axis=-1)
        out = _shift_image_traced_once(out, delta)
    if grazing is not None:
        out = out * (1.0 + terms.grazing * grazing)[..., None]
    if incidence is not None:
        out = out * (1.0 + terms.incidence * incidence)[..., None]
    return blurred + mask[..., None] * (out - blurred)


def apply_light_terms(blurred, depth, mask, params, terms: LightTerms, buffers: LightBuffers):
    """Apply the light-aware terms after the blur to an image :func:`invsss.render` produced.

    Parameters
    ----------
    blurred : array, shape (H, W, C)
        The screen-space model's output.
    depth, mask : arrays, shape (H, W)
        As given to :func:`invsss.render` (depth already valid everywhere).
    params : SSSParams
        Its stretch parameters set the shift's scale (section 2).
    terms : LightTerms
    buffers : LightBuffers
        A term is applied when its buffers are present.

    Returns
    -------
    array, shape (H, W, C)
    """
    stretch = stretch_factors(depth, params.sss_level, params.correction, params.maxdd)
    offsets = None if buffers.light is None else propagation_offsets(jnp.asarray(buffers.light, blurred.dtype))
    normal = None if buffers.normal is None else jnp.asarray(buffers.normal, blurred.dtype)
    light = None if buffers.light is None else jnp.asarray(buffers.light, blurred.dtype)
    grazing = None if normal is None else grazing_field(normal)
    incidence = None if normal is None or light is None else incidence_field(normal, light)
    return light_transport(blurred, mask, stretch, terms, offsets, grazing, incidence)


def apply_law(image, mask, albedo, buffers: LightBuffers, strength=1.0, fill=0.0):
    """Apply the ``law`` (and ``fill``) term to a source image before :func:`invsss.render` blurs it.

    Parameters
    ----------
    image : array, shape (H, W, C)
        The source (all lights, Lambertian).
    mask : array, shape (H, W)
    albedo : float or array of shape (C,)
        ``w`` in (0, 1), one or one per channel.
    buffers : LightBuffers
        With ``key`` (shape (H, W, C)), ``normal`` and ``light``; and
        ``fill_light`` when ``fill`` is not 0.
    strength : float
        ``a``: 0 leaves the key light's part as it is, 1 (the default) applies the law.
    fill : float
        ``b``: the same for the other lights' part ``S - K`` (0, the default: Lambert).

    Returns
    -------
    array, shape (H, W, C)
        ``S + m a K (g(n, l) - 1) + m b (S - K) (g(n, l_f) - 1)``, ``g`` from
        :func:`reflectance_law`.

    Examples
    --------
    >>> import numpy as np
    >>> from invsss.forward.light_terms import LightBuffers, apply_law
    >>> facing = np.zeros((1, 2, 3)); facing[..., 2] = 1.0   # normal and light towards the camera
    >>> source = np.full((1, 2, 1), 0.5); key = np.full((1, 2, 1), 0.3)
    >>> apply_law(source, np.ones((1, 2)), 0.9, LightBuffers(facing, facing, key))[..., 0].tolist()
    [[0.5, 0.5]]
    """
    image = jnp.asarray(image)
    dtype = image.dtype
    skip_fill = buffers.fill_light is None or (is_concrete(fill) and float(fill) == 0.0)
    return lit_source(image, jnp.asarray(buffers.key, dtype), jnp.asarray(mask, dtype),
                      jnp.asarray(buffers.normal, dtype), jnp.asarray(buffers.light, dtype),
                      jnp.asarray(albedo, dtype), jnp.asarray(strength, dtype),
                      None if skip_fill else jnp.asarray(buffers.fill_light, dtype),
                      None if skip_fill else jnp.asarray(fill, dtype))
