"""Tests of piezohyst.model."""
