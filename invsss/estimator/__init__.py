"""Estimate the screen-space SSS parameters from image pairs (docs/model.md, section 7).

Public entry points: :func:`fit_pair`, :func:`fit_pairs` and their
:class:`FitResult`; :class:`FitOptions` (the fit's settings, checked once) and
:func:`build_problem` (the problem a fit solves, to probe or time it);
:class:`FitInterrupted` (a fit stopped before its first step). The modules, one
idea each, in the order a fit uses them:

* :mod:`.fit` -- :func:`fit_pair`, :func:`fit_pairs` and the composed stages;
* :mod:`.options` -- :class:`FitOptions`; :mod:`.option_text` -- their command-line
  spellings (``--fix maxdd=0.05``, ``--canvas 256x256``) turned into values;
* :mod:`.stages` -- what changes *what* is fitted, around the core: clipped pixels
  left out, alignment, highlights refit, light terms;
* :mod:`.core` -- :class:`~.core.FitCall` and the innermost stage (build, solve, report);
* :mod:`.problem` -- :func:`build_problem`: parametrisation, objective, starts;
* :mod:`.inputs` -- checked float64 copies of the pairs;
* :mod:`.canvas` -- pairs padded onto one canvas so pairs of different sizes share
  their compiled functions;
* :mod:`.parametrisation` -- roles (free, linear, fixed, unused), gauge, constraints
  by reparametrisation;
* :mod:`.basis`, :mod:`.projection` -- the images the prediction is linear in, and
  the least-squares elimination of the linear unknowns (variable projection);
* :mod:`.vignetting`, :mod:`.pigment` -- smooth gain fields for the camera's
  fall-off and the skin's pigment difference;
* :mod:`.objective` -- the projected, weighted residual as one pytree;
* :mod:`.initial` -- data scales and multi-start grid;
* :mod:`.search` -- the solve on a built problem: starts, successive halving,
  robust rounds, active set;
* :mod:`.solve` -- optimistix solvers stepped by hand (progress, loss history);
* :mod:`.robust` -- robust loss by reweighting;
* :mod:`.registration` -- a target photograph's warp onto its source (``align``);
* :mod:`.summary` -- a solved problem's estimate, uncertainty and diagnostics;
* :mod:`.uncertainty` -- Gauss-Newton standard errors, undetermined parameters;
* :mod:`.blur_width` -- the fitted blur's width on the image, in pixels and mm;
* :mod:`.diagnostics` -- PSNR, SSIM, misalignment;
* :mod:`.result` -- :class:`FitResult`.
"""

from .fit import fit_pair, fit_pairs
from .options import FitOptions
from .problem import FitProblem, build_problem
from .result import FitResult
from .solve import FitInterrupted

__all__ = ["fit_pair", "fit_pairs", "FitResult", "FitOptions", "FitProblem", "build_problem", "FitInterrupted"]
