"""The residual the nonlinear solver sees, as one jit-friendly pytree.

:class:`Objective` bundles the data, the parametrisation and the per-pixel weights;
``objective(z, args)`` returns the weighted residual with the linear unknowns
projected out, in the ``(residual, aux)`` form optimistix solvers call. All of
its numbers are arrays, so a new start, new robust weights or a new active set
reuse the compiled solver step; only the static layout (model, free blocks,
image sizes) triggers a compile.

Residual of pixel ``n``, channel ``j`` of pair ``p`` (``m`` the mask times the
pair's ``fit_weight``, ``u`` the robust weight, ``s`` the target's masked
standard deviation):

    rho = sqrt(m u) (T - pred) / s

so that the loss the estimator reports, ``s^2 sum rho^2 / sum m`` per channel, is
the (robustly weighted) mean squared error on the mask in the target's units.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..forward.light_terms import (
    AFTER_BLUR,
    LightTerms,
    grazing_field,
    incidence_field,
    light_transport,
    lit_source,
    propagation_offsets,
)
from ..forward.models import get_model
from ..forward.stretch import stretch_factors
from ..forward.transmission import transmitted_source, wrapped_back_lighting
from .basis import basis_images
from .parametrisation import LIGHT_UNKNOWNS, Parametrisation
from .pigment import pigment_field
from .projection import combine, projected_jacobian, solve_linear
from .vignetting import vignetting_field

__all__ = ["Objective"]

#: The unknowns of the terms applied to the blurred images (``law`` changes the source).
_AFTER_BLUR = tuple(LIGHT_UNKNOWNS[term] for term in AFTER_BLUR)
#: The unknowns of the terms that change the source before the blur: a move in one
#: of them moves the image the passes blur, not the passes.
_LIGHTING = (LIGHT_UNKNOWNS["law"], LIGHT_UNKNOWNS["law_strength"], LIGHT_UNKNOWNS["fill"],
             LIGHT_UNKNOWNS["transmission"], LIGHT_UNKNOWNS["thickness_scale"])
#: The layouts whose passes treat every channel of the image alike (one set of
#: variances and taps for all): the burley disk has a variance per channel, and a
#: layered render with fixed weights may have a weight per channel.
_SAME_PASSES_PER_CHANNEL = ("chained",)
#: The unknowns the blurred basis images depend on (the grey mix apart: the blur is
#: linear in the image); the others act after the blur.
_BLURRED_BY = ("sss_level", "correction", "maxdd", "variances", "weights", *_LIGHTING)


def _mixed(images: Float[Array, "nb H W C"], mix: Float[Array, " C"]) -> Float[Array, "nb H W 1"]:
    """Blurred source channels mixed to the grey image the model fits (the passes
    are linear in the image: blurring the mix is mixing the blurs)."""
    return jnp.einsum("ihwc,c->ihw", images, mix)[..., None]


def _lit_source(pair, natural):
    """The pair with the terms that change the source applied to it (docs/model.md,
    section 8): the ``law`` (and ``fill``, when its strength is among the natural
    values) when ``w`` is among them, then the ``transmission`` when its tint is. The
    blur of the changed source is the model's, and the difference Jacobian sees their
    unknowns as it sees any blur parameter."""
    if "law" not in natural and "transmission" not in natural:
        return pair
    lit = pair.source
    if "law" in natural:
        fill = natural.get("fill_strength")
        lit = lit_source(lit, pair.key, pair.mask, pair.normal, pair.light, natural["law"],
                         natural["law_strength"], None if fill is None else pair.fill_light, fill)
    if "transmission" in natural:
        lit = transmitted_source(lit, pair.mask, natural["transmission"], natural["thickness_scale"], pair.thickness,
                                 pair.key_irradiance, wrapped_back_lighting(pair.normal, pair.light))
    return eqx.tree_at(lambda p: p.source, pair, lit)


def _light_terms(images, pair, natural):
    """The light-aware terms after the blur (docs/model.md, section 8) on every basis image of a pair.

    Both terms are linear in the image, so applying them to each basis image
    and then mixing equals mixing and then applying them: the weights stay linear.
    """
    terms = LightTerms(natural.get("light_shift", 0.0), natural.get("grazing", 0.0), natural.get("incidence", 0.0))
    stretch = stretch_factors(pair.depth, natural["sss_level"], natural["correction"], natural["maxdd"])
    offsets = propagation_offsets(pair.light) if "light_shift" in natural else None
    grazing = grazing_field(pair.normal) if "grazing" in natural else None
    incidence = incidence_field(pair.normal, pair.light) if "incidence" in natural else None
    return jax.vmap(lambda x: light_transport(x, pair.mask, stretch, terms, offsets, grazing, incidence))(images)


class Objective(eqx.Module):
    """Weighted, projected residual of a fit.

    Attributes
    ----------
    param : Parametrisation
    pairs : tuple of ImagePair
    tap_weights : array, shape (7,)
    robust : tuple of arrays, shape (H_p, W_p, C')
        Robust weights per pixel and channel (1 for plain least squares).
    active : array, shape (nb, C')
        Basis images in use (see :func:`~invsss.estimator.projection.solve_linear`).
    scale : array, shape ()
        Residual unit (the target's masked standard deviation).
    model : str, static
    linear_weights : bool, static
        Whether the ``sog`` weights are eliminated (basis = layers).
    """

    param: Parametrisation
    pairs: tuple
    tap_weights: Array
    robust: tuple
    active: Array
    scale: Array
    model: str = eqx.field(static=True)
    linear_weights: bool = eqx.field(static=True)

    @property
    def num_basis(self) -> int:
        return int(self.active.shape[0])

    def ratios(self, natural: dict) -> Float[Array, "P C"]:
        c = self.pairs[0].target.shape[-1]
        one = jnp.ones((1, c), self.scale.dtype)
        if "gain_ratio" in natural:
            return jnp.concatenate([one, natural["gain_ratio"]], axis=0)
        return one

    def weights(self) -> tuple:
        return tuple(p.residual_weight[..., None] * u for p, u in zip(self.pairs, self.robust))

    def blurred_bases(self, natural: dict) -> tuple:
        """The model's basis images of every pair (:func:`.basis.basis_images`): the blur."""
        return tuple(
            basis_images(_lit_source(p, natural), natural, self.model, self.tap_weights, self.linear_weights)
            for p in self.pairs
        )

    def bases(self, natural: dict, blurred: tuple | None = None) -> tuple:
        """The basis images the projection mixes: the blurred ones (made here unless
        given), through the light-aware terms after the blur and the vignetting when
        fitted."""
        images = self.blurred_bases(natural) if blurred is None else blurred
        if any(name in natural for name in _AFTER_BLUR):
            images = tuple(_light_terms(x, p, natural) for x, p in zip(images, self.pairs))
        if "vignetting" in natural:
            # The lens shades whatever the scattering delivers; the offset stays flat.
            images = tuple(
                x * vignetting_field(natural["vignetting"], x.shape[1:3])[None, :, :, None] for x in images
            )
        if "pigment" in natural:
            # Each pair's own pigment field, per target channel; the offset stays flat.
            images = tuple(x * pigment_field(a, x.shape[1:3])[None] for x, a in zip(images, natural["pigment"]))
        return images

    def linear(self, z, blurred: tuple | None = None) -> tuple[dict, tuple, Array, Array, Array]:
        """``(natural, bases, ratios, coef, offset)`` at ``z`` (from the given
        blurred basis images instead of blurring, if given)."""
        natural = self.param.natural(z)
        bases = self.bases(natural, blurred)
        ratios = self.ratios(natural)
        coef, offset = solve_linear(
            bases, tuple(p.target for p in self.pairs), self.weights(), ratios, self.active
        )
        return natural, bases, ratios, coef, offset

    def mixed_residual(self, bases, ratios, coef, offset) -> Float[Array, " N"]:
        """The weighted residual of the predictions mixed from given basis images
        (linear in ``coef`` and ``offset``; the covariance differentiates it)."""
        parts = []
        for k, (pair, x, w) in enumerate(zip(self.pairs, bases, self.weights())):
            pred = combine(x, ratios[k], coef, offset[k])
            parts.append((jnp.sqrt(w) * (pair.target - pred)).ravel())
        return jnp.concatenate(parts) / self.scale

    def __call__(self, z, args=None):
        _, bases, ratios, coef, offset = self.linear(z)
        return self.mixed_residual(bases, ratios, coef, offset), None

    def difference_jacobian(self, z, step: float) -> tuple[Float[Array, " N"], Float[Array, "N n"]]:
        """The residual at ``z`` and its Jacobian, the blur by forward differences.

        The blurred basis images are differentiated by forward differences of
        ``step`` in each unknown the blur depends on (one blur per unknown of the
        passes, and one for all those of the source together, where
        forward mode costs about two: each tap gathers the tangent image and the
        image's slope), except the grey mix, whose columns are exact and cost no
        blur (:meth:`_blurred_with_slopes`). The terms after the blur, the
        vignetting and the gain ratios are differentiated by forward mode through
        their linearisation in those images, and the projection by its closed form
        (:func:`~.projection.projected_jacobian`). Differencing the whole residual
        instead would difference the projection's solve too, whose rounding (its
        normal matrix is ill-conditioned: neighbouring layers are alike) then
        enters the columns at 1e-10 / step and makes the solver's path depend on
        how XLA happened to compile it.
        """
        natural = self.param.natural(z)
        blurred, slopes = self._blurred_with_slopes(z, natural, step)

        def mixing_inputs(u, images):
            moved = self.param.natural(u)
            return self.bases(moved, images), self.ratios(moved)

        bases, ratios = mixing_inputs(z, blurred)
        # One forward-mode direction per unknown: unit in z, the blur's slope in the images.
        # A loop over the directions, not vmap: XLA on CPU ran the vmapped directions,
        # once the projection's sums consumed them, 2.1-2.4 times slower with the
        # shift and the law (pt_face_940, 128 x 128: 56-63 against 26-30 ms per
        # Jacobian; plain, the same 12 ms), with the same numbers bit for bit.
        d_bases, d_ratios = jax.lax.map(
            lambda directions: jax.jvp(mixing_inputs, (z, blurred), directions)[1],
            (jnp.eye(z.size, dtype=z.dtype), slopes),
        )
        targets = tuple(p.target for p in self.pairs)
        weights = self.weights()
        coef, offset, d_predictions = projected_jacobian(
            bases, targets, weights, ratios, self.active, d_bases,
            d_ratios if "gain_ratio" in natural else None,
        )
        residual = self.mixed_residual(bases, ratios, coef, offset)
        jacobian = jnp.concatenate(
            [(-jnp.sqrt(w)[None] * d).reshape(z.size, -1) for w, d in zip(weights, d_predictions)], axis=1
        )
        return residual, jacobian.T / self.scale

    def _blurred_with_slopes(self, z, natural, step) -> tuple[tuple, tuple]:
        """The blurred basis images of every pair and their derivative along each
        unknown, ``(n, nb, H, W, C)`` per pair.

        Only the unknowns the blur depends on (:data:`_BLURRED_BY`) are differenced;
        the others (the gain ratios, the vignetting, the terms after the blur) leave
        the blurred images as they are. A grey mix is exact instead: the passes
        are linear in the image, so the blur of the mixed source is the mix of the
        blurred source channels, and each channel is blurred once (a three-channel
        blur costs about 1.25 grey ones on CPU: the sample positions are shared),
        where differencing the mix would cost two blurs. For the same reason the
        unknowns of the terms that light the source (:data:`_LIGHTING`) are
        differenced in one blur with the source (:meth:`_blurred_with_lighting_slopes`).
        """
        h = jnp.asarray(step, z.dtype)
        taken = (z + h) - z  # divide by the step actually taken
        blocks = self.param.layout()
        columns: list[list[Any]] = [[None] * z.size for _ in self.pairs]
        lighting = [j for name, (first, stop) in blocks.items() if name in _LIGHTING for j in range(first, stop)]
        if lighting and self._passes_alike_per_channel():
            channels, blurred = self._blurred_with_lighting_slopes(z, natural, h, taken, lighting, columns)
        else:
            lighting = []
            if "mix" in natural:
                channels = self.blurred_bases({k: v for k, v in natural.items() if k != "mix"})
                blurred = tuple(_mixed(x, natural["mix"]) for x in channels)
            else:
                blurred = self.blurred_bases(natural)
        differenced = [j for name, (first, stop) in blocks.items() if name in _BLURRED_BY
                       for j in range(first, stop) if j not in lighting]
        if differenced:

            def column(j):
                moved = self.blurred_bases(self.param.natural(z.at[j].add(h)))
                return tuple((a - b) / taken[j] for a, b in zip(moved, blurred))

            found = jax.lax.map(column, jnp.asarray(differenced))
            for p, slopes in enumerate(found):
                for i, j in enumerate(differenced):
                    columns[p][j] = slopes[i]
        if "mix" in natural:
            first, stop = blocks["mix"]
            for j in range(first, stop):
                d_mix = jax.jvp(lambda u: self.param.natural(u)["mix"], (z,), (jnp.zeros_like(z).at[j].set(1.0),))[1]
                for p, x in enumerate(channels):
                    columns[p][j] = _mixed(x, d_mix)
        slopes = tuple(
            jnp.stack([jnp.zeros_like(b) if c is None else c for c in cols]) for b, cols in zip(blurred, columns)
        )
        return blurred, slopes

    def _passes_alike_per_channel(self) -> bool:
        """Whether the blur gives every channel of the image the same passes, so
        that images side by side as channels blur as they would one by one."""
        layout = get_model(self.model).layout
        return (layout == "layered" and self.linear_weights) or layout in _SAME_PASSES_PER_CHANNEL

    def _blurred_with_lighting_slopes(self, z, natural, h, taken, lighting, columns) -> tuple[tuple, tuple]:
        """The blurred basis images of every pair, unmixed and mixed (as
        :meth:`_blurred_with_slopes` makes them), and in ``columns`` their forward
        differences along the unknowns ``lighting`` (of :data:`_LIGHTING`).

        Those unknowns move the source, not the passes, so the source and its
        moved copies go through one blur side by side as channels: the sample
        positions and tap weights, which depend on the depth and the blur
        parameters alone, are worked out once for all of them instead of once per
        moved copy. On pt_face_940 with ``shift,law`` (128 x 128, one core) the
        Jacobian took 35 ms in place of 41. The differences are those of a blur
        per copy to rounding; the passes mix no channels.
        """
        unmixed_natural = {k: v for k, v in natural.items() if k != "mix"}
        moved = [self.param.natural(z.at[j].add(h)) for j in lighting]
        unmixed, mixed = [], []
        for p, pair in enumerate(self.pairs):
            sources = [_lit_source(pair, values).source for values in [natural, *moved]]
            c = pair.source.shape[-1]
            side_by_side = eqx.tree_at(lambda q: q.source, pair, jnp.concatenate(sources, axis=-1))
            images = basis_images(side_by_side, unmixed_natural, self.model, self.tap_weights, self.linear_weights)
            copies = [images[..., i * c:(i + 1) * c] for i in range(len(sources))]
            unmixed.append(copies[0])
            if "mix" in natural:
                copies = [_mixed(x, natural["mix"]) for x in copies]
            for copy, j in zip(copies[1:], lighting):
                columns[p][j] = (copy - copies[0]) / taken[j]
            mixed.append(copies[0])
        return tuple(unmixed), tuple(mixed)

    def explicit_residual(self, z, coef, offset) -> Float[Array, " N"]:
        """The residual with the linear unknowns given instead of projected out."""
        natural = self.param.natural(z)
        return self.mixed_residual(self.bases(natural), self.ratios(natural), coef, offset)

    def predictions(self, z) -> tuple:
        """``a * out + b`` for every pair, full images of the target's shape."""
        _, bases, ratios, coef, offset = self.linear(z)
        return tuple(combine(x, ratios[k], coef, offset[k]) for k, x in enumerate(bases))

    def loss(self, z) -> Float[Array, ""]:
        """Mask-weighted mean of ``u (T - pred)^2`` over pixels and channels."""
        r, _ = self(z)
        c = self.pairs[0].target.shape[-1]
        total = sum(jnp.sum(p.residual_weight) for p in self.pairs) * c
        return jnp.sum(r**2) * self.scale**2 / total
