"""Tests of the scripts in experiments/ and of the data they made (data_synthetic/)."""
