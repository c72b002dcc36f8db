"""Tests of invsss/runtime/: the compilation and executable caches, the deterministic scheduler."""
