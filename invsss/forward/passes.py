"""One directional pass of a screen-space blur (docs/model.md, section 3).

The pass the models call: the plain-XLA reference of :mod:`invsss.forward.taps`,
or a Pallas kernel where :mod:`invsss.forward.pass_kernels` says one runs. The
tap names are re-exported here, where they were first defined.
"""

from __future__ import annotations

from jaxtyping import Array, Float

from . import pass_kernels
from .taps import (
    TAP_OFFSETS,
    TAP_WEIGHTS,
    directional_pass_xla,
    pixel_coordinates,
    sample_along,
    tap_spread,
    tap_sum,
    tap_weights,
)

__all__ = [
    "TAP_OFFSETS",
    "TAP_WEIGHTS",
    "tap_weights",
    "tap_spread",
    "sample_along",
    "tap_sum",
    "pixel_coordinates",
    "directional_pass",
    "directional_pass_xla",
]


def directional_pass(
    image: Float[Array, "H W C"],
    footprint: Float[Array, "H W"],
    mask: Float[Array, "H W"],
    weights: Float[Array, " 7"],
    axis: int,
) -> Float[Array, "H W C"]:
    """``P(I; f)[y, x] = sum_k W_k I(y, x + t_k f[y, x])``, blended by the mask.

    ``axis=1`` is the horizontal pass ``P_x``, ``axis=0`` the vertical ``P_y``;
    ``axis`` may be traced, so one scan body can alternate between the two.
    Where ``mask`` is 0 the image is returned unchanged; in between the result
    is ``m P + (1 - m) I``.
    """
    # ---- GPU dispatch (issue 35): one Pallas kernel per pass where
    # invsss.forward.pass_kernels.kernel_enabled says so; this XLA code stays the
    # reference and the CPU path.
    if pass_kernels.kernel_enabled(image):
        return pass_kernels.directional_pass_kernel(image, footprint, mask, weights, axis)
    # ---- end of GPU dispatch
    return directional_pass_xla(image, footprint, mask, weights, axis)
