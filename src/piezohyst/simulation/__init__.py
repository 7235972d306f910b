"""The simulated bench: actuator, charge circuit, sensors and excitation signals."""

from __future__ import annotations

from .bench import DEFAULT_PRESET, PRESETS, BenchPreset, BenchRecord, simulate
from .signals import SIGNALS, make_signal

__all__ = [
    "DEFAULT_PRESET",
    "PRESETS",
    "SIGNALS",
    "BenchPreset",
    "BenchRecord",
    "make_signal",
    "simulate",
]
