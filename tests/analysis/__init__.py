"""Tests of piezohyst.analysis."""
