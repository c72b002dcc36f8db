"""Values as the model's float arrays: the one converter of its pytrees' fields."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ..validation import InvalidInputError

__all__ = ["float_array"]


def float_array(x, dtype=None, name: str | None = None) -> Array:
    """``x`` as a JAX array of ``dtype``, by default JAX's float type (float32, or float64 under x64).

    A JAX array (or a tracer, inside ``jit``) is converted by ``jnp.asarray``; a host
    value (a number, a list, a NumPy array) by NumPy and then put on the device,
    because a conversion on the device compiles, and this runs for every field of
    every :class:`~invsss.SSSParams` and :class:`~invsss.SumOfGaussians` built.

    Examples
    --------
    >>> float_array([1, 2]).dtype
    dtype('float32')
    >>> float_array(0.5, "float16")
    Array(0.5, dtype=float16)
    """
    dtype = dtype or jnp.result_type(float)
    if isinstance(x, jax.Array):
        return jnp.asarray(x, dtype=dtype)
    host = np.asarray(x)
    if host.dtype.kind in "US":
        # NumPy would parse "600" as 600.0; a params file refuses text, and so does this.
        raise InvalidInputError(f"{name + ': ' if name else ''}expected numbers, got the text {x!r}")
    return jax.device_put(host.astype(dtype, copy=False))
