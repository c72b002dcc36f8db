"""Tests of invsss/estimator/stages/: the stages around a fit's core (saturation, alignment,
highlights, light terms)."""
