"""Tests of piezohyst.io."""
