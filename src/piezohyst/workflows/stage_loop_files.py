"""A stage on its actuators' charges from files: ``calibrate-stage`` (the stage's positions
from the charges, :func:`~piezohyst.calibrate_stage`, saved as a stage map) and the exports of
a stage map with its actuators' model files (``export-c``, ``--shared``, ``--mex``,
``export-fmu``: :class:`~piezohyst.CoupledSelfSensingController` outside Python)."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..control.coupled_selfsensing import CoupledSelfSensingController
from ..control.export.c_code import c_paths
from ..control.export.stage_c import (
    stage_paths,
    write_stage_c,
    write_stage_fmu,
    write_stage_mex,
    write_stage_shared,
)
from ..errors import DataFileError, ParameterError
from ..io import DataSpec
from ..model.calibrations.leakage import Leakage
from ..model.calibrations.stage_map import STAGE_MAP_FORMAT, StageMap, calibrate_stage
from ._base import PathLike, _load, guard_outputs
from .stage_files import _read_stage, holds_format

__all__ = [
    "StageLoopRun",
    "StageLoopSettings",
    "calibrate_stage_file",
    "export_stage_loop_file",
    "is_stage_map_file",
    "simulate_stage_loop_file",
]


def is_stage_map_file(path: PathLike) -> bool:
    """True for a stage map file (``StageMap.save``), read only as far as its format.

    Parameters
    ----------
    path : str or os.PathLike
        Any file: one that cannot be read, or is not JSON, is not a stage map.

    Returns
    -------
    bool
    """
    return holds_format(path, STAGE_MAP_FORMAT)


@dataclass(frozen=True)
class StageLoopSettings:
    """A stage's loop from files: its limits and gains (as
    :class:`~piezohyst.CoupledSelfSensingController` takes them).

    Attributes
    ----------
    v_min, v_max : float or None
        Every actuator's voltage limits (V); None: each what its model was identified on.
    slew_rate : float, "trained" or None
    allow_extrapolation : bool
    leakage : tuple of path, optional
        One leakage file per actuator (``calibrate-leakage``); None: the models' growth terms.
    ki, kp : float
        Each loop's integral and proportional gains.
    """

    v_min: float | None = None
    v_max: float | None = None
    slew_rate: float | str | None = "trained"
    allow_extrapolation: bool = False
    leakage: tuple[PathLike, ...] | None = None
    ki: float = 0.5
    kp: float = 0.0


def _loop(
    map_path: PathLike,
    models: Sequence[PathLike],
    sample_rate: float,
    cfg: StageLoopSettings,
    gains: bool = True,
) -> CoupledSelfSensingController:
    """The stage's loop from its files: the map, one model (and leakage) file per actuator
    (``gains`` False: the loops' gains at 0, feedforward alone)."""
    stage = StageMap.load(map_path)
    n = len(stage.maps)
    leakage = cfg.leakage
    if len(models) != n or (leakage is not None and len(leakage) != n):
        msg = (
            f"the stage map {map_path} holds {n} actuators: give one model file (--models) "
            f"and, if any, one leakage file (--leakage) per actuator, comma-separated"
        )
        raise ParameterError(msg)
    fitted = [_load(p) for p in models]
    leaks = None if leakage is None else [Leakage.load(p) for p in leakage]
    lo = [m.input_range_[0] for m in fitted] if cfg.v_min is None else cfg.v_min
    hi = [m.input_range_[1] for m in fitted] if cfg.v_max is None else cfg.v_max
    return CoupledSelfSensingController(
        fitted, stage, v_min=lo, v_max=hi, sample_rate=sample_rate, leakage=leaks,
        ki=cfg.ki if gains else 0.0, kp=cfg.kp if gains else 0.0,
        slew_rate=cfg.slew_rate,  # type: ignore[arg-type]
        allow_extrapolation=cfg.allow_extrapolation,
    )  # fmt: skip


def export_stage_loop_file(
    map_path: PathLike,
    out: PathLike,
    *,
    models: Sequence[PathLike],
    sample_rate: float | None,
    settings: StageLoopSettings | None = None,
    precision: str = "double",
    shared: bool = False,
    mex: bool = False,
    force: bool = False,
) -> list[os.PathLike[str]]:
    """A stage's self-sensing loop as C files, with ``shared`` its library, with ``mex`` a
    MEX gateway, or where ``out`` ends in ``.fmu`` an FMU.

    Parameters
    ----------
    map_path : str or os.PathLike
        A stage map file (``calibrate-stage``).
    out : str or os.PathLike
        The stage's ``.c`` file (each actuator's pair beside it), a gateway, or an FMU.
    models : sequence of path
        The actuators' model files the map was calibrated through, in its order.
    sample_rate : float
        Hz, of the loop.
    settings : StageLoopSettings, optional
        Its limits, leakage files and gains.
    precision : {"double", "float"}
    shared, mex : bool
        Also build the library; or write a MEX gateway (``out``) with the C beside it.
    force : bool
        Overwrite files even where piezohyst did not write them.

    Returns
    -------
    list of Path
        Every file written: the stage's ``.c`` first, a library last.

    Raises
    ------
    ParameterError
        No sample rate, or not one model (and leakage file) per actuator.
    """
    if sample_rate is None:
        msg = "a stage's self-sensing loop needs the loop's sample rate (--sample-rate, Hz)"
        raise ParameterError(msg)
    cfg = settings or StageLoopSettings()
    loop = _loop(map_path, models, sample_rate, cfg)
    n = len(loop.loops)
    sources = [map_path, *models, *(cfg.leakage or [])]
    kind: Any = precision
    if str(out).endswith(".fmu"):
        guard_outputs([out], sources, force=force)
        return [write_stage_fmu(loop, out, precision=kind)]
    c_path = c_paths(out)[0]
    guard_outputs(stage_paths(c_path, n, mex=mex), sources, force=force)
    if mex:
        return list(write_stage_mex(loop, c_path, precision=kind))
    if shared:
        files, lib = write_stage_shared(loop, c_path, precision=kind)
        return [*files, lib]
    return list(write_stage_c(loop, Path(c_path), precision=kind))


def calibrate_stage_file(
    data: PathLike,
    out: PathLike | None = None,
    *,
    models: Sequence[PathLike],
    inputs: Sequence[str],
    charges: Sequence[str],
    outputs: Sequence[str],
    data_spec: DataSpec | None = None,
    force: bool = False,
    output_dynamics: str = "auto",
) -> StageMap:
    """Calibrate a stage's positions from its actuators' charges from one record (each
    actuator's voltage and charge, each axis's position, sampled together) and save the map.

    Parameters
    ----------
    data : str or os.PathLike
        The recording.
    out : str or os.PathLike, optional
        Where to save the stage map (JSON).
    models : sequence of path
        One model file per actuator, each fitted on its own voltage -> charge.
    inputs, charges, outputs : sequence of str
        The actuators' voltage and charge columns and the axes' position columns (outputs
        at least as many as actuators, actuator ``i``'s own axis ``i``-th).
    data_spec : DataSpec, optional
        How the file is read (its time column or rate, group, window, units, scales).
    force : bool
        Overwrite ``out`` even where piezohyst did not write it.
    output_dynamics : {"auto", "none", "second-order"}, default "auto"
        Each actuator's mode between its charge and what it moves
        (:func:`~piezohyst.calibrate_gain`).

    Returns
    -------
    StageMap

    Raises
    ------
    ParameterError
        Not one model, voltage and charge column per actuator, or fewer positions.
    """
    n = len(models)
    if len(inputs) != n or len(charges) != n or len(outputs) < n or n < 2:
        msg = (
            "calibrate-stage takes one model, one voltage and one charge column per actuator "
            f"(two or more) and a position column per axis: got {n} models, {len(inputs)} "
            f"voltage, {len(charges)} charge and {len(outputs)} position columns"
        )
        raise ParameterError(msg)
    if out is not None:
        guard_outputs([out], [data, *models], force=force)
    spec = data_spec or DataSpec()
    try:
        t, u, q, _ = _read_stage(data, inputs, charges, spec)
    except DataFileError as exc:  # the charges are read as outputs: name their own option
        said = str(exc).replace("--output (output_column=)", "--charge")
        raise DataFileError(said.replace("output column", "charge column")) from None
    t2, _, y, unit = _read_stage(data, inputs, outputs, spec)
    assert q is not None and y is not None and t2.shape == t.shape  # columns given: read
    stage = calibrate_stage([_load(p) for p in models], u, q, y, t, output_unit=unit or "m",
                            output_dynamics=output_dynamics)  # fmt: skip
    if out is not None:
        stage.save(out)
    return stage


#: Samples (at the built-in stage's 1 kHz) after the arrival from rest left out of the scores:
#: the loops settle their charge frames (on the built-in stage a held axis arrives within
#: 50 ms, 1.6 um of 320 um against 1.85 um after)
ARRIVAL = 100
#: What the built-in stage a map runs on is, without lags and modes and with them (a map that
#: holds modes, or models with lags, run on the one that has them: their inverses shape the
#: commands for them)
BUILT_IN_STAGES = {
    False: "the built-in XY stage (two of the bench's actuators, x moves y by 4 %, y x by -3 %)",
    True: ("the built-in XY stage with lags and modes (two of the bench's actuators behind 4 "
           "and 3 ms amplifiers, modes at 150 and 120 Hz, x moves y by 4 %, y x by -3 %)"),
}  # fmt: skip


@dataclass(frozen=True)
class StageLoopRun:
    """What :func:`simulate_stage_loop_file` did.

    Attributes
    ----------
    nrmse : tuple of float
        Per axis, the lasers' RMS error over what the axis's actuator alone moves, after the
        arrival from rest (the slew limit's ramp and :data:`ARRIVAL` samples).
    width : tuple of float
        Per axis, the loop width desired -> laser position (NaN for an axis held still).
    moved : tuple of float
        Per axis, the lasers' peak-to-peak over the same span (a held axis's motion).
    loop : CoupledSelfSensingController
        After the run: its counts per actuator.
    stage : str
        Which built-in stage it ran on (the one with lags and modes where the map holds
        modes or the models lags).
    """

    nrmse: tuple[float, ...]
    width: tuple[float, ...]
    moved: tuple[float, ...]
    loop: CoupledSelfSensingController
    stage: str = ""


def simulate_stage_loop_file(
    map_path: PathLike,
    target: PathLike,
    out: PathLike,
    *,
    models: Sequence[PathLike],
    columns: Sequence[str],
    settings: StageLoopSettings | None = None,
    feedforward: bool = False,
    seed: int = 0,
    force: bool = False,
) -> StageLoopRun:
    """A stage map's self-sensing loop (or its feedforward alone) run on the built-in
    simulated stage (:class:`~piezohyst.simulation.Stage`: two of the bench's actuators, the
    default XY coupling; with their amplifiers' lags and modes, ``XY_DYNAMIC``, where the map
    holds modes or the models lags; another stage than a lab's) over a target file, at 1 kHz.

    Writes ``time``, ``desired_<axis>``, ``command_<k>`` (V), ``charge_<k>`` (C) and the
    stage's lasers ``position_<axis>`` (m, for checking: the loop reads the charges only).

    Parameters
    ----------
    map_path, target, out : path
        The stage map, the desired positions (``time`` and one column per axis), the output.
    models : sequence of path
        The actuators' model files the map was calibrated through.
    columns : sequence of str
        The target's axis columns, in the map's order.
    settings : StageLoopSettings, optional
        Its limits, leakage files and gains.
    feedforward : bool
        The loops' gains at 0: the models and the map as feedforward alone.
    seed : int
        The stage's noise.
    force : bool
        Overwrite ``out`` even where piezohyst did not write it.

    Returns
    -------
    StageLoopRun

    Raises
    ------
    ParameterError
        A stage of other than two actuators, a target at another rate or with other axes.
    """
    from ..io import read_table, write_table
    from ..metrics import hysteresis_width
    from ..simulation import XY_DYNAMIC, Stage, run_stage_loop

    cfg = settings or StageLoopSettings()
    guard_outputs([out], [map_path, target, *models, *(cfg.leakage or [])], force=force)
    loop = _loop(map_path, models, 1000.0, cfg, gains=not feedforward)
    n, m = len(loop.loops), loop.stage.coupling.shape[0]
    if n != 2 or m != 2:
        msg = (
            f"the built-in stage has two actuators and two axes; {map_path} maps {n} "
            f"actuators to {m} axes: run your own stage with run_stage_loop in Python"
        )
        raise ParameterError(msg)
    if len(columns) != m:
        msg = f"{map_path} moves {m} axes: got {len(columns)} target columns ({columns})"
        raise ParameterError(msg)
    table = read_table(target)
    t = table.get("time")
    if t.size < 2 or abs(float(np.median(np.diff(t))) - 1e-3) > 1e-6:
        msg = f"{target}: the built-in stage samples at 1 kHz; give the target at that rate"
        raise DataFileError(msg)
    desired = np.column_stack([table.get(c, finite=False) for c in columns])
    # a map with modes (or models with lags) inverts what the stage with lags and modes has
    dynamic = any(om.mode.active for om in loop.stage.maps) or any(
        m.input_dynamics_.active for m in loop.models
    )
    plant = Stage(XY_DYNAMIC if dynamic else None, seed=seed, voltage=loop.last_command)
    run = run_stage_loop(loop, desired, plant)
    written: dict[str, Any] = {"time": t}
    units: dict[str, str | None] = {"time": "s"}
    for i, c in enumerate(columns):
        written[f"desired_{c}"], units[f"desired_{c}"] = desired[:, i], "m"
    for k in range(n):
        written[f"command_{k}"], units[f"command_{k}"] = run.voltage[:, k], "V"
        written[f"charge_{k}"], units[f"charge_{k}"] = run.charge[:, k], "C"
    for i, c in enumerate(columns):
        written[f"position_{c}"], units[f"position_{c}"] = run.position[:, i], "m"
    write_table(out, written, units)
    ok = np.all(np.isfinite(desired), axis=1)
    # scored after the arrival from rest: the slew limit's ramp and the loops' first 0.1 s
    ramp = max(int(lp.sent_count - lp.command_count) for lp in loop.loops)
    ok[: ramp + ARRIVAL] = False
    span = loop.reach[:, 1] - loop.reach[:, 0]
    err = np.sqrt(np.mean((run.position[ok] - desired[ok]) ** 2, axis=0)) / span
    width = tuple(
        hysteresis_width(desired[ok, i], run.position[ok, i])
        if np.ptp(desired[ok, i]) > 0.01 * span[i] else math.nan
        for i in range(m)
    )  # fmt: skip
    moved = tuple(float(x) for x in np.ptp(run.position[ok], axis=0) / span)
    said = BUILT_IN_STAGES[dynamic]
    return StageLoopRun(tuple(float(e) for e in err), width, moved, loop, said)
