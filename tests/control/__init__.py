"""Tests of piezohyst.control."""
