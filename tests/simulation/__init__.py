"""Tests of piezohyst.simulation."""
