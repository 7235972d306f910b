"""The simulated bench: actuator, charge circuit, sensors and excitation signals."""

from __future__ import annotations

from .bench import (
    DEFAULT_PRESET,
    PLANTS,
    PRESETS,
    Bench,
    BenchPreset,
    BenchRecord,
    Reading,
    batch_unit,
    simulate,
)
from .loop import run_loop
from .signals import SIGNALS, make_signal

__all__ = [
    "DEFAULT_PRESET",
    "PLANTS",
    "PRESETS",
    "SIGNALS",
    "Bench",
    "BenchPreset",
    "BenchRecord",
    "Reading",
    "batch_unit",
    "make_signal",
    "run_loop",
    "simulate",
]
