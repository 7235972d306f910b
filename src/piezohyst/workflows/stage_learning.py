"""``piezohyst learn`` on a coupled stage: one trial of a repeated scan through files, as the
single actuator's (:mod:`~piezohyst.workflows.learning_files`), with one desired column per
axis, one command column per actuator, and the stage's sensors read back
(:class:`~piezohyst.CoupledLearningCompensator`)."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._validation import FloatArray
from ..control.learning.coupled import OPTIONS, CoupledLearningCompensator, CoupledTrial
from ..errors import DataFileError, ModelFileError, ParameterError
from ..io import read_table, write_table
from ..model.coupled import CoupledModel
from ._base import PathLike, guard_outputs
from .learning_files import recording_check

__all__ = ["StageLearnRun", "learn_stage_file"]

#: The command line's option for each of a run's settings kept in the state
RUN_OPTIONS = {"v_min": "--v-min", "v_max": "--v-max", "slew_rate": "--slew-rate",
               "allow_extrapolation": "--allow-extrapolation", "options": "the learning options",
               "columns": "--column"}  # fmt: skip


@dataclasses.dataclass(frozen=True)
class StageLearnRun:
    """What one call of a stage's ``learn`` did.

    Attributes
    ----------
    learner : CoupledLearningCompensator
        After the call (its history, its learners).
    trial : CoupledTrial or None
        The trial just learned from (None on the first call).
    commands : ndarray, shape (samples, actuators)
        The next trial's commands (V).
    """

    learner: CoupledLearningCompensator
    trial: CoupledTrial | None
    commands: FloatArray


def _columns(table: Any, names: Sequence[str], where: Path, what: str) -> FloatArray:
    missing = [c for c in names if c not in table]
    if missing:
        msg = f"{where}: no {what} column {missing[0]!r} (columns: {', '.join(table.columns)})"
        raise DataFileError(msg)
    return np.column_stack([table.get(c, finite=False) for c in names])


def learn_stage_file(
    model_path: PathLike,
    state_path: PathLike,
    out: PathLike,
    *,
    recorded: PathLike | None = None,
    desired: PathLike | None = None,
    columns: Sequence[str] | None = None,
    v_min: float | Sequence[float],
    v_max: float | Sequence[float],
    sample_rate: float | None = None,
    slew_rate: float | str | None = "trained",
    allow_extrapolation: bool = False,
    voltage_columns: Sequence[str] | None = None,
    reading_columns: Sequence[str] | None = None,
    tolerance: float = 1e-4,
    voltage_tolerance: float | None = None,
    force: bool = False,
    **options: Any,
) -> StageLearnRun:
    """One trial of learning a stage's repeated scan through files.

    The first call (no state file yet) takes the desired scan (one period: a ``time`` column
    and one column per axis, ``columns``) and writes the first trial's commands. Every later
    call takes the DAQ's recording of the trial just sent: its voltage columns (one per
    actuator, default ``voltage_0``, ``voltage_1``, ...) must be the commands written, or
    those commands measured with noise (each checked as the single actuator's,
    :func:`~piezohyst.workflows.learning_files.recording_check`), and its reading columns
    (default: the desired columns' names) the stage's positions in the model's units. The
    state is saved after the commands are written, so a call that fails halfway can be
    repeated with the same files.

    Parameters
    ----------
    model_path, state_path, out : path
        The coupled model file, the learner's state (JSON), the next commands' CSV (``time``,
        ``command_<k>`` per actuator, ``desired_<axis>`` per axis).
    recorded, desired : path, optional
        The trial's recording (later calls), or the scan (the first call).
    columns : sequence of str, optional
        The scan's axis columns, in the model's order (the first call).
    v_min, v_max : float or sequence of float
        Every actuator's limits (V), or one per actuator; the same on every call.
    sample_rate : float, optional
        Hz; default the scan's time column's.
    slew_rate, allow_extrapolation
        As for :class:`~piezohyst.CoupledLearningCompensator`; the same on every call.
    voltage_columns, reading_columns : sequence of str, optional
        The recording's columns of the voltages sent and of the positions read.
    tolerance, voltage_tolerance : float
        How far the recorded voltages may stray from the commands (as the single actuator's).
    force : bool
        Replace an ``out`` that piezohyst did not write.
    **options
        The learning options (:class:`~piezohyst.CoupledLearningCompensator`); the same on
        every call.

    Returns
    -------
    StageLearnRun
    """
    state_path, out = Path(state_path), Path(out)
    inputs = [Path(p) for p in (model_path, recorded, desired, state_path) if p is not None]
    guard_outputs([out], inputs, force=force)
    model = CoupledModel.load(model_path)
    n, m = model.coupling_.shape[1], model.coupling_.shape[0]
    run: dict[str, Any] = {
        "v_min": np.broadcast_to(np.asarray(v_min, dtype=np.float64), (n,)).tolist(),
        "v_max": np.broadcast_to(np.asarray(v_max, dtype=np.float64), (n,)).tolist(),
        "slew_rate": slew_rate, "allow_extrapolation": bool(allow_extrapolation),
        "options": {k: options[k] for k in sorted(options)},
    }  # fmt: skip
    first = not state_path.exists()
    saved: dict[str, Any] = {}
    scan: FloatArray | None = None
    if first:
        if desired is None or recorded is not None:
            msg = (
                f"no learning state at {state_path} yet: start with --desired (the scan) and no "
                "recording"
            )
            raise ParameterError(msg)
        if columns is None or len(columns) != m:
            msg = f"{model_path} moves {m} axes: give one desired column each (--column x,y)"
            raise ParameterError(msg)
        table = read_table(Path(desired))
        scan = _columns(table, columns, Path(desired), "desired")
        rate = sample_rate
        if rate is None:
            t = table.get("time")
            rate = float(f"{(t.size - 1) / (t[-1] - t[0]):.12g}")
        run["columns"] = list(columns)
    else:
        if desired is not None:
            msg = f"{state_path} already holds a scan: --desired starts a run (new file)"
            raise ParameterError(msg)
        try:
            saved = json.loads(state_path.read_text(encoding="utf-8"))
            kept, rate = saved["run"], float(saved["sample_rate"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            msg = f"{state_path}: cannot read the stage's learning state ({exc})"
            raise ModelFileError(msg) from None
        if sample_rate is not None and abs(sample_rate - rate) > 1e-9 * rate:
            msg = f"{state_path}: this run learns at {rate:g} Hz; this call gives {sample_rate:g}"
            raise ParameterError(msg)
        run["columns"] = kept.get("columns")
        if columns is not None and list(columns) != run["columns"]:
            run["columns"] = list(columns)
        for key, option in RUN_OPTIONS.items():
            if kept.get(key) != run[key]:
                msg = (
                    f"{state_path}: this run was started with {option} {kept.get(key)!r}; this "
                    f"call gives {run[key]!r}: give the same on every call of a run"
                )
                raise ParameterError(msg)
    unknown = sorted(set(options) - OPTIONS)
    if unknown:
        msg = f"not a learning option: {', '.join(unknown)}"
        raise ParameterError(msg)
    learner = CoupledLearningCompensator(
        model, v_min=run["v_min"], v_max=run["v_max"], sample_rate=rate,
        slew_rate=slew_rate,  # type: ignore[arg-type]  # checked by the compensator
        allow_extrapolation=allow_extrapolation, **options,
    )  # fmt: skip
    trial = None
    if not first:
        learner.restore(saved, str(state_path))
        sent = learner.pending
        if sent is None:  # pragma: no cover - every saved state waits for a recording
            msg = f"{state_path}: no trial waits for its recording"
            raise ModelFileError(msg)
        if recorded is None:
            msg = f"{state_path} waits for trial {learner.trials}'s recording (RECORDED)"
            raise ParameterError(msg)
        rec = Path(recorded)
        recording = read_table(rec)
        volts = _columns(recording, voltage_columns or [f"voltage_{k}" for k in range(n)], rec,
                         "voltage")  # fmt: skip
        if volts.shape != sent.shape:
            msg = (
                f"{rec}: {volts.shape[0]} rows of {volts.shape[1]} voltages, but trial "
                f"{learner.trials} sent {sent.shape[0]} commands to {sent.shape[1]} actuators"
            )
            raise DataFileError(msg)
        for k in range(n):
            span = run["v_max"][k] - run["v_min"][k]
            check = recording_check(volts[:, k], sent[:, k], tolerance * span, voltage_tolerance)
            if check["worst_row"] >= 0:
                row = int(check["worst_row"])
                msg = (
                    f"{rec}: row {row}'s voltage {volts[row - 1, k]:.6g} V (actuator {k}) is "
                    f"not the command written for trial {learner.trials} "
                    f"({sent[row - 1, k]:.6g} V; off by {check['off_V']:.3g} V, allowed "
                    f"{check['allowed_V']:.3g} V): a recording of another trial or run "
                    "(--voltage-tolerance sets what is allowed)"
                )
                raise DataFileError(msg)
        positions = _columns(recording, reading_columns or run["columns"], rec, "reading")
        trial = learner.learn(positions)
    commands = learner.command(scan)
    rows = commands.shape[0]
    written: dict[str, FloatArray] = {"time": np.arange(rows) / rate}
    units: dict[str, str | None] = {"time": "s"}
    for k in range(n):
        written[f"command_{k}"], units[f"command_{k}"] = commands[:, k], "V"
    assert learner.desired is not None
    for j, name in enumerate(run["columns"]):
        written[f"desired_{name}"] = learner.desired[:, j]
        units[f"desired_{name}"] = model.channels_[0].output_unit
    write_table(out, written, units=units)
    payload = learner.to_dict()
    payload["sample_rate"], payload["run"] = rate, run
    learner.save_dict(state_path, payload)
    return StageLearnRun(learner, trial, commands)
