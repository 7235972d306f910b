"""Tests of piezohyst.cli."""
