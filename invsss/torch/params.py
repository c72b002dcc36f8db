"""The model parameters as a dataclass of torch tensors (twin of :mod:`invsss.forward.params`)."""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from ..forward.params import PARAM_NAMES, check_parameter_values, parameter_arrays

__all__ = ["SSSParams"]

def _as_float_tensor(x) -> torch.Tensor:
    # A floating tensor is kept as it is, so a leaf with requires_grad stays the
    # leaf the caller differentiates against; anything else gets torch's default
    # float type, as the JAX SSSParams takes JAX's default float type.
    if torch.is_tensor(x):
        return x if x.is_floating_point() else x.to(torch.get_default_dtype())
    return torch.as_tensor(np.asarray(x, dtype=np.float64), dtype=torch.get_default_dtype())


@dataclasses.dataclass(frozen=True)
class SSSParams:
    """Stretch factors and sum-of-Gaussians profile (docs/model.md, sections 2, 4, 6).

    The same fields and constraints as :class:`invsss.SSSParams`; each field is a
    torch tensor (numbers and arrays are converted, tensors kept as given).

    Parameters
    ----------
    sss_level : tensor, shape ()
        ``L`` > 0 in ``s = L / (d + c min(|dd|, maxdd))``.
    correction : tensor, shape ()
        ``c`` >= 0.
    maxdd : tensor, shape ()
        ``delta`` > 0.
    weights : tensor, shape (K,) or (K, C)
        Gaussian weights, one per Gaussian or one per Gaussian and channel.
    variances : tensor, shape (K,)
        Gaussian variances in scene units squared.

    Examples
    --------
    >>> import invsss.torch as itorch
    >>> p = itorch.SSSParams(0.5, 2000.0, 0.001, [0.4, 0.6], [0.5, 2.0])
    >>> p.num_gaussians
    2
    """

    sss_level: torch.Tensor
    correction: torch.Tensor
    maxdd: torch.Tensor
    weights: torch.Tensor
    variances: torch.Tensor

    def __post_init__(self):
        for k in PARAM_NAMES:
            object.__setattr__(self, k, _as_float_tensor(getattr(self, k)))

    @property
    def num_gaussians(self) -> int:
        return int(self.variances.shape[-1])

    def to(self, dtype=None, device=None) -> SSSParams:
        """A copy with every field converted (differentiably) to ``dtype``/``device``."""
        return SSSParams(**{k: getattr(self, k).to(dtype=dtype, device=device) for k in PARAM_NAMES})

    @classmethod
    def from_dict(cls, d: dict, source: str = "params") -> SSSParams:
        """Build from a params mapping (e.g. ``invsss.SSSParams.to_dict()`` or a JSON file)."""
        # check() covers the shapes and the constraints.
        params = cls(**parameter_arrays(d, source))  # type: ignore[arg-type]  # the fields' converters take array-likes
        params.check(source)
        return params

    def to_dict(self) -> dict:
        """Plain-Python mapping (lists and floats) suitable for JSON."""
        return {k: getattr(self, k).detach().cpu().tolist() for k in PARAM_NAMES}

    def check(self, name: str = "params") -> None:
        """Raise :class:`~invsss.InvalidInputError` if the values break the constraints.

        The same checks and messages as :meth:`invsss.SSSParams.check`.
        """
        check_parameter_values({k: getattr(self, k).detach().cpu().numpy() for k in PARAM_NAMES}, name)
