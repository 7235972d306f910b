"""``piezohyst simulate`` and ``piezohyst excite``: the records the other commands read (a
simulated bench run, or the voltage a lab plays on its rig)."""

from __future__ import annotations

import dataclasses

from .._validation import check_float, check_int
from ..errors import (
    ParameterError,
)
from ..io import (
    write_table,
)
from ..simulation import DEFAULT_PRESET, PRESETS, BenchRecord, batch_unit, simulate
from ._base import (
    PathLike,
    command_gain,
    guard_outputs,
)
from .excitation import Excitation


def simulate_file(
    out: PathLike,
    *,
    preset: str = DEFAULT_PRESET,
    signal: str = "hold",
    amplitude: float | None = None,
    frequency: float = 0.5,
    duration: float = 20.0,
    rate: float | None = None,
    seed: int = 0,
    unit: int = 0,
    force: bool = False,
) -> BenchRecord:
    """Run the simulated bench and write ``time,voltage,charge,displacement`` (s, V, C, m).

    ``seed`` seeds the noise; ``unit`` picks an actuator of a production batch (0: the
    preset; see :func:`piezohyst.simulation.batch_unit`). ``force`` replaces an existing
    file piezohyst did not write (see :func:`guard_outputs`).

    Parameters
    ----------
    out : str or path
        The file to write (CSV, or by its suffix).
    preset : str
        A name of :data:`piezohyst.simulation.PRESETS`.
    signal, amplitude, frequency, duration, rate
        As :func:`piezohyst.simulation.make_signal` (amplitude and rate default to the
        preset's).
    seed, unit : int
    force : bool, default False

    Returns
    -------
    BenchRecord
        What was simulated and written.
    """
    guard_outputs([out], [], force=force)
    if preset not in PRESETS:
        msg = f"unknown preset {preset!r}; available: {', '.join(PRESETS)}"
        raise ParameterError(msg)
    p = batch_unit(preset, check_int(unit, "unit", "simulate", 0, 2**32 - 1))
    if rate is not None:
        p = dataclasses.replace(
            p, rate=check_float(rate, "rate", "simulate", 0.0, 1e7, low_open=True)
        )
    rec = simulate(
        preset=p,
        signal=signal,
        amplitude=amplitude,
        frequency=frequency,
        duration=duration,
        seed=check_int(seed, "seed", "simulate", 0, 2**32 - 1),
    )
    write_table(
        out,
        {
            "time": rec.t,
            "voltage": rec.voltage,
            "charge": rec.charge,
            "displacement": rec.displacement,
        },
        units={"time": "s", "voltage": "V", "charge": "C", "displacement": "m"},
    )
    return rec


def excite_file(
    out: PathLike,
    exc: Excitation,
    *,
    force: bool = False,
    command_scale: str | float | None = None,
) -> Excitation:
    """Write an excitation to play on the rig: ``time,voltage`` (s, V), or a column
    ``voltage_0``, ``voltage_1``, ... per actuator, as CSV, MAT, TDMS, NPZ or Parquet.

    Parameters
    ----------
    out : str or os.PathLike
        The file; its suffix picks the format.
    exc : Excitation
        What :func:`piezohyst.workflows.excitation.excitation` made.
    force : bool, default False
        Replace an existing file piezohyst did not write (see :func:`guard_outputs`).
    command_scale : str or float, optional
        The amplifier's gain: the voltage is written in the volts the DAQ plays (the
        piezo's divided by it; :func:`~piezohyst.workflows._base.command_gain`).

    Returns
    -------
    Excitation
        ``exc``, written.
    """
    gain = command_gain(command_scale)
    guard_outputs([out], [], force=force)
    v = exc.voltage / gain
    volts = {"voltage": v} if v.ndim == 1 else {f"voltage_{q}": v[:, q] for q in range(v.shape[1])}
    write_table(out, {"time": exc.t, **volts}, units={"time": "s", **dict.fromkeys(volts, "V")})
    return exc
