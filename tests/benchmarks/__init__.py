"""Tests of the benchmark scripts that score against public data (run here on generated data)."""
