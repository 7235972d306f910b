"""Tests of piezohyst.workflows."""
