"""The compensate workflow: a desired trajectory in a file to the commands a DAQ plays, safe by
default (re-exported by :mod:`piezohyst.workflows`)."""

from __future__ import annotations

import copy
import dataclasses
import itertools
import math
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from .._validation import FloatArray
from ..control.compensator import Compensator, CompensatorSettings
from ..errors import DataFileError, ExtrapolationWarning, LimitWarning, ParameterError
from ..io import (
    check_finite,
    check_increasing,
    open_table,
    write_blocks,
)
from ..model.model import HysteresisModel
from ..units import to_standard
from ._base import (
    _DEFAULT_SETTINGS,
    ONE_RATE,
    PathLike,
    Progress,
    _desired_column,
    _load,
    check_rate,
    command_gain,
    guard_outputs,
    time_rate,
)

__all__ = ["PRECONDITION_MARGIN", "REACH_HOLD", "Compensation", "compensate_file"]


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
