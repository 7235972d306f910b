"""Learning across trial files: what ``piezohyst learn`` does, for labs that run their own DAQ.

Each call reads what the DAQ recorded over the trial last written, learns from it, and
writes the next trial's commands; the learner's state lives in a JSON file between calls
(written atomically, and bound to its model, settings and trajectory).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ._formats import Table
from .compensator import CompensatorSettings
from .errors import DataFileError, ModelFileError, ParameterError
from .io import read_table, write_table
from .leakage import Leakage
from .learning import LearningCompensator, Trial
from .persistence import load_model

__all__ = ["LearnFileResult", "learn_file"]


@dataclass(frozen=True)
class LearnFileResult:
    """What one call of :func:`learn_file` did.

    Attributes
    ----------
    learner : LearningCompensator
    trial : Trial or None
        What the recorded trial measured (None on the first call).
    commands : ndarray
        The next trial's voltages, as written.
    """

    learner: LearningCompensator
    trial: Trial | None
    commands: np.ndarray


def _column(table: Table, name: str, what: str) -> np.ndarray:
    if name not in table:
        msg = (
            f"{table.path}: no column {name!r} for the {what} (columns: {', '.join(table.columns)})"
        )
        raise DataFileError(msg)
    return table.get(name, finite=False)


def learn_file(
    model_path: str | Path,
    state_path: str | Path,
    out: str | Path,
    *,
    recorded: str | Path | None = None,
    desired: str | Path | None = None,
    column: str = "desired",
    settings: CompensatorSettings | None = None,
    leakage: str | Path | None = None,
    lag: float = 0.0,
    learning_gain: float | Literal["auto"] = "auto",
    cutoff: float | Literal["auto"] = "auto",
    voltage_column: str = "voltage",
    reading_column: str = "charge",
    sensor: bool = False,
    tolerance: float = 1e-4,
    lead_in: bool = True,
) -> LearnFileResult:
    """One trial of learning through files.

    The first call (no state file yet) takes the desired trajectory and writes
    the first trial's commands. Every later call takes the file the DAQ recorded
    over the trial just sent: its voltage column must be the commands written
    (to ``tolerance`` of the voltage range: two runs are never mixed), its
    ``reading_column`` the charge (or, with ``sensor``, a displacement in m).
    The state is saved after the commands are written, so a call that fails
    halfway can be repeated with the same files.

    Parameters
    ----------
    model_path, state_path, out : path
        The model file, the learner's state (JSON), the next commands' CSV
        (``time``, ``command``, ``desired``).
    recorded : path, optional
        The trial's recording.
    desired : path, optional
        The trajectory (column ``column``, and ``time`` or ``sample_rate``), first call only.
    settings : CompensatorSettings
        Limits (default: the model's training range), slew limit, sample rate,
        domain and gain.
    leakage : path, optional
        A leakage file (:func:`~piezohyst.leakage.calibrate_leakage`); default the model's.
    lag, learning_gain, cutoff, lead_in
        See :class:`~piezohyst.LearningCompensator`.

    Returns
    -------
    LearnFileResult
    """
    settings = settings or CompensatorSettings()
    state_path, out = Path(state_path), Path(out)
    model = load_model(model_path)
    lo, hi = model.input_range_
    v_min = lo if settings.v_min is None else settings.v_min
    v_max = hi if settings.v_max is None else settings.v_max
    first = not state_path.exists()
    d: np.ndarray | None = None
    saved: dict[str, Any] = {}
    rate = settings.sample_rate
    if first:
        if desired is None or recorded is not None:
            msg = (
                f"no learning state at {state_path} yet: start with --desired (the trajectory) "
                "and no recording"
            )
            raise ParameterError(msg)
        table = read_table(Path(desired))
        d = _column(table, column, "desired trajectory")
        if rate is None:
            t = _column(table, "time", "time (or give --sample-rate)")
            rate = float(f"{(t.size - 1) / (t[-1] - t[0]):.12g}")  # 1000.0, not 999.9999999999
    else:
        if desired is not None:
            msg = f"{state_path} already holds a trajectory: --desired starts a run (new file)"
            raise ParameterError(msg)
        try:
            saved = json.loads(state_path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            msg = f"{state_path}: cannot read the learning state ({exc})"
            raise ModelFileError(msg) from None
        if rate is None:  # the rate the run was started with
            rate = float(saved.get("sample_rate", 0.0)) if isinstance(saved, dict) else 0.0
            if not rate > 0:
                msg = f"{state_path}: no sample rate in the state: give --sample-rate"
                raise ModelFileError(msg)
    learner = LearningCompensator(
        model,
        v_min=v_min,
        v_max=v_max,
        sample_rate=rate,
        leakage=None if leakage is None else Leakage.load(leakage),
        slew_rate=settings.slew_rate,
        domain=settings.domain,
        gain=settings.gain,
        allow_extrapolation=settings.allow_extrapolation,
        lag=lag,
        learning_gain=learning_gain,
        cutoff=cutoff,
        lead_in=lead_in,
    )
    trial = None
    if not first:
        learner.restore(saved, str(state_path))
        if recorded is None:
            msg = f"{state_path} waits for trial {learner.trials}'s recording (RECORDED)"
            raise ParameterError(msg)
        rec = Path(recorded)
        sent = learner.pending
        assert sent is not None
        recording = read_table(rec)
        v = _column(recording, voltage_column, "voltage sent")
        if v.size != sent.size:
            msg = f"{rec}: {v.size} rows, but trial {learner.trials} sent {sent.size} commands"
            raise DataFileError(msg)
        off = np.abs(v - sent)
        worst = int(np.nanargmax(off)) if np.isfinite(off).any() else 0
        if not np.isfinite(off).all() or off[worst] > tolerance * (v_max - v_min):
            msg = (
                f"{rec}: row {worst + 1}'s voltage {v[worst]!r} is not the command written for "
                f"trial {learner.trials} ({sent[worst]!r}): a recording of another trial or run"
            )
            raise DataFileError(msg)
        y = _column(recording, reading_column, "reading")
        trial = learner.learn(displacement=y) if sensor else learner.learn(y)
    else:
        assert d is not None
    commands = learner.command(d)
    desired_now = learner.desired
    t = np.arange(commands.size) / rate
    write_table(out, {"time": t, "command": commands, "desired": desired_now})
    payload: dict[str, Any] = learner.to_dict()
    payload["sample_rate"] = rate
    learner.save_dict(state_path, payload)
    return LearnFileResult(learner, trial, commands)
