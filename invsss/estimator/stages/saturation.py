"""Stage: the targets' clipped pixels left out of the fit (``saturation``)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ...validation import InvalidInputError
from ..core import Fit, FitCall
from ..inputs import prepare_pairs
from ..result import FitResult

__all__ = ["unsaturated"]


def unsaturated(inner: Fit) -> Fit:
    """The stage that gives each target's pixels at or above ``saturation`` a fit
    weight of 0 and fits the rest with the inner stage, saying how many it left out."""

    def fit(call: FitCall) -> FitResult:
        saturation = call.options.saturation
        if saturation is None:
            return inner(call)
        if saturation == "auto":
            raise InvalidInputError(
                "saturation: 'auto' is the targets' own clipping level, which only their files know; give the "
                "level (1.0 for 8- or 16-bit targets decoded to [0, 1]) or None, or resolve it from the files "
                "with invsss.io.resolved_saturation", field="saturation")
        prepared = prepare_pairs(call.pairs)
        out, messages = [], []
        for i, pair in enumerate(prepared):
            clipped = np.any(np.asarray(pair.target) >= saturation, axis=-1) & (np.asarray(pair.mask) > 0)
            count = int(clipped.sum())
            keep = np.where(clipped, 0.0, 1.0 if pair.fit_weight is None else np.asarray(pair.fit_weight))
            if count:
                name = f"pairs[{i}].target" if len(prepared) > 1 else "target"
                if not (keep * np.asarray(pair.mask)).any():
                    raise InvalidInputError(f"{name}: every masked pixel is at or above the saturation level "
                                            f"{saturation:g}", field=name)
                messages.append(f"{name}: {count} masked pixel(s) at or above the saturation level "
                                f"{saturation:g} (clipped) left out of the fit")
            # ImagePair keeps the NumPy weight as given; the field is annotated as a jax Array.
            out.append(dataclasses.replace(pair, fit_weight=keep if count else pair.fit_weight))  # type: ignore[arg-type]
        result = inner(dataclasses.replace(call, pairs=out))
        return dataclasses.replace(result, warnings=tuple(messages) + tuple(result.warnings))

    return fit
