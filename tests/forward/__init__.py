"""Tests of invsss/forward/: the models, profiles, passes, light terms and render."""
