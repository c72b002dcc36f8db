"""Tests of invsss/scenes/ and the path-traced pairs it made."""
