"""Tests of invsss/torch/: the PyTorch twin, against the JAX forward model."""
