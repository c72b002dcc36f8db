"""Tests of the sweep engine, invsss/sweeps/: experiment files, trials, stores, reports."""
