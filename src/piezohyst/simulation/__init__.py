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
from .model_plant import ModelPlant, PlantRun, run_on_model
from .signals import SIGNALS, make_signal

__all__ = [
    "DEFAULT_PRESET",
    "PLANTS",
    "PRESETS",
    "SIGNALS",
    "Bench",
    "BenchPreset",
    "BenchRecord",
    "ModelPlant",
    "PlantRun",
    "Reading",
    "batch_unit",
    "make_signal",
    "run_loop",
    "run_on_model",
    "simulate",
]
