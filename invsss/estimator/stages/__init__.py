"""The stages of a fit around its core (:func:`invsss.estimator.fit.fit_stages`).

Each stage is a function ``stage(inner) -> fit`` of the stage inside it; a fit
takes a :class:`~invsss.estimator.core.FitCall` and returns a
:class:`~invsss.estimator.result.FitResult`. A stage whose option is off passes
the call on unchanged.
"""

from .alignment import aligned
from .highlights import without_highlights
from .light_terms import with_light_terms
from .saturation import unsaturated

__all__ = ["aligned", "unsaturated", "with_light_terms", "without_highlights"]
