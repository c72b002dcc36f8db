"""Gaussians whose layers differ by a blur far below a pixel: only the sum of their
weights is determined, and the fit says so once per group of neighbours in variance."""

from __future__ import annotations

import numpy as np

from invsss.estimator.initial import DataScales
from invsss.estimator.uncertainty import structural_reasons

#: The thesis's profile (Table 5.1): variances 0.549 and 0.5574 mm^2 are 1.5 % apart.
VARIANCES = np.array([8.749, 2.099, 0.549, 0.5574, 1.194])
WEIGHTS = np.array([0.28, 0.25, 0.001, 0.1, 0.17])
ROLES = {"sss_level": "fixed", "correction": "fixed", "maxdd": "fixed", "weights": "linear",
         "variances": "fixed"}


def _reasons(sss_level: float):
    flat = np.zeros(100)
    scales = DataScales(np.full(100, 500.0), flat, flat, 64, 40.0)  # stretch sss_level / 500 px per mm
    natural = {"sss_level": sss_level, "correction": 0.0, "maxdd": 1.0, "variances": VARIANCES,
               "weights": WEIGHTS}
    return structural_reasons(ROLES, "sog", scales, natural, WEIGHTS, np.ones((5, 1)))


def test_two_coinciding_gaussians_give_one_sum():
    flags, messages = _reasons(500.0)  # 1 px per mm: 0.09 px between the two close variances
    assert flags["weights"].tolist() == [False, False, True, True, False]
    assert messages == ["weights[2], weights[3]: variances 0.549 and 0.5574 differ by a blur of 0.09 px at "
                        "most (below 0.25 px), so only their sum 0.101 is determined"]


def test_a_chain_of_coinciding_gaussians_is_one_group_with_one_sum():
    # 0.28 px per mm: 0.026 px from 0.549 to 0.5574, 0.22 px from there to 1.194, and
    # 0.27 px (resolved) from 1.194 to 2.099.
    flags, messages = _reasons(140.0)
    assert flags["weights"].tolist() == [False, False, True, True, True]
    assert messages == ["weights[2], weights[3], weights[4]: variances 0.549, 0.5574 and 1.194 differ from one "
                        "to the next by a blur of 0.22 px at most (below 0.25 px), so only their sum 0.271 "
                        "is determined"]
