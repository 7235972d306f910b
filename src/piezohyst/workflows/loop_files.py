"""``piezohyst simulate-loop``: a controller run on a simulated actuator (the bench, a plant of
other physics, or a lab's own model standing in for its actuator).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._validation import FloatArray, check_float, check_int
from ..control.compensator import CompensatorSettings
from ..control.selfsensing import LoopSettings
from ..errors import ParameterError
from ..io import (
    read_table,
    write_table,
)
from ..metrics import hysteresis_width, nrmse
from ..simulation import (
    DEFAULT_PRESET,
    PRESETS,
    Bench,
    BenchRecord,
    ModelPlant,
    PlantRun,
    run_loop,
    run_on_model,
)
from ..units import to_standard
from ._base import (
    _DEFAULT_SETTINGS,
    PathLike,
    _desired_column,
    _load,
    check_rate,
    desired_unit,
    guard_outputs,
    standard_column,
    time_rate,
)

__all__ = ["LoopRun", "simulate_loop_file"]


@dataclass(frozen=True)
class LoopRun:
    """What :func:`simulate_loop_file` did.

    Attributes
    ----------
    record : BenchRecord
        Commands, readings and the bench's hidden truth.
    desired : ndarray
        The desired trajectory.
    width : float
        Hysteresis width desired → laser displacement (fraction of the span), from the
        sample the commands reached the trajectory on (see ``arrived``).
    nrmse : float
        Tracking NRMSE desired → laser displacement (displacement domain; else NaN), the same.
    saturated : int
        Commands clipped to the limits.
    arrived : int
        Samples before the commands reached the trajectory (the ramp from rest at the slew
        limit), left out of ``width`` and ``nrmse``: the ramp's error is the limit's, not the
        controller's (on the bench's 5-35 um target, 9 % NRMSE with it, 0.8 % without).
    plant : str
        Which actuator ran: the built-in bench (another actuator than a lab's), or the
        model file standing in for the lab's.
    """

    record: BenchRecord | PlantRun
    desired: FloatArray
    width: float
    nrmse: float
    saturated: int
    arrived: int = 0
    plant: str = ""


def simulate_loop_file(
    model_path: PathLike,
    target: PathLike,
    out: PathLike,
    *,
    column: str | None = None,
    settings: CompensatorSettings = _DEFAULT_SETTINGS,
    loop: LoopSettings | None = None,
    preset: str = DEFAULT_PRESET,
    extra_bias: float = 0.0,
    seed: int = 0,
    force: bool = False,
    plant: PathLike | None = None,
) -> LoopRun:
    """Run a desired trajectory through a controller against the simulated bench, or
    against a model standing in for the lab's actuator (``plant``).

    Writes ``time, desired, command, charge, displacement`` (s, desired
    units, V, C, m): what the bench read after each command. ``loop=None``
    runs the feedforward compensator alone, otherwise the self-sensing
    controller. ``extra_bias`` (A) adds to the preset's amplifier bias
    current, a change the model never saw.

    Parameters
    ----------
    model_path, target, out : path
        A saved model, the desired trajectory (``time`` and ``desired``), the output.
    column : str, optional
        The desired column.
    settings : CompensatorSettings
        Limits, domain, gain, slew; the sample rate defaults to the preset's.
    loop : LoopSettings, optional
        The controller's settings; None: feedforward alone.
    preset : str
        Bench preset.
    extra_bias : float
        A (added to the preset's bias current).
    seed : int
        Noise seed.
    force : bool
        Replace an existing ``out`` that piezohyst did not write.
    plant : path, optional
        A saved model standing in for the actuator (:class:`~piezohyst.simulation.ModelPlant`:
        the lab's own, not the built-in bench's physics; no noise). ``preset``,
        ``extra_bias`` and ``seed`` are the bench's and not used with it; the sample rate
        is the settings' (default the model's training record's).

    Returns
    -------
    LoopRun
        ``plant_name`` says which actuator ran.
    """
    inputs: list[PathLike] = [model_path, target]
    if plant is not None:
        inputs.append(plant)
    if loop is not None and loop.leakage is not None:
        inputs.append(loop.leakage)
    guard_outputs([out], inputs, force=force)
    if preset not in PRESETS:
        msg = f"unknown preset {preset!r}; available: {', '.join(PRESETS)}"
        raise ParameterError(msg)
    p = PRESETS[preset]
    p = dataclasses.replace(
        p, i_bias=p.i_bias + check_float(extra_bias, "extra_bias", "simulate-loop", -1e-6, 1e-6)
    )
    model = _load(model_path)
    table = read_table(target)
    name = _desired_column(table, column, target)
    desired = standard_column(table, name, "desired trajectory", "output",
                              desired_unit(settings, model))  # fmt: skip
    if plant is not None:  # the lab's plant runs at the loop's rate: the settings' or the target's
        rate = settings.sample_rate
        if rate is None and "time" in table:
            times = table.get("time")
            rate = time_rate(to_standard(times, table.unit("time"), "time", f"{target}: 'time'")[0])
        if rate is None:
            msg = f"{target} has no time column: give the loop's rate (--sample-rate)"
            raise ParameterError(msg)
        p = dataclasses.replace(p, rate=float(rate))
    fs = settings.sample_rate or p.rate
    if abs(fs - p.rate) > 1e-9 * p.rate:
        msg = f"the bench {preset} samples at {p.rate:g} Hz; the loop rate must be the same"
        if plant is not None:
            msg = f"{target} is timed at {p.rate:g} Hz; the loop rate must be the same"
        raise ParameterError(msg)
    if "time" in table:  # a target timed at another rate would be played at the bench's
        t = to_standard(table.get("time"), table.unit("time"), "time", f"{target}: column 'time'")
        played = "the target would be played at the bench's rate; resample it to that rate"
        check_rate(
            target, time_rate(t[0]), fs, f" and the bench {preset} samples at {fs:g} Hz: {played}"
        )
    settings = dataclasses.replace(settings, sample_rate=fs)
    ctl = settings.build(model) if loop is None else loop.build(settings, model)
    rec: BenchRecord | PlantRun
    if plant is None:
        bench = Bench(p, voltage=ctl.last_command,
                      seed=check_int(seed, "seed", "simulate-loop", 0, 2**32 - 1))  # fmt: skip
        rec = run_loop(ctl, desired, bench)
        name = (f"the built-in bench {preset!r} (another actuator than yours: "
                "--plant MODEL runs your own model as the plant)")  # fmt: skip
    else:
        stand_in = ModelPlant(_load(plant), fs, voltage=ctl.last_command,
                              gain=settings.output_map or settings.gain)  # fmt: skip
        rec = run_on_model(ctl, desired, stand_in)
        name = f"{Path(plant).name}, {stand_in.describe()}"
    write_table(
        out,
        {
            "time": rec.t,
            "desired": desired,
            "command": rec.voltage,
            "charge": rec.charge,
            "displacement": rec.displacement,
        },
        units={
            "time": "s",
            "desired": "m" if settings.domain == "displacement" else model.output_unit,
            "command": "V",
            "charge": "C",
            "displacement": "m",
        },
    )
    arrived = ctl.sent_count - ctl.command_count  # the ramp from rest at the slew limit
    ok = np.isfinite(desired)
    ok[:arrived] = False
    shown = rec.hysteresis if isinstance(rec, PlantRun) else rec.displacement
    width = hysteresis_width(desired[ok], shown[ok])
    err = (
        nrmse(desired[ok], rec.displacement[ok]) if settings.domain == "displacement" else math.nan
    )
    return LoopRun(rec, desired, width, err, ctl.saturated_count, arrived, name)
