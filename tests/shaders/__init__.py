"""Tests of invsss/shaders/ alone. The shaders are run against render in tests/io/
(test_shader*.py), the layer that writes their constants."""
