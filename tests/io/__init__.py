"""Tests of invsss/io/: images, masks, depth, params.json, result directories, export.

The reference shaders are checked against render here (test_shader*.py), as io is
the layer that joins the exported constants, the shaders and the forward model.
"""
