"""Checked, float64 copies of the image pairs an estimator fits.

Everything that can be wrong with the user's arrays is caught here, before any
tracing, with one-line :class:`~invsss.validation.InvalidInputError` messages that
name the input (``pairs[1].target`` for the second pair of :func:`fit_pairs`).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..validation import InvalidInputError, check_depth, check_image, check_mask, check_same_size

__all__ = ["PairData", "prepare_pair", "prepare_pairs"]


class PairData(eqx.Module):
    """One (source, target, depth, mask) pair as float64 arrays.

    Attributes
    ----------
    source : array, shape (H, W, C), C in {1, 3}
    target : array, shape (H, W, C'), C' = C, or C' = 1 with an RGB source
    depth : array, shape (H, W), > 0
    mask : array, shape (H, W), in [0, 1], not all zero
    target_ndim : int, static
        2 when the target was given as (H, W) (the fitted prediction is returned so).
    """

    source: Float[Array, "H W C"]
    target: Float[Array, "H W Ct"]
    depth: Float[Array, "H W"]
    mask: Float[Array, "H W"]
    target_ndim: int = eqx.field(static=True, default=3)

    @property
    def channels(self) -> tuple[int, int]:
        """(source channels, target channels)."""
        return int(self.source.shape[-1]), int(self.target.shape[-1])


def _as_hwc(x) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    return x[..., None] if x.ndim == 2 else x


def prepare_pair(source, target, depth, mask=None, *, name: str = "") -> PairData:
    """Validate one pair and convert it to float64 (call under ``jax.enable_x64``).

    ``mask=None`` fits every pixel. ``name`` prefixes the input names in errors.
    """
    check_image(source, f"{name}source")
    check_image(target, f"{name}target")
    check_same_size(np.shape(source), np.shape(target), f"{name}source", f"{name}target")
    hw = tuple(np.shape(source)[:2])
    check_depth(depth, hw, f"{name}depth")
    if mask is None:
        mask = np.ones(hw)
    check_mask(mask, hw, f"{name}mask")
    src, tgt = _as_hwc(source), _as_hwc(target)
    c_src, c_tgt = src.shape[-1], tgt.shape[-1]
    if c_tgt != c_src and not (c_src == 3 and c_tgt == 1):
        raise InvalidInputError(
            f"{name}target: expected {c_src} channel(s) like the source "
            f"(or 1 for a grey target of an RGB source), got {c_tgt}"
        )
    return PairData(
        jnp.asarray(src),
        jnp.asarray(tgt),
        jnp.asarray(np.asarray(depth, dtype=np.float64)),
        jnp.asarray(np.asarray(mask, dtype=np.float64)),
        int(np.ndim(target)),
    )


def _unpack(pair, index: int):
    if all(hasattr(pair, k) for k in ("source", "target", "depth", "mask")):
        return pair.source, pair.target, pair.depth, pair.mask
    if isinstance(pair, (tuple, list)) and len(pair) in (3, 4):
        return (*pair, None) if len(pair) == 3 else tuple(pair)
    raise InvalidInputError(
        f"pairs[{index}]: expected a (source, target, depth, mask) tuple or an "
        f"invsss.ImagePair, got {type(pair).__name__}"
    )


def prepare_pairs(pairs) -> tuple[PairData, ...]:
    """Validate a sequence of pairs; all must have the same channel layout."""
    if isinstance(pairs, (str, bytes)) or not hasattr(pairs, "__len__") or len(pairs) == 0:
        raise InvalidInputError("pairs: expected a non-empty sequence of (source, target, depth, mask)")
    out = tuple(
        prepare_pair(*_unpack(p, i), name=f"pairs[{i}]." if len(pairs) > 1 else "")
        for i, p in enumerate(pairs)
    )
    layouts = {p.channels for p in out}
    if len(layouts) > 1:
        raise InvalidInputError(
            "pairs: every pair must have the same (source, target) channel counts, got "
            + ", ".join(f"{a}->{b}" for a, b in sorted(layouts))
        )
    return out
