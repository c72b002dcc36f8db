"""Tests of invsss/measurement/: profile measurement, sum-of-Gaussians and dipole fits."""
