"""Tests of invsss/cli/: the command line driven end to end, its progress line and report."""
