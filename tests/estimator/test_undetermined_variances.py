"""Free variances the image cannot resolve are reported, not left to wander.

With the variances estimated (the ``sss_level`` gauge), a Gaussian narrower than
0.1 px even where the stretch is largest looks like no blur, and one wider than
the mask even where the stretch is smallest looks like a flat offset: either
variance is reported undetermined with its reason.
"""

from __future__ import annotations

import numpy as np

from invsss.estimator.initial import DataScales
from invsss.estimator.uncertainty import structural_reasons


def test_variances_the_image_cannot_resolve_are_reported():
    # 1 px per mm everywhere (L = 500 at 500 mm, flat), a mask 40 px across.
    flat = np.zeros(100)
    scales = DataScales(np.full(100, 500.0), flat, flat, 64, 40.0)
    roles = {"sss_level": "fixed", "correction": "fixed", "maxdd": "fixed", "weights": "linear",
             "variances": "free"}
    natural = {"sss_level": 500.0, "correction": 0.0, "maxdd": 1.0,
               # 0.03 px, 1 px, 50 px and (weight 0) 0.01 px
               "variances": np.array([0.001, 1.0, 2500.0, 1e-4])}
    weights = natural["weights"] = np.array([0.3, 0.4, 0.3, 0.0])
    flags, messages = structural_reasons(roles, "sog", scales, natural, weights, np.ones((4, 1)))
    assert flags["variances"].tolist() == [True, False, True, True]
    said = " ".join(messages)
    assert "variances[0] (0.001 mm^2): blurs by less than 0.1 px" in said
    assert "variances[2] (2.5e+03 mm^2): blurs by more than the mask's width (40 px)" in said
    # The empty Gaussian is reported for its weight, not a second time for its width.
    assert "variances[3]: the weight is ~0" in said and "0.0001 mm^2" not in said
