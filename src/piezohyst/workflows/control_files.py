"""File workflows around a fitted model: compensate, export C, calibrate leakage, run the
closed loop on the bench, report. Each is one call of a CLI command (see
:mod:`piezohyst.workflows`, which re-exports them).
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import math
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from .._validation import FloatArray, check_float, check_int
from ..control.calibration import OutputMap, calibrate_gain
from ..control.compensator import Compensator, CompensatorSettings
from ..control.export import Precision, c_paths, write_c
from ..control.fmu import write_fmu
from ..control.selfsensing import LoopSettings
from ..control.shared import write_mex, write_shared
from ..errors import DataFileError, ExtrapolationWarning, LimitWarning, ParameterError
from ..io import (
    DataSpec,
    Table,
    atomic_folder,
    check_finite,
    check_increasing,
    open_table,
    read_table,
    write_blocks,
    write_table,
)
from ..metrics import hysteresis_width, nrmse, rmse, run_on
from ..model.leakage import LEAKAGE_TERMS, Leakage, calibrate_leakage
from ..model.model import HysteresisModel
from ..model.state import predict_record
from ..simulation import DEFAULT_PRESET, PRESETS, Bench, BenchRecord, run_loop
from ..units import to_standard
from ._base import (
    _DEFAULT_SETTINGS,
    ONE_RATE,
    PathLike,
    Progress,
    _check_measured_unit,
    _default_unit,
    _load,
    check_folder,
    check_rate,
    command_gain,
    desired_unit,
    guard_outputs,
    standard_column,
    time_rate,
    warn_assumed_span,
    warn_clipped,
)

__all__ = [
    "Compensation",
    "LoopRun",
    "ReportResult",
    "calibrate_gain_file",
    "calibrate_leakage_file",
    "compensate_file",
    "export_c_file",
    "export_fmu_file",
    "model_report",
    "simulate_loop_file",
]


@dataclass(frozen=True)
class Compensation:
    """What :func:`compensate_file` did.

    Attributes
    ----------
    compensator : Compensator
        After the run: limits used, counters of saturated and non-finite samples.
    preamble : int
        Samples of ramp-in and preconditioning written before the trajectory.
    sample_rate : float
        Samples per second of the written commands (Hz).
    """

    compensator: Compensator
    preamble: int
    sample_rate: float


def compensate_file(
    model_path: PathLike,
    target: PathLike,
    out: PathLike,
    *,
    column: str | None = None,
    settings: CompensatorSettings = _DEFAULT_SETTINGS,
    precondition: bool = True,
    present_voltage: float | None = None,
    target_unit: str | None = None,
    target_offset: float = 0.0,
    force: bool = False,
    progress: Progress = None,
    command_scale: str | float | None = None,
) -> Compensation:
    """Feedforward voltage for a desired trajectory; writes ``time,command,desired``.

    Safe by default, as a lab running an amplifier needs:

    * commands stay inside the limits, which default to the voltages the model
      was identified on; limits beyond them are refused unless
      ``settings.allow_extrapolation``;
    * the slew limit defaults to the fastest change of the training record
      (``model.max_slew_rate_``);
    * the file starts with a ramp from the actuator's present voltage
      (default: at rest, 0 V or the nearer limit) and a precondition cycle
      over the voltages the trajectory needs, 10 % beyond them (inside the
      limits), that wipes out the unknown history (rows with an empty
      ``desired``); ``precondition=False`` keeps only the ramp;
    * NaN or infinite desired values hold the last command and are counted;
    * a trajectory that saturates most samples (out of reach: units, or the
      sign of the gain), or whose commands the slew limit holds mostly (faster than the
      amplifier or the training record), is an error, and nothing is written.

    Parameters
    ----------
    model_path : str or os.PathLike
        A saved model.
    target : str or os.PathLike
        The desired trajectory with its ``time`` column (s), or give
        ``settings.sample_rate``.
    out : str or os.PathLike
        Where to write the commands.
    column : str, optional
        The desired column (default ``desired``, or the only one besides ``time``).
    settings : CompensatorSettings
        Limits, domain, gain, slew rate, sample rate, extrapolation.
    precondition : bool, default True
        Write the precondition cycle before the trajectory.
    present_voltage : float, optional
        The actuator's voltage now (V); default at rest: 0 V, or the nearer limit.
    target_unit : str, optional
        The desired column's unit (``um``, ``nm``, ``uC``) when its header names
        none; a header naming another is an error.
    target_offset : float, default 0
        Added to every desired value, in the target's unit: a target written
        relative to another zero (the written ``desired`` column includes it).
    force : bool, default False
        Replace an existing ``out`` that piezohyst did not write.
    progress : callable, optional
        Called with the rows of the target read so far.
    command_scale : str or float, optional
        The amplifier's gain (piezo V per V the DAQ plays): the command column is written
        divided by it; the limits and the slew rate stay the piezo's.

    Returns
    -------
    Compensation
    """
    gain = command_gain(command_scale)
    guard_outputs([out], [model_path, target], force=force)
    model = _load(model_path)
    table = open_table(target)
    name = _desired_column(table, column, target)
    expected = "m" if settings.domain == "displacement" else model.output_unit
    where = f"{target}: column {name!r}"
    source_unit = table.unit(name) or target_unit
    if table.unit(name) is not None and target_unit is not None and table.unit(name) != target_unit:
        msg = (
            f"{target}: column {name!r} is marked {table.unit(name)!r} in the file, but the "
            f"target's unit was given as {target_unit!r}"
        )
        raise DataFileError(msg)
    if not math.isfinite(target_offset):
        msg = f"the target offset must be finite. Got {target_offset}."
        raise ParameterError(msg)

    def desired_of(values: FloatArray) -> FloatArray:
        return to_standard(values + target_offset, source_unit, "output", where)[0]

    unit = to_standard(np.empty(0), source_unit, "output", where)[1]
    if unit is not None and unit != expected:
        msg = f"{target}: the desired column is in {unit!r}, the compensator expects {expected!r}"
        raise DataFileError(msg)
    timed = "time" in table
    if not timed and settings.sample_rate is None:
        msg = (
            f"{target}: no time column; the commands need their sample times: add a 'time' "
            "column (s) or give the sample rate"
        )
        raise DataFileError(msg)
    keys = [name, "time"] if timed else [name]
    batches = table.batches(keys)
    head = next(batches)  # the sample rate comes from the first batch
    t_unit = table.unit("time") if timed else None
    fs = settings.sample_rate
    if timed:
        file_fs = time_rate(
            to_standard(head["time"], t_unit, "time", f"{target}: column 'time'")[0]
        )
        if fs is not None:
            check_rate(target, file_fs, fs, f", and the sample rate given is {fs:g} Hz: {ONE_RATE}")
        fs = fs if fs is not None else (file_fs if file_fs is not None else 1.0)
    assert fs is not None  # untimed without a rate was refused above
    comp = dataclasses.replace(settings, sample_rate=fs).build(model)  # slew: "trained"
    start = present_voltage
    if start is None:  # at rest: 0 V, or the nearer limit
        start = float(np.clip(0.0, comp.v_min, comp.v_max))
    comp.reset(voltage=start)
    preamble = np.empty(0)
    if precondition:  # a cycle over what the trajectory needs, with a margin
        span = _needed_span(comp, lambda: (desired_of(b[name]) for b in table.batches(keys)))
        preamble = comp.precondition(max(3, round(fs)), span)
    finite = 0

    def rows() -> Iterator[dict[str, FloatArray]]:
        nonlocal finite
        row = 0
        t_last: float | None = None
        for batch in itertools.chain([head], batches):
            desired = desired_of(batch[name])
            if timed:
                check_finite(batch["time"], row, f"{target}", "time")
                check_increasing(batch["time"], t_last, row, f"{target}", "time")
                t_last = float(batch["time"][-1])
                t = to_standard(batch["time"], t_unit, "time", f"{target}: column 'time'")[0]
            else:
                t = (row + np.arange(desired.size, dtype=np.float64)) / fs
            if row == 0 and preamble.size:
                n = preamble.size
                yield {  # k / fs from the first time: -1.001, not -1.001000000000001
                    "time": t[0] + np.arange(-n, 0) / fs,
                    "command": preamble / gain,
                    "desired": np.full(n, np.nan),  # written empty: nothing is desired there
                }
            finite += int(np.count_nonzero(np.isfinite(desired)))
            yield {"time": t, "command": comp.process(desired) / gain, "desired": desired}
            row += desired.size
            if progress is not None:
                progress(row)
        if finite and comp.saturated_count > 0.5 * finite:  # before the file is renamed into place
            lo, hi = _reachable(model, comp, settings)
            unit = "m" if settings.domain == "displacement" else model.output_unit
            msg = (
                f"{target}: {comp.saturated_count} of {finite} desired values "
                f"({100 * comp.saturated_count / finite:.0f} %) are out of reach of "
                f"[{comp.v_min:g}, {comp.v_max:g}] V, which reaches about [{lo:.4g}, {hi:.4g}] "
                f"{unit}; check the units and the sign of the gain"
            )
            raise ParameterError(msg)
        slewed = comp.slew_limited_count + comp.approach_count
        if finite and slewed > 0.5 * finite:  # mostly cut by the slew limit: not the target
            rate = comp.max_step * fs
            msg = (
                f"{target}: the slew limit ({rate:.4g} V/s) held {slewed} of {finite} commands "
                f"({100 * slewed / finite:.0f} %): the trajectory is faster than the limit (by "
                "default the training record's fastest change); set --slew-rate to what the "
                "amplifier allows, or slow the target"
            )
            raise ParameterError(msg)

    write_blocks(out, rows(), units={"time": "s", "command": "V", "desired": expected},
                 blank=("desired",))  # fmt: skip
    return Compensation(comp, preamble.size, fs)


#: The precondition cycle reaches this fraction of the trajectory's own voltage span beyond it
PRECONDITION_MARGIN = 0.1


def _needed_span(
    comp: Compensator, desired: Callable[[], Iterator[FloatArray]]
) -> tuple[float, float]:
    """The voltages a trajectory's commands cover, with a margin, inside the limits, found by
    dry runs on copies: first from where the commands start, then after a cycle over that
    span, as the real run will send them (grown to cover both); the whole limits when the
    commands have no finite value.

    The dry run had started after a cycle over the whole range: on an actuator that keeps a
    large remanence (the bench's, 52 um at 0 V after a full cycle), a target below it looked
    out of reach, the real cycle then covered the whole range too and made it so."""
    span = _commands_span(comp, desired(), None)
    for _ in range(2):  # a cycle over the span moves the commands a little: cover them too
        if span is None:
            break
        after = _commands_span(comp, desired(), span)
        if after is None or (span[0] <= after[0] and after[1] <= span[1]):
            break
        span = (min(span[0], after[0]), max(span[1], after[1]))
    return (comp.v_min, comp.v_max) if span is None else span


def _commands_span(
    comp: Compensator, desired: Iterator[FloatArray], cycle: tuple[float, float] | None
) -> tuple[float, float] | None:
    """A dry run's commands on a copy (after a precondition cycle over ``cycle`` if given):
    their span with :data:`PRECONDITION_MARGIN`, inside the limits; None when none is finite."""
    probe = copy.deepcopy(comp)
    if cycle is not None:
        probe.precondition(3, cycle)
    lo, hi = math.inf, -math.inf
    with warnings.catch_warnings():  # limits that bite and extrapolation: said once, by the
        warnings.simplefilter("ignore", LimitWarning)  # real run, with its own counts
        warnings.simplefilter("ignore", ExtrapolationWarning)
        for values in desired:
            commands = probe.process(values)
            lo, hi = min(lo, float(commands.min())), max(hi, float(commands.max()))
    if not lo < hi:
        return None
    margin = PRECONDITION_MARGIN * (hi - lo)
    return max(comp.v_min, lo - margin), min(comp.v_max, hi + margin)


def _desired_column(table: Table, column: str | None, target: PathLike) -> str:
    """The desired trajectory's column: as named, else ``desired``, else the only one but time."""
    if column is None:
        others = [c for c in table.columns if c != "time"]
        column = "desired" if "desired" in table else (others[0] if len(others) == 1 else None)
        if column is None:
            msg = (
                f"{target}: which column is the desired trajectory? Name it 'desired' or name "
                f"the column (columns: {', '.join(map(repr, table.columns))})"
            )
            raise DataFileError(msg)
    return table.resolve(column)


#: Samples each voltage is held for when estimating what the limits reach
REACH_HOLD = 64


def _reachable(
    model: HysteresisModel, comp: Compensator, settings: CompensatorSettings
) -> tuple[float, float]:
    """Roughly the desired values the limits reach: the outputs at v_min and v_max from rest.

    Each voltage is held for :data:`REACH_HOLD` samples 1e4 s apart: creep terms settle, and
    an input delay of a few samples (which shifts the output by samples, not seconds) has
    passed; each level's last output counts (with one sample each, a delayed model's reach
    was the previous level's)."""
    h = model.hysteresis_
    x0 = float(model.initial_state_[0])
    x = np.repeat([x0, comp.v_min, comp.v_max], REACH_HOLD)
    y = h.predict(x, t=np.arange(x.size) * 1e4)
    rest, low, high = y[REACH_HOLD - 1 :: REACH_HOLD]
    values = np.array([low, high])
    if settings.output_map is not None:
        values = settings.output_map.predict(values)
    elif settings.domain == "displacement" and settings.gain is not None:
        values = settings.gain * (values - rest)
    return float(values.min()), float(values.max())


def export_c_file(
    model_path: PathLike,
    out: PathLike,
    *,
    settings: CompensatorSettings = _DEFAULT_SETTINGS,
    precision: Precision = "double",
    controller: LoopSettings | None = None,
    force: bool = False,
    shared: bool = False,
    mex: bool = False,
) -> tuple[Path, ...]:
    """Write ``NAME.c`` and ``NAME.h`` for the model's compensator (:mod:`~.control.export`).

    Parameters
    ----------
    model_path : str or os.PathLike
        A saved model.
    out : str or os.PathLike
        The ``.c`` file.
    settings : CompensatorSettings
        Limits, domain, gain, slew rate (and the sample rate a controller needs).
    precision : {"double", "float"}
        The C type of every real.
    controller : LoopSettings, optional
        Export the self-sensing controller instead of the feedforward compensator.
    force : bool, default False
        Replace existing files piezohyst did not write.
    shared : bool, default False
        Add the shared-library API and build ``libNAME.so`` beside the sources
        (:mod:`~piezohyst.control.shared`).
    mex : bool, default False
        ``out`` is a MEX gateway (``NAME_mex.c``), written with the step it includes.

    Returns
    -------
    tuple of Path
        Source and header (and the library).
    """
    c_path, h_path, _ = c_paths(out)
    inputs: list[PathLike] = [model_path]
    if controller is not None and controller.leakage is not None:
        inputs.append(controller.leakage)
    guard_outputs([c_path, h_path], inputs, force=force)
    model = _load(model_path)
    built = settings.build(model) if controller is None else controller.build(settings, model)
    if shared and mex:
        msg = "--shared and --mex build different things: choose one"
        raise ParameterError(msg)
    if shared:
        return write_shared(built, out, precision=precision)
    if mex:
        return write_mex(built, out, precision=precision)
    return write_c(built, out, precision=precision)


def calibrate_leakage_file(
    data: PathLike,
    out: PathLike | None = None,
    *,
    data_spec: DataSpec | None = None,
    terms: Sequence[str] = LEAKAGE_TERMS,
    min_duration: float = 1.0,
    settle: float | str = "auto",
    force: bool = False,
) -> Leakage:
    """Calibrate the leakage from the holds of a record and save it (JSON) to ``out``.

    Parameters
    ----------
    data : str or os.PathLike
        A record with constant-voltage holds (voltage, charge, time).
    out : str or os.PathLike, optional
        Where to save the leakage.
    data_spec : DataSpec, optional
        Columns, units and window.
    terms : sequence of str
        Leakage terms to fit (see :func:`~piezohyst.model.leakage.calibrate_leakage`).
    min_duration, settle
        Hold detection and trim (see :func:`~piezohyst.model.leakage.calibrate_leakage`).
    force : bool
        Replace an existing ``out`` that piezohyst did not write.

    Returns
    -------
    Leakage
    """
    if out is not None:
        guard_outputs([out], [data], force=force)
    rec = (data_spec or DataSpec()).read(data)
    assert rec.y is not None
    w = rec.window
    x_unit, y_unit = rec.units
    leak = calibrate_leakage(
        rec.t[w],
        rec.x[w],
        rec.y[w],
        terms=terms,
        min_duration=min_duration,
        settle=settle,
        input_unit=x_unit or "V",
        output_unit=y_unit or _default_unit(rec.names[1]),
    )
    if out is not None:
        leak.save(out)
    return leak


def export_fmu_file(
    model_path: PathLike,
    out: PathLike,
    *,
    settings: CompensatorSettings = _DEFAULT_SETTINGS,
    precision: Precision = "double",
    controller: LoopSettings | None = None,
    force: bool = False,
) -> Path:
    """Write an FMI 2.0 Co-Simulation FMU of the model's compensator (:mod:`~.control.fmu`).

    Parameters
    ----------
    model_path : str or os.PathLike
        A saved model.
    out : str or os.PathLike
        The ``.fmu`` file.
    settings : CompensatorSettings
        Limits, domain, gain, slew rate and the sample rate (one step of the FMU).
    precision : {"double", "float"}
    controller : LoopSettings, optional
        The self-sensing controller instead of the feedforward compensator.
    force : bool, default False
        Replace an existing file piezohyst did not write.

    Returns
    -------
    Path
    """
    if Path(out).exists() and not force and not _our_fmu(Path(out)):
        msg = f"{out} exists and piezohyst did not write it: pass --force to replace it"
        raise ParameterError(msg)
    model = _load(model_path)
    built = settings.build(model) if controller is None else controller.build(settings, model)
    return write_fmu(built, out, precision=precision)


def _our_fmu(path: Path) -> bool:
    """An FMU piezohyst wrote (its modelDescription names the tool): safe to replace."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as z:
            return 'generationTool="piezohyst' in z.read("modelDescription.xml").decode()
    except (OSError, KeyError, zipfile.BadZipFile, UnicodeDecodeError):
        return False


def _sensor_spec(
    spec: DataSpec, column: str, unit: str | None, scale: str | float | None
) -> DataSpec:
    """``spec`` reading the displacement sensor's column as its output: its own unit and
    scale (never the charge channel's)."""
    return dataclasses.replace(spec, output_column=column, output_unit=unit, output_scale=scale)


def calibrate_gain_file(
    model_path: PathLike,
    data: PathLike,
    out: PathLike | None = None,
    *,
    displacement_column: str = "displacement",
    displacement_unit: str | None = None,
    displacement_scale: str | float | None = None,
    data_spec: DataSpec | None = None,
    force: bool = False,
) -> OutputMap:
    """Calibrate the charge -> displacement map from a record with a displacement sensor
    (voltage, charge and displacement sampled together) and save it (JSON) to ``out``.

    Parameters
    ----------
    model_path : str or os.PathLike
        A model fitted on voltage -> charge.
    data : str or os.PathLike
        The record: its voltage, charge and time columns as ``data_spec`` names them,
        and the displacement column.
    out : str or os.PathLike, optional
        Where to save the map.
    displacement_column : str, default "displacement"
    displacement_unit : str, optional
        Its unit if its header does not say (um, nm, m...); converted to m.
    displacement_scale : str or float, optional
        What one unit of it is worth, for a sensor logged in V (``"10 um/V"``).
    data_spec : DataSpec, optional
        Columns, units, scales and window of the voltage and charge.
    force : bool
        Replace an existing ``out`` that piezohyst did not write.

    Returns
    -------
    OutputMap
    """
    if out is not None:
        guard_outputs([out], [data, model_path], force=force)
    model = _load(model_path)
    spec = data_spec or DataSpec()
    rec = spec.read(data)
    sensor = _sensor_spec(spec, displacement_column, displacement_unit, displacement_scale).read(
        data
    )
    if rec.t is None:
        msg = f"{data}: calibrate-gain needs the time column (or --sample-rate)"
        raise DataFileError(msg)
    assert rec.y is not None and sensor.y is not None
    w = rec.window
    unit = sensor.units[1] or "m"
    if sensor.units[1] is None:
        span = float(np.ptp(sensor.y[w]))
        warn_assumed_span(span, "m", displacement_column, data, "--displacement-unit")
    om = calibrate_gain(model, rec.x[w], rec.y[w], sensor.y[w], rec.t[w], output_unit=unit)
    if out is not None:
        om.save(out)
    return om


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
    """

    record: BenchRecord
    desired: FloatArray
    width: float
    nrmse: float
    saturated: int
    arrived: int = 0


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
) -> LoopRun:
    """Run a desired trajectory through a controller against the simulated bench.

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

    Returns
    -------
    LoopRun
    """
    inputs: list[PathLike] = [model_path, target]
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
    fs = settings.sample_rate or p.rate
    if abs(fs - p.rate) > 1e-9 * p.rate:
        msg = f"the bench {preset} samples at {p.rate:g} Hz; the loop rate must be the same"
        raise ParameterError(msg)
    if "time" in table:  # a target timed at another rate would be played at the bench's
        t = to_standard(table.get("time"), table.unit("time"), "time", f"{target}: column 'time'")
        played = "the target would be played at the bench's rate; resample it to that rate"
        check_rate(
            target, time_rate(t[0]), fs, f" and the bench {preset} samples at {fs:g} Hz: {played}"
        )
    settings = dataclasses.replace(settings, sample_rate=fs)
    ctl = settings.build(model) if loop is None else loop.build(settings, model)
    bench = Bench(
        p, voltage=ctl.last_command, seed=check_int(seed, "seed", "simulate-loop", 0, 2**32 - 1)
    )
    rec = run_loop(ctl, desired, bench)
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
    width = hysteresis_width(desired[ok], rec.displacement[ok])
    err = (
        nrmse(desired[ok], rec.displacement[ok]) if settings.domain == "displacement" else math.nan
    )
    return LoopRun(rec, desired, width, err, ctl.saturated_count, arrived)


@dataclass(frozen=True)
class ReportResult:
    """Metrics and files written by :func:`model_report`.

    Attributes
    ----------
    metrics : dict
        Metric key to value (units in ``metrics.json``).
    files : list of Path
        Figures, ``metrics.json``, ``report.md`` and ``report.html``.
    """

    metrics: dict[str, Any]
    files: list[Path]


def model_report(
    model_path: PathLike,
    data: PathLike,
    out: PathLike,
    *,
    data_spec: DataSpec | None = None,
    command: str | None = None,
    force: bool = False,
    progress: Progress = None,
    gain: float | OutputMap | None = None,
    displacement_column: str | None = None,
    displacement_unit: str | None = None,
    displacement_scale: str | float | None = None,
) -> ReportResult:
    """A report a lab can file on a model and a data file (HTML, Markdown, JSON, figures).

    With ``gain`` (m/C, or the map :func:`calibrate_gain` identified) the report adds
    the displacement the model predicts from the voltage (its capacitor charge, growth
    removed, through the map), in metres; with ``displacement_column`` too, scored
    against that sensor (the map's delay applied).

    Parameters
    ----------
    model_path : str or os.PathLike
        A saved model.
    data : str or os.PathLike
        The recording to check it on.
    out : str or os.PathLike
        The report folder; an existing one that does not hold a piezohyst
        report is refused unless ``force`` (see :func:`guard_outputs`).
    data_spec : DataSpec, optional
        Columns, units and time window.
    command : str, optional
        The command line that made the report, recorded in it.
    force : bool, default False
        Replace an existing folder piezohyst did not write.
    progress : callable, optional
        Called with the rows read so far.
    gain : float or OutputMap, optional
        From the capacitor charge to displacement.
    displacement_column : str, optional
        A displacement sensor's column to score the displacement against (needs ``gain``).
    displacement_unit : str, optional
        Its unit if its header does not say (um, nm, m...); converted to m.
    displacement_scale : str or float, optional
        What one unit of it is worth, for a sensor logged in V (``"10 um/V"``).

    Returns
    -------
    ReportResult
    """
    from ..analysis.report import Report

    guard_outputs(
        [check_folder(out, "the figures and the report")], [model_path, data], force=force
    )
    spec = data_spec or DataSpec()
    model = _load(model_path)
    if displacement_column is not None and gain is None:
        msg = ("a displacement column is scored through the map from charge to displacement: "
               "give the gain (m/C) or the map calibrate-gain wrote")  # fmt: skip
        raise ParameterError(msg)
    rec = spec.read(data, progress=progress)
    sensor = None
    if displacement_column is not None:
        sensor = _sensor_spec(
            spec, displacement_column, displacement_unit, displacement_scale
        ).read(data)
    w = rec.window  # the model runs over the whole record: the window's start has a history
    end = rec.x.size if w.stop is None else w.stop  # nothing after the window is run
    pred = predict_record(model, rec.x[:end], rec.t[:end])[w]
    assert rec.y is not None
    _check_measured_unit(rec.units[1], model, data)
    x, y, t = rec.x[w], rec.y[w], rec.t[w]
    warn_clipped([y], rec.names[1], rec.units[1], data)
    with atomic_folder(out) as folder:  # all or nothing: Ctrl-C leaves no partial folder
        rep = _report(model, rec, pred, Report(f"{type(model).__name__} on {Path(data).name}",
                      folder), (x, y, t), (model_path, data, command))  # fmt: skip
        if gain is not None:
            charge = model.hysteresis_.predict(rec.x[:end], t=rec.t[:end])[w]
            measured = None if sensor is None or sensor.y is None else sensor.y[w]
            _in_metres(rep, x, t, charge, gain, measured)
        files = [Path(out) / f.name for f in rep.write()]
    return ReportResult({m.key: m.value for m in rep.metrics}, files)


def _report(
    model: HysteresisModel,
    rec: Any,
    pred: FloatArray,
    rep: Any,
    xyt: tuple[FloatArray, FloatArray, FloatArray],
    sources: tuple[PathLike, PathLike, str | None],
) -> Any:
    """The report's metadata, tables, metrics and figures (written by the caller)."""
    from ..analysis.report import file_facts

    x, y, t = xyt
    model_path, data, command = sources
    w = rec.window
    in_u, out_u = model.input_unit, model.output_unit
    rep.metadata = {
        "written": datetime.now(UTC).isoformat(timespec="seconds"),
        "command": command or "(called from Python)",
        "data_file": file_facts(data),
        "model_file": file_facts(model_path),
        "columns": dict(zip(("input", "output", "time"), rec.names, strict=True)),
        "time_window_s": [float(t[0]), float(t[-1])],
        "units": {"input": in_u, "output": out_u, "time": "s"},
    }
    rep.tables["Model"] = [
        ("class", type(model).__name__),
        *[(f"setting {k}", _setting(v)) for k, v in model.params_to_json().items()],
        *model.operator_.describe(in_u, out_u),
        (
            "training input range",
            f"{model.input_range_[0]:.6g} to {model.input_range_[1]:.6g} {in_u}",
        ),
        *[(k, f"{v:.6g} {u}") for k, (v, u) in model.coefficients().items()],
        (
            "input dynamics",
            "none"
            if not model.input_dynamics_.active
            else f"{model.input_dynamics_.kind}: lag {model.input_dynamics_.tau * 1e3:.4g} ms, "
            f"delay {model.input_dynamics_.delay * 1e3:.4g} ms",
        ),
    ]
    if model.output_dynamics_.active:
        rep.add("output_mode_hz", "output mode: resonance", model.output_dynamics_.f0, "Hz")
        rep.add("output_mode_zeta", "output mode: damping ratio", model.output_dynamics_.zeta, "")
    if model.input_dynamics_.active:
        rep.add("input_lag_s", "input dynamics: lag", model.input_dynamics_.tau, "s")
        rep.add("input_delay_s", "input dynamics: delay", model.input_dynamics_.delay, "s")
    err = y - pred
    rep.add("samples", "samples", int(x.size))
    _windows(rep, model, t)
    nrmse_pct = 100 * nrmse(y, pred)
    rep.add("nrmse_pct", "NRMSE (RMSE / output span)", nrmse_pct, "%")
    zero_pct = 100 * nrmse(y, np.zeros_like(y))
    rep.add("nrmse_zero_pct", "NRMSE of predicting zero (the baseline)", zero_pct, "%")
    if nrmse_pct >= zero_pct:
        rep.add("verdict", "verdict", "worse than predicting zero: the model does not describe "
                "this record (check the columns, units and the model's class)")  # fmt: skip
    rep.add("rmse", "RMSE", rmse(y, pred), out_u)
    rep.add("max_abs_error", "largest error", float(np.max(np.abs(err))), out_u)
    rep.add("hysteresis_width_measured_pct", "hysteresis width, measured",
            100 * hysteresis_width(x, y), "%")  # fmt: skip
    lo, hi = model.input_range_
    if not math.isnan(lo):
        outside = int(np.count_nonzero((x < lo - 1e-9) | (x > hi + 1e-9)))
        rep.add("samples_outside_training_range", "samples outside the training range", outside)
    # the model a wide pale band beneath, the measured line thin on top: both stay visible
    measured = {"color": "0.2", "lw": 0.8, "zorder": 3}
    model_line = {"color": "C0", "lw": 3.0, "alpha": 0.45, "zorder": 2}
    rep.figure("loop.png", "input-output loop: data (dark line) and model (blue band)", [
        {"curves": [(x, y, "measured", measured), (x, pred, "model", model_line)],
         "xlabel": "input", "xunit": in_u, "ylabel": "output", "yunit": out_u, "title": ""},
    ])  # fmt: skip
    caption = f"output over time, and the residual (NRMSE {nrmse_pct:.3g} %)"
    rep.figure("fit.png", caption, [
        {"curves": [(t, y, "measured", measured), (t, pred, "model", model_line)],
         "xlabel": "time", "xunit": "s", "ylabel": "output", "yunit": out_u},
        {"curves": [(t, err, "measured - model", {"lw": 0.7, "color": "C3"})],
         "xlabel": "time", "xunit": "s", "ylabel": "residual", "yunit": out_u},
    ], stacked=True)  # fmt: skip
    growth = model.growth_coefficients()
    dyn = model.input_dynamics_  # the piezo's voltage, where a lag was identified
    driven = dyn.apply(rec.x, np.r_[0.0, np.diff(rec.t)])[0][w] if dyn.active else x
    pure = y - model.growth(rec.x, t=rec.t)[w] if growth else y  # eq. 19: growth removed
    share, far, turns = run_on(driven, pure)
    if turns:  # what no model whose branches rise with the input can follow
        rep.add("run_on_pct", f"output's run-on past the input's turns (median of {turns} "
                "turns; rising branches: none)", 100 * share, "%")  # fmt: skip
        rep.add("run_on_input", "the input's way back where the run-on peaks", far, in_u)
    if growth:
        for k, (v, u) in growth.items():
            rep.add(f"growth_{k}", f"growth term {k}", v, u)
        rep.add("hysteresis_width_growth_removed_pct", "hysteresis width, growth removed",
                100 * hysteresis_width(x, pure), "%")  # fmt: skip
        rep.figure("growth_removed.png", "identified growth removed (eq. 19)", [
            {"curves": [(x, y, "measured", {"lw": 0.7, "color": "0.55"}),
                        (x, pure, "growth removed", {"lw": 1.1, "color": "C1"})],
             "xlabel": "input", "xunit": in_u, "ylabel": "output", "yunit": out_u},
        ])  # fmt: skip
    chosen = "+".join(k for k in growth) or "none"
    for label, score in model.selection_.items():  # the term selection, fold by fold
        folds = ", ".join(f"{f:.4g}" for f in model.selection_folds_.get(label, []))
        mark = " (chosen)" if label == chosen else ""
        rep.add(f"selection_{label}", f"held-out RMSE, growth {label}{mark}",
                f"{score:.4g} {out_u}; per fold: {folds}")  # fmt: skip
    return rep


def _in_metres(
    rep: Any,
    x: FloatArray,
    t: FloatArray,
    charge: FloatArray,
    gain: float | OutputMap,
    measured: FloatArray | None,
) -> None:
    """The displacement predicted from the voltage through the capacitor charge and the
    map (or gain), in metres; scored against a sensor's reading when there is one."""
    if isinstance(gain, OutputMap):
        lo, hi = gain.charge_range
        outside = int(np.count_nonzero((charge < lo) | (charge > hi)))
        with warnings.catch_warnings():  # counted and reported below, not warned per call
            warnings.simplefilter("ignore", ExtrapolationWarning)
            s = gain.predict(charge)
        rep.add("map", "map from charge to displacement", gain.summary())
        rep.add("map_stderr_max", "the map's standard error, largest over this record",
                float(np.max(gain.stderr(charge))), "m")  # fmt: skip
        rep.add("samples_outside_map_range", "samples whose charge lies outside the map's "
                "calibrated range (extended linearly)", outside)  # fmt: skip
        dt = float(np.median(np.diff(t))) if t.size > 1 else math.inf
        shift = min(round(gain.delay / dt), t.size // 2)
    else:
        s, shift = gain * (charge - charge[0]), 0  # a gain alone does not know the sensor's zero
        rep.add("gain", "gain from charge to displacement", gain, "m/C")
    band = {"color": "C0", "lw": 3.0, "alpha": 0.45, "zorder": 2}  # as the charge's figures
    thin = {"color": "0.2", "lw": 0.8, "zorder": 3}
    curves = [(x, s, "predicted from the charge", band)]
    panels: list[dict[str, Any]] = [
        {"curves": [(t, s, "predicted", band)], "xlabel": "time", "xunit": "s",
         "ylabel": "displacement", "yunit": "m"},
    ]  # fmt: skip
    caption = "displacement predicted from the voltage through the charge model and the map"
    if measured is not None:
        n = t.size - shift  # the sensor reads the displacement ``shift`` samples late
        got, want = s[:n], measured[shift:]
        centred = (got - got.mean()) - (want - want.mean())
        if isinstance(gain, OutputMap):
            rep.add("displacement_nrmse_pct", "displacement NRMSE (the sensor's reading)",
                    100 * nrmse(want, got), "%")  # fmt: skip
        free = 100 * float(np.sqrt(np.mean(centred**2)) / np.ptp(want))
        rep.add("displacement_nrmse_offset_free_pct", "displacement NRMSE, offsets removed",
                free, "%")  # fmt: skip
        rep.add("displacement_rmse_offset_free", "displacement RMSE, offsets removed",
                float(np.sqrt(np.mean(centred**2))), "m")  # fmt: skip
        curves.insert(0, (x[:n], want, "sensor", thin))
        panels[0]["curves"].insert(0, (t[:n], want, "sensor", thin))
        panels.append({"curves": [(t[:n], centred, "predicted - sensor, offsets removed",
                                   {"lw": 0.7, "color": "C3"})], "xlabel": "time",
                       "xunit": "s", "ylabel": "residual", "yunit": "m"})  # fmt: skip
        caption += f" and the sensor (offset-free NRMSE {free:.3g} %)"
    rep.figure("displacement_loop.png", "displacement against voltage, in metres", [
        {"curves": curves, "xlabel": "input", "xunit": "V", "ylabel": "displacement",
         "yunit": "m", "title": ""},
    ])  # fmt: skip
    rep.figure("displacement.png", caption, panels, stacked=True)


def _setting(value: object) -> str:
    """A model setting as a reader wants it: text bare, lists joined, none as 'default'."""
    if value is None:
        return "default"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, str):
        return value
    if isinstance(value, list | tuple):
        return ", ".join(_setting(v) for v in value) or "none"
    if isinstance(value, dict):
        return ", ".join(f"{k}: {_setting(v)}" for k, v in value.items()) or "none"
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def _windows(rep: Any, model: HysteresisModel, t: FloatArray) -> None:
    """Which part of the record trained the model and how much of the scored part it never
    saw (by time: when the report's record is the one the model was fitted on)."""
    t0, t1 = model.train_window_
    a, b = float(t[0]), float(t[-1])
    rep.add("scored_window_s", "scored window", f"{a:.6g} to {b:.6g}", "s")
    if not (math.isfinite(t0) and math.isfinite(t1)):
        rep.add("training_window_s", "training window", "unknown (not in the model file)")
        return
    rep.add("training_window_s", "training window (of the record it was fitted on)",
            f"{t0:.6g} to {t1:.6g}", "s")  # fmt: skip
    unseen = float(np.mean((t < t0) | (t > t1)))
    rep.add("held_out_pct", "scored samples outside the training window (held out, if this "
            "is the record it was fitted on)", 100 * unseen, "%")  # fmt: skip


def _fmt(values: FloatArray) -> str:
    return ", ".join(f"{v:.6g}" for v in values)
