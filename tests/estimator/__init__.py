"""Tests of invsss/estimator/: fit_pair and fit_pairs, the problem, the solver, the uncertainty."""
