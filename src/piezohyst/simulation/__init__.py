"""The simulated bench: actuator, charge circuit, sensors and excitation signals; a coupled
stage of several benches (``stage``: :func:`simulate_stage` in one run, :class:`Stage` and
:func:`run_stage_loop` one sample at a time for a stage's closed loops)."""

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
from .stage import (
    XY_COUPLING,
    XY_DYNAMIC,
    Stage,
    StageReading,
    StageRecord,
    run_stage_loop,
    simulate_stage,
)

__all__ = [
    "DEFAULT_PRESET",
    "PLANTS",
    "PRESETS",
    "SIGNALS",
    "XY_COUPLING",
    "XY_DYNAMIC",
    "Bench",
    "BenchPreset",
    "BenchRecord",
    "ModelPlant",
    "PlantRun",
    "Reading",
    "Stage",
    "StageReading",
    "StageRecord",
    "batch_unit",
    "make_signal",
    "run_loop",
    "run_on_model",
    "run_stage_loop",
    "simulate",
    "simulate_stage",
]
