"""A directional pass as one GPU kernel (Pallas on Triton), with its derivatives.

:func:`invsss.forward.passes.directional_pass` in plain XLA is the reference and the
CPU path. Here one Pallas kernel computes a pass per tile of pixels: each
output pixel reads its 7 taps (two neighbours each, linear interpolation,
clamp-to-edge) and writes the blend ``I + m (sum_k W_k S_k - I)`` once. On an
H100 (docs/gpu.md) the forward kernel runs about as fast as XLA's own fusion
of the gathers; the gain is in forward mode, where one launch serves all the
tangents of ``jax.jacfwd`` (the estimator's Jacobian): 2.2-2.9x faster per pass
at 1024^2.

The pass is a JAX primitive with three kernels:

``forward``
    the pass itself;
``tangent``
    its JVP, linear in the image tangent and the footprint tangent: the pass
    applied to the image tangent plus ``m sum_k W_k t_k (R_k - L_k)`` times the
    footprint tangent (``L_k``, ``R_k`` the two neighbours of tap ``k``);
    several tangents at once (``jax.jacfwd`` batches them into one launch);
``transpose``
    the transpose of the tangent map (reverse mode): the image cotangent is a
    scatter of each tap's interpolation weights (atomic adds, so the order of
    the additions, and the last bits, can change between runs, as they do in
    XLA's own scatter), the footprint cotangent a gather like the forward pass.
    Measured slower than XLA's scatter on an H100, it is not used on CUDA
    (:data:`KERNEL_ON_CUDA`); the interpreter tests keep it correct.

Tangents of the mask and of the tap weights (zero in every fit) are computed
from the XLA reference when they are not zero. Every primitive also lowers
without Pallas (to the reference and its derivatives) on other platforms, and
with ``interpret=True`` the kernels run in Pallas's interpreter on the CPU,
which is how the tests check them against the reference.

Which path a pass takes is decided by :func:`kernel_enabled`: the kernel on a
GPU backend, the XLA reference elsewhere; ``INVSSS_PASS_KERNEL=xla`` forces
the reference and ``INVSSS_PASS_KERNEL=pallas`` the kernel.
"""

from __future__ import annotations

import functools
import os

import jax
import jax.numpy as jnp
from jax.extend.core import Primitive
from jax.interpreters import ad, batching, mlir

from .taps import TAP_OFFSETS, directional_pass_xla, tap_sum

__all__ = [
    "PASS_KERNEL_VARIABLE",
    "DEFAULT_BLOCK",
    "kernel_enabled",
    "directional_pass_kernel",
]

#: The environment variable that picks the pass implementation: ``auto``
#: (default: the kernel on a GPU backend), ``pallas``, ``xla``, or
#: ``interpret`` (the kernels in Pallas's interpreter on any backend: slow, for tests).
PASS_KERNEL_VARIABLE = "INVSSS_PASS_KERNEL"

#: Output tile of one kernel program: rows, columns (powers of 2 for Triton).
DEFAULT_BLOCK = (8, 128)

#: Triton warps per program.
NUM_WARPS = 4


def kernel_enabled(image) -> bool:
    """Whether :func:`invsss.forward.passes.directional_pass` runs :func:`directional_pass_kernel`.

    ``INVSSS_PASS_KERNEL`` = ``xla`` or ``pallas`` decides; otherwise (``auto``)
    the kernel runs when JAX's default backend is a GPU and the image is float32
    or float64 (the estimator fits in float64) and at least 2 x 2 pixels.

    Examples
    --------
    >>> import jax, jax.numpy as jnp
    >>> kernel_enabled(jnp.zeros((8, 8, 3))) == (jax.default_backend() == "gpu"
    ...     and os.environ.get(PASS_KERNEL_VARIABLE, "auto") != "xla")
    True
    """
    choice = _choice()
    if choice == "xla":
        return False
    fits = (
        getattr(image, "dtype", None) in (jnp.float32, jnp.float64)
        and image.ndim == 3
        and image.shape[0] >= 2
        and image.shape[1] >= 2
    )
    if choice in ("pallas", "interpret"):
        return fits
    return fits and jax.default_backend() == "gpu"


def _choice() -> str:
    choice = os.environ.get(PASS_KERNEL_VARIABLE, "auto").strip().lower()
    if choice not in ("auto", "pallas", "xla", "interpret"):
        from ..validation import InvalidInputError

        raise InvalidInputError(
            f"{PASS_KERNEL_VARIABLE}: expected one of auto, pallas, xla, interpret, got {choice!r}",
            field=PASS_KERNEL_VARIABLE,
        )
    return choice


# --------------------------------------------------------------- kernels


def _tap_geometry(rows, cols, footprint, along_rows, h, w, t):
    """Left index, step to the right neighbour, fraction and clamp slope of tap ``t``.

    ``along_rows`` is the pass axis as int32, 1 (rows) or 0 (columns): the two
    layouts are mixed arithmetically, as Triton lowers no select of scalars.
    """
    dtype = footprint.dtype
    n = h + along_rows * (w - h)
    base = (rows + along_rows * (cols - rows)).astype(dtype)
    p = base + t * footprint
    top = (n - 1).astype(dtype)
    u = jnp.clip(p, 0.0, top)
    i0 = jnp.clip(jnp.floor(u).astype(jnp.int32), 0, n - 2)
    frac = u - i0.astype(dtype)
    flat0 = along_rows * (rows * w + i0) + (1 - along_rows) * (i0 * w + cols)
    step = w - along_rows * (w - 1)
    # d u / d p of jnp.clip: 1 inside, 1/2 on a bound (JAX's convention for ties).
    inside = (p > 0.0) & (p < top)
    on_bound = (p == 0.0) | (p == top)
    slope = jnp.where(inside, 1.0, jnp.where(on_bound, 0.5, 0.0)).astype(dtype)
    return flat0, step, frac, slope


def _tile(block, h, w, first_axis):
    """This program's output pixels: the grid's axes ``first_axis`` and the next one tile (H, W)."""
    from jax.experimental import pallas as pl

    bh, bw = block
    rows = pl.program_id(first_axis) * bh + jnp.arange(bh, dtype=jnp.int32)[:, None]
    cols = pl.program_id(first_axis + 1) * bw + jnp.arange(bw, dtype=jnp.int32)[None, :]
    valid = (rows < h) & (cols < w)
    # Lanes past the image redo the last row's or column's pixel and store the
    # same value there: no masked stores, whose masked-off lanes write back
    # stale values in the interpreter.
    rows = jnp.minimum(rows, h - 1)
    cols = jnp.minimum(cols, w - 1)
    return rows, cols, valid, rows * w + cols


def _forward_kernel(axis_ref, w_ref, img_ref, f_ref, m_ref, out_ref, *, h, w, c, block):
    from jax.experimental.pallas import triton as plgpu

    rows, cols, valid, pix = _tile(block, h, w, 0)
    along_rows = axis_ref[0]
    f = f_ref[pix]
    m = m_ref[pix]
    centre = [img_ref[pix * c + ch] for ch in range(c)]
    acc = [w_ref[3] * x for x in centre]
    for k, t in enumerate(TAP_OFFSETS):
        if t == 0.0:
            continue
        flat0, step, frac, _ = _tap_geometry(rows, cols, f, along_rows, h, w, t)
        for ch in range(c):
            left = img_ref[flat0 * c + ch]
            right = img_ref[(flat0 + step) * c + ch]
            acc[ch] = acc[ch] + w_ref[k] * (left + frac * (right - left))
    for ch in range(c):
        plgpu.store(out_ref.at[pix * c + ch], centre[ch] + m * (acc[ch] - centre[ch]))


def _tangent_kernel(axis_ref, w_ref, img_ref, f_ref, m_ref, dimg_ref, df_ref, out_ref, *, h, w, c, block):
    from jax.experimental import pallas as pl
    from jax.experimental.pallas import triton as plgpu

    rows, cols, valid, pix = _tile(block, h, w, 1)
    image_offset = pl.program_id(0) * (h * w * c)
    along_rows = axis_ref[0]
    f = f_ref[pix]
    m = m_ref[pix]
    df = df_ref[pl.program_id(0) * (h * w) + pix]
    centre = [dimg_ref[image_offset + pix * c + ch] for ch in range(c)]
    acc = [w_ref[3] * x for x in centre]
    for k, t in enumerate(TAP_OFFSETS):
        if t == 0.0:
            continue
        flat0, step, frac, slope = _tap_geometry(rows, cols, f, along_rows, h, w, t)
        shift = (w_ref[k] * t) * slope * df
        for ch in range(c):
            left_at, right_at = flat0 * c + ch, (flat0 + step) * c + ch
            d_left = dimg_ref[image_offset + left_at]
            d_right = dimg_ref[image_offset + right_at]
            rise = img_ref[right_at] - img_ref[left_at]
            acc[ch] = acc[ch] + w_ref[k] * (d_left + frac * (d_right - d_left)) + shift * rise
    for ch in range(c):
        plgpu.store(out_ref.at[image_offset + pix * c + ch], centre[ch] + m * (acc[ch] - centre[ch]))


def _scatter_add(ref, index, value, interpret):
    """``ref[index] += value``, repeated indices adding up."""
    if interpret:
        # The interpreter's atomic_add keeps one of several updates to one
        # address; its discharged add-update is a scatter-add (private API, used
        # by the CPU tests only).
        from jax._src.state.primitives import ref_addupdate

        ref_addupdate(ref, (index,), value)
    else:
        from jax.experimental.pallas import triton as plgpu

        plgpu.atomic_add(ref, (index,), value)


def _transpose_kernel(
    axis_ref, w_ref, img_ref, f_ref, m_ref, ct_ref, ct_img_in_ref, ct_img_ref, ct_f_ref, *, h, w, c, block,
    interpret,
):
    from jax.experimental import pallas as pl
    from jax.experimental.pallas import triton as plgpu

    del ct_img_in_ref  # aliased to ct_img_ref, which holds the direct term already
    rows, cols, valid, pix = _tile(block, h, w, 1)
    tangent = pl.program_id(0)
    image_offset = tangent * (h * w * c)
    along_rows = axis_ref[0]
    f = f_ref[pix]
    m = m_ref[pix]
    ct = [m * ct_ref[image_offset + pix * c + ch] for ch in range(c)]
    # Lanes past the image duplicate a pixel: they add zeros rather than mask the atomics.
    ct_once = [jnp.where(valid, x, 0.0) for x in ct]
    ct_f = jnp.zeros_like(f)
    for k, t in enumerate(TAP_OFFSETS):
        if t == 0.0:
            continue
        flat0, step, frac, slope = _tap_geometry(rows, cols, f, along_rows, h, w, t)
        dot = jnp.zeros_like(f)
        for ch in range(c):
            left_at, right_at = flat0 * c + ch, (flat0 + step) * c + ch
            share = w_ref[k] * ct_once[ch]
            _scatter_add(ct_img_ref, image_offset + left_at, share - share * frac, interpret)
            _scatter_add(ct_img_ref, image_offset + right_at, share * frac, interpret)
            dot = dot + ct[ch] * (img_ref[right_at] - img_ref[left_at])
        ct_f = ct_f + (w_ref[k] * t) * slope * dot
    plgpu.store(ct_f_ref.at[tangent * (h * w) + pix], ct_f)


def _call(kernel, grid, out_shapes, args, *, interpret, aliases=None):
    from jax.experimental import pallas as pl
    from jax.experimental.pallas import triton as plgpu

    return pl.pallas_call(
        kernel,
        out_shape=out_shapes,
        grid=grid,
        input_output_aliases=aliases or {},
        interpret=interpret,
        compiler_params=None if interpret else plgpu.CompilerParams(num_warps=NUM_WARPS, num_stages=1),
    )(*args)


def _grid(shape, block, tangents=None):
    h, w = shape[:2]
    tiles = (-(-h // block[0]), -(-w // block[1]))
    return tiles if tangents is None else (tangents,) + tiles


def _forward_pallas(image, footprint, mask, weights, axis, *, interpret, block):
    h, w, c = image.shape
    kernel = functools.partial(_forward_kernel, h=h, w=w, c=c, block=block)
    out = _call(
        kernel,
        _grid(image.shape, block),
        jax.ShapeDtypeStruct((h * w * c,), image.dtype),
        (axis.reshape(1), weights, image.reshape(-1), footprint.reshape(-1), mask.reshape(-1)),
        interpret=interpret,
    )
    return out.reshape(h, w, c)


def _tangent_pallas(image, footprint, mask, weights, axis, d_image, d_footprint, *, interpret, block):
    h, w, c = image.shape
    t = d_image.shape[0]
    kernel = functools.partial(_tangent_kernel, h=h, w=w, c=c, block=block)
    out = _call(
        kernel,
        _grid(image.shape, block, t),
        jax.ShapeDtypeStruct((t * h * w * c,), image.dtype),
        (axis.reshape(1), weights, image.reshape(-1), footprint.reshape(-1), mask.reshape(-1),
         d_image.reshape(-1), d_footprint.reshape(-1)),
        interpret=interpret,
    )
    return out.reshape(t, h, w, c)


def _transpose_pallas(image, footprint, mask, weights, axis, ct, *, interpret, block):
    h, w, c = image.shape
    t = ct.shape[0]
    kernel = functools.partial(_transpose_kernel, h=h, w=w, c=c, block=block, interpret=interpret)
    # The centre tap and the unblurred share land on the pixel itself: written
    # here, the kernel adds the six moving taps on top.
    direct = (1.0 - mask[..., None] + mask[..., None] * weights[3]) * ct
    ct_img, ct_f = _call(
        kernel,
        _grid(image.shape, block, t),
        (jax.ShapeDtypeStruct((t * h * w * c,), image.dtype), jax.ShapeDtypeStruct((t * h * w,), image.dtype)),
        (axis.reshape(1), weights, image.reshape(-1), footprint.reshape(-1), mask.reshape(-1),
         ct.reshape(-1), direct.reshape(-1)),
        interpret=interpret,
        aliases={6: 0},
    )
    return ct_img.reshape(t, h, w, c), ct_f.reshape(t, h, w)


# ------------------------------------------------- XLA lowerings (reference)


def _forward_xla(image, footprint, mask, weights, axis, **_):
    return directional_pass_xla(image, footprint, mask, weights, axis)


def _tangent_map_xla(image, footprint, mask, weights, axis):
    def tangent(d_image, d_footprint):
        return jax.jvp(
            lambda i, f: directional_pass_xla(i, f, mask, weights, axis),
            (image, footprint),
            (d_image, d_footprint),
        )[1]

    return tangent


def _tangent_xla(image, footprint, mask, weights, axis, d_image, d_footprint, **_):
    return jax.vmap(_tangent_map_xla(image, footprint, mask, weights, axis))(d_image, d_footprint)


def _transpose_xla(image, footprint, mask, weights, axis, ct, **_):
    tangent = _tangent_map_xla(image, footprint, mask, weights, axis)
    _, transpose = jax.vjp(tangent, jnp.zeros_like(image), jnp.zeros_like(footprint))
    return jax.vmap(transpose)(ct)


# --------------------------------------------------------------- primitives

pass_p = Primitive("invsss_directional_pass")
pass_tangent_p = Primitive("invsss_directional_pass_tangent")
pass_transpose_p = Primitive("invsss_directional_pass_transpose")
pass_transpose_p.multiple_results = True

_IMPLEMENTATIONS = {
    pass_p: (_forward_pallas, _forward_xla),
    pass_tangent_p: (_tangent_pallas, _tangent_xla),
    pass_transpose_p: (_transpose_pallas, _transpose_xla),
}


def _shaped(x):
    return jax.core.ShapedArray(x.shape, x.dtype)


pass_p.def_abstract_eval(lambda image, *_, **__: _shaped(image))
pass_tangent_p.def_abstract_eval(lambda image, f, m, w, a, d_image, d_f, **_: _shaped(d_image))
pass_transpose_p.def_abstract_eval(
    lambda image, f, m, w, a, ct, **_: (
        _shaped(ct),
        jax.core.ShapedArray(ct.shape[:3], ct.dtype),
    )
)


def _implementation(prim, use_pallas):
    pallas_fn, xla_fn = _IMPLEMENTATIONS[prim]

    def run(*args, interpret, block):
        if use_pallas or interpret:
            return pallas_fn(*args, interpret=interpret, block=block)
        return xla_fn(*args)

    return run


#: Which primitives lower to their Pallas kernel on CUDA. Measured per pass on
#: an H100 (docs/gpu.md): the forward kernel about matches XLA's fusion (0.11-0.14
#: against 0.12 ms at 1024^2) and the tangent kernel with 8 tangents, what the
#: estimator's Jacobian runs, takes 0.38-0.48 against 1.08 ms; the transpose
#: kernel's atomic adds took 0.71-0.97 against 0.58 ms for XLA's scatter (0.44
#: against 0.11 ms at 256^2), so reverse mode keeps XLA's.
KERNEL_ON_CUDA = {pass_p: True, pass_tangent_p: True, pass_transpose_p: False}

for _prim in _IMPLEMENTATIONS:
    _prim.def_impl(functools.partial(jax.jit, static_argnames=("interpret", "block"))(
        _implementation(_prim, use_pallas=False)
    ))
    # Other platforms: the reference (or the interpreter when asked); CUDA: the kernel.
    mlir.register_lowering(
        _prim, mlir.lower_fun(_implementation(_prim, False), multiple_results=_prim.multiple_results)
    )
    mlir.register_lowering(
        _prim,
        mlir.lower_fun(_implementation(_prim, KERNEL_ON_CUDA[_prim]), multiple_results=_prim.multiple_results),
        platform="cuda",
    )


def _blurred_xla(image, footprint, weights, axis):
    return directional_pass_xla(image, footprint, jnp.ones(image.shape[:2], image.dtype), weights, axis)


def _pass_jvp(primals, tangents, *, interpret, block):
    image, footprint, mask, weights, axis = primals
    d_image, d_footprint, d_mask, d_weights, _ = tangents
    out = pass_p.bind(*primals, interpret=interpret, block=block)
    d_out = None
    if type(d_image) is not ad.Zero or type(d_footprint) is not ad.Zero:
        d_image = ad.instantiate_zeros(d_image)
        d_footprint = ad.instantiate_zeros(d_footprint)
        d_out = pass_tangent_p.bind(
            image, footprint, mask, weights, axis, d_image[None], d_footprint[None],
            interpret=interpret, block=block,
        )[0]
    # The mask and the tap weights are constants in every fit; their rare
    # tangents come from the reference.
    if type(d_mask) is not ad.Zero:
        term = d_mask[..., None] * (_blurred_xla(image, footprint, weights, axis) - image)
        d_out = term if d_out is None else d_out + term
    if type(d_weights) is not ad.Zero:
        term = _weights_tangent(image, footprint, mask, d_weights, axis)
        d_out = term if d_out is None else d_out + term
    if d_out is None:
        return out, ad.Zero.from_primal_value(out)
    return out, d_out


def _weights_tangent(image, footprint, mask, d_weights, axis):
    return mask[..., None] * tap_sum(image, footprint, d_weights, axis)


ad.primitive_jvps[pass_p] = _pass_jvp


def _tangent_transpose(ct, image, footprint, mask, weights, axis, d_image, d_footprint, *, interpret, block):
    for primal in (image, footprint, mask, weights, axis):
        if ad.is_undefined_primal(primal):
            raise NotImplementedError("directional_pass_kernel: second derivatives are not implemented")
    if type(ct) is ad.Zero:
        ct_image = ad.Zero(d_image.aval) if ad.is_undefined_primal(d_image) else None
        ct_f = ad.Zero(d_footprint.aval) if ad.is_undefined_primal(d_footprint) else None
        return None, None, None, None, None, ct_image, ct_f
    ct_image, ct_f = pass_transpose_p.bind(
        image, footprint, mask, weights, axis, ct, interpret=interpret, block=block
    )
    return (
        None, None, None, None, None,
        ct_image if ad.is_undefined_primal(d_image) else None,
        ct_f if ad.is_undefined_primal(d_footprint) else None,
    )


ad.primitive_transposes[pass_tangent_p] = _tangent_transpose


def _second_order(*_, **__):
    raise NotImplementedError("directional_pass_kernel: second derivatives are not implemented")


ad.primitive_jvps[pass_tangent_p] = _second_order
ad.primitive_jvps[pass_transpose_p] = _second_order


def _map_batched(prim, args, dims, params):
    # Batched primal inputs (rare: a vmap over images): one pass per element.
    size = next(a.shape[d] for a, d in zip(args, dims) if d is not None)
    moved = [batching.bdim_at_front(a, d, size) for a, d in zip(args, dims)]
    out = jax.lax.map(lambda xs: prim.bind(*xs, **params), moved)
    return out, ([0] * len(out) if prim.multiple_results else 0)


def _tangent_batch(args, dims, **params):
    # jax.jacfwd batches the tangents only: fold the batch into the kernel's tangent axis.
    if any(d is not None for d in dims[:5]):
        return _map_batched(pass_tangent_p, args, dims, params)
    *primal, d_image, d_footprint = args
    size = next(a.shape[d] for a, d in zip(args[5:], dims[5:]) if d is not None)
    d_image = batching.bdim_at_front(d_image, dims[5], size)
    d_footprint = batching.bdim_at_front(d_footprint, dims[6], size)
    t = d_image.shape[1]
    out = pass_tangent_p.bind(
        *primal, d_image.reshape((size * t,) + d_image.shape[2:]),
        d_footprint.reshape((size * t,) + d_footprint.shape[2:]), **params,
    )
    return out.reshape((size, t) + out.shape[1:]), 0


def _transpose_batch(args, dims, **params):
    if any(d is not None for d in dims[:5]):
        return _map_batched(pass_transpose_p, args, dims, params)
    *primal, ct = args
    size = ct.shape[dims[5]]
    ct = batching.bdim_at_front(ct, dims[5], size)
    t = ct.shape[1]
    ct_image, ct_f = pass_transpose_p.bind(*primal, ct.reshape((size * t,) + ct.shape[2:]), **params)
    return [ct_image.reshape((size, t) + ct_image.shape[1:]), ct_f.reshape((size, t) + ct_f.shape[1:])], [0, 0]


batching.primitive_batchers[pass_p] = lambda args, dims, **params: _map_batched(pass_p, args, dims, params)
batching.primitive_batchers[pass_tangent_p] = _tangent_batch
batching.primitive_batchers[pass_transpose_p] = _transpose_batch


def directional_pass_kernel(image, footprint, mask, weights, axis, *, interpret=None, block=None):
    """:func:`invsss.forward.passes.directional_pass` as one kernel per pass (see the module docstring).

    Same arguments and result as the reference; float32 or float64. ``interpret``
    runs the Pallas kernels in the interpreter (any platform, slow; for tests);
    otherwise they run on CUDA and the XLA reference runs elsewhere; ``None``
    means ``INVSSS_PASS_KERNEL == "interpret"``.
    ``block`` is the (rows, columns) tile of one program, powers of 2.

    Examples
    --------
    >>> import jax.numpy as jnp
    >>> from invsss.forward.passes import directional_pass, tap_weights
    >>> image = jnp.linspace(0.0, 1.0, 4 * 6 * 3).reshape(4, 6, 3)
    >>> footprint = jnp.full((4, 6), 1.5); mask = jnp.ones((4, 6))
    >>> fast = directional_pass_kernel(image, footprint, mask, tap_weights(), 1, interpret=True)
    >>> bool(jnp.allclose(fast, directional_pass(image, footprint, mask, tap_weights(), 1), atol=1e-6))
    True
    """
    if interpret is None:
        interpret = _choice() == "interpret"
    block = tuple(block or DEFAULT_BLOCK)
    if any(b < 1 or b & (b - 1) for b in block) or len(block) != 2:
        raise ValueError(f"block: expected two powers of 2, got {block}")
    axis = jnp.asarray(axis, jnp.int32)
    return pass_p.bind(
        image, footprint.astype(image.dtype), mask.astype(image.dtype), weights.astype(image.dtype), axis,
        interpret=bool(interpret), block=block,
    )

