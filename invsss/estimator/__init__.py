"""Estimate the screen-space SSS parameters from image pairs (docs/model.md, section 7).

Public entry points: :func:`fit_pair`, :func:`fit_pairs` and their
:class:`FitResult`; :class:`FitOptions` (the fit's settings, checked once) and
:func:`build_problem` (the problem a fit solves, to probe or time it);
:class:`FitInterrupted` (a fit stopped before its first step). The modules, one
idea each:

* :mod:`.options` -- :class:`FitOptions`;
* :mod:`.problem` -- :func:`build_problem`: parametrisation, objective, starts;
* :mod:`.inputs` -- checked float64 copies of the pairs;
* :mod:`.parametrisation` -- roles (free, linear, fixed, unused), gauge, constraints
  by reparametrisation;
* :mod:`.basis`, :mod:`.projection` -- the images the prediction is linear in, and
  the least-squares elimination of the linear unknowns (variable projection);
* :mod:`.objective` -- the projected, weighted residual as one pytree;
* :mod:`.initial` -- data scales and multi-start grid;
* :mod:`.solve` -- optimistix solvers stepped by hand (progress, loss history);
* :mod:`.robust` -- robust loss by reweighting;
* :mod:`.uncertainty` -- Gauss-Newton standard errors, undetermined parameters;
* :mod:`.diagnostics` -- PSNR, SSIM, misalignment;
* :mod:`.result` -- :class:`FitResult`.
"""

from .fit import fit_pair, fit_pairs
from .options import FitOptions
from .problem import FitProblem, build_problem
from .result import FitResult
from .solve import FitInterrupted

__all__ = ["fit_pair", "fit_pairs", "FitResult", "FitOptions", "FitProblem", "build_problem", "FitInterrupted"]
