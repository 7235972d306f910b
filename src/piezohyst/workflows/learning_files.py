"""Learning across trial files: what ``piezohyst learn`` does, for labs that run their own DAQ.

Each call reads what the DAQ recorded over the trial last written, learns from it, and
writes the next trial's commands; the learner's state lives in a JSON file between calls
(written atomically, and bound to its model, settings and trajectory).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..control.compensator import CompensatorSettings
from ..control.learning import LearningCompensator, Trial
from ..errors import DataFileError, ModelFileError, ParameterError
from ..io import read_table, write_table
from ..io.screening import NOISE_REACH, noise_level
from ..model.calibrations.leakage import Leakage
from ..model.persistence import load_model
from ._base import (
    ONE_RATE,
    check_rate,
    command_gain,
    desired_unit,
    guard_outputs,
    standard_column,
)

__all__ = ["LearnFileResult", "learn_file", "recording_check"]


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
    voltage_scale: str | float | None = None,
    reading_scale: str | float | None = None,
    sensor: bool = False,
    tolerance: float = 1e-4,
    lead_in: bool = True,
    probe: bool = True,
    noise_gate: float = 0.0,
    law: Literal["auto", "harmonic", "jacobian"] = "auto",
    measure_lag: bool = True,
    voltage_tolerance: float | None = None,
    force: bool = False,
    command_scale: str | float | None = None,
) -> LearnFileResult:
    """One trial of learning through files.

    The first call (no state file yet) takes the desired trajectory and writes
    the first trial's commands. Every later call takes the file the DAQ recorded
    over the trial just sent: its voltage column must be the commands written,
    or the voltage the DAQ measured while sending them (:func:`recording_check`:
    the commands plus white noise; two runs are never mixed), its
    ``reading_column`` the charge (or,
    with ``sensor``, a displacement in m).
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
        A leakage file (:func:`~piezohyst.calibrate_leakage`); default the model's.
    lag, learning_gain, cutoff, lead_in, probe, noise_gate, law, measure_lag
        See :class:`~piezohyst.LearningCompensator`.
    voltage_scale, reading_scale : str or float, optional
        What one unit of the recording's voltage or reading column is worth, for channels
        a DAQ logs in volts (a 1/100 monitor: ``100``; a Sawyer-Tower's ``"4.7 uF"``; a
        sensor's ``"10 um/V"``; :func:`piezohyst.units.scaled`).
    voltage_tolerance : float, optional
        How far (V) the recorded voltage may stray from the commands; default from
        its noise (:func:`recording_check`, what it found kept in the state file).
    force : bool, default False
        Replace an ``out`` that piezohyst did not write.
    command_scale : str or float, optional
        The amplifier's gain (piezo V per V the DAQ plays): the commands are written divided
        by it (the recording's voltage column stays the piezo's, through ``voltage_scale``).
        Kept in the state: every call of a run must give the same.

    Returns
    -------
    LearnFileResult
    """
    written = command_gain(command_scale)
    settings = settings or CompensatorSettings()
    state_path, out = Path(state_path), Path(out)
    inputs = [p for p in (model_path, recorded, desired, leakage, state_path) if p is not None]
    guard_outputs([out], inputs, force=force)
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
        d = standard_column(table, column, "desired trajectory", "output",
                            desired_unit(settings, model))  # fmt: skip
        if rate is None or "time" in table:
            t = standard_column(table, "time", "time (or give --sample-rate)", "time", "s")
            timed = float(f"{(t.size - 1) / (t[-1] - t[0]):.12g}")  # 1000.0, not 999.9999999999
            if rate is not None:
                check_rate(
                    desired, timed, rate, f", and the sample rate given is {rate:g} Hz: {ONE_RATE}"
                )
            rate = timed
    else:
        if desired is not None:
            msg = f"{state_path} already holds a trajectory: --desired starts a run (new file)"
            raise ParameterError(msg)
        try:
            saved = json.loads(state_path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            msg = f"{state_path}: cannot read the learning state ({exc})"
            raise ModelFileError(msg) from None
        kept = saved.get("command_scale", 1.0) if isinstance(saved, dict) else 1.0
        if not isinstance(kept, (int, float)) or isinstance(kept, bool):
            msg = f"{state_path}: a damaged learning state (command_scale {kept!r})"
            raise ModelFileError(msg)
        if kept != written:  # commands 14 times the intended would reach the amplifier
            msg = (f"{state_path}: this run writes its commands divided by --command-scale "
                   f"{kept:g} (the amplifier's gain); this call gives {written:g}: give the "
                   "same on every call of a run")  # fmt: skip
            raise ParameterError(msg)
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
        output_map=settings.output_map,
        lag=lag,
        learning_gain=learning_gain,
        cutoff=cutoff,
        lead_in=lead_in,
        probe=probe,
        noise_gate=noise_gate,
        law=law,
        measure_lag=measure_lag,
    )
    trial = None
    check: dict[str, float] = {}
    if not first:
        _restore(learner, saved, state_path)
        if recorded is None:
            msg = f"{state_path} waits for trial {learner.trials}'s recording (RECORDED)"
            raise ParameterError(msg)
        rec = Path(recorded)
        sent = learner.pending
        assert sent is not None
        recording = read_table(rec)
        v = standard_column(recording, voltage_column, "voltage sent", "input", "V",
                            ("voltage scale", voltage_scale))  # fmt: skip
        if v.size != sent.size:
            msg = f"{rec}: {v.size} rows, but trial {learner.trials} sent {sent.size} commands"
            raise DataFileError(msg)
        check = recording_check(v, sent, tolerance * (v_max - v_min), voltage_tolerance)
        if check["worst_row"] >= 0:
            row = int(check["worst_row"])
            msg = (
                f"{rec}: row {row}'s voltage {v[row - 1]:.6g} V is not the command written for "
                f"trial {learner.trials} ({sent[row - 1]:.6g} V; off by {check['off_V']:.3g} V, "
                f"allowed {check['allowed_V']:.3g} V, the difference not white noise: lag-1 "
                f"autocorrelation {check['lag1']:.2f}): a recording of another trial or run "
                "(--voltage-tolerance sets what is allowed)"
            )
            raise DataFileError(msg)
        y = standard_column(recording, reading_column, "reading", "output",
                            "m" if sensor else model.output_unit,
                            ("reading scale", reading_scale))  # fmt: skip
        trial = learner.learn(displacement=y) if sensor else learner.learn(y)
    else:
        assert d is not None
    commands = learner.command(d)
    desired_now = learner.desired
    t = np.arange(commands.size) / rate
    in_metres = settings.domain == "displacement" or settings.output_map is not None
    write_table(out, {"time": t, "command": commands / written, "desired": desired_now},
                units={"time": "s", "command": "V",
                       "desired": "m" if in_metres else model.output_unit})  # fmt: skip
    payload: dict[str, Any] = learner.to_dict()
    payload["sample_rate"] = rate
    if written != 1.0:  # only when set: the states saved before it existed resume
        payload["command_scale"] = written
    payload["run"] = _run_settings(learner)  # readable: what a later call must give again
    if check:  # how the last recording's voltage was matched to the commands, for the record
        payload["recording_check"] = check
    learner.save_dict(state_path, payload)
    return LearnFileResult(learner, trial, commands)


#: The command line's option for each of a run's settings (``learn``)
RUN_OPTIONS = {
    "model": "MODEL", "leakage": "--leakage", "output_map": "--gain FILE", "gain": "--gain",
    "domain": "--domain", "v_min": "--v-min", "v_max": "--v-max", "slew_rate": "--slew-rate",
    "allow_extrapolation": "--allow-extrapolation", "lag": "--lag",
    "learning_gain": "--learning-gain", "cutoff": "--cutoff", "lead_in": "--no-lead-in",
    "probe": "--no-probe", "noise_gate": "--noise-gate", "law": "--law",
    "measure_lag": "--no-lag-measurement",
}  # fmt: skip


#: What a run's first call gave for the options added since runs were first saved
RUN_DEFAULTS = {"noise_gate": 0.0, "law": "harmonic", "measure_lag": True}


def _run_settings(learner: LearningCompensator) -> dict[str, Any]:
    """A run's settings as the command line gives them (files by a digest of their contents)."""

    def digest(data: Any) -> str:
        return hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()[
            :12
        ]

    out = {k: v for k, v in learner.settings.items() if k in RUN_OPTIONS}
    out["noise_gate"] = learner.settings.get("noise_gate", RUN_DEFAULTS["noise_gate"])
    out["law"] = learner.settings.get("law", RUN_DEFAULTS["law"])
    out["measure_lag"] = learner.settings.get("measure_lag", RUN_DEFAULTS["measure_lag"])
    out["model"] = digest(learner.model.to_dict())
    out["leakage"] = digest(learner.leakage.to_dict())
    out["output_map"] = None if learner.output_map is None else digest(learner.output_map.to_dict())
    return out


def _restore(learner: LearningCompensator, saved: Any, state_path: Path) -> None:
    """Continue the run in ``saved``; where this call's settings are not its first call's,
    say which options differ (the state's digest alone could not)."""
    try:
        learner.restore(saved, str(state_path))
    except ModelFileError:
        was = saved.get("run") if isinstance(saved, dict) else None
        if not isinstance(was, dict):
            raise
        now = _run_settings(learner)
        was = {**RUN_DEFAULTS, **was}  # a run begun before these options existed had them so
        diff = [
            _differs(k, was.get(k), now.get(k)) for k in RUN_OPTIONS if was.get(k) != now.get(k)
        ]
        if not diff:
            raise
        msg = (
            f"{state_path}: this call's settings are not the run's: {'; '.join(diff)}; give "
            "every call of a run the options of its first"
        )
        raise ModelFileError(msg) from None


def _differs(key: str, was: Any, now: Any) -> str:
    """One setting a call gave otherwise than its run's first call, as the option's name."""
    option = RUN_OPTIONS[key]
    if key not in ("model", "leakage", "output_map"):
        return f"{option} {now!r}, where the first call gave {was!r}"
    if now is None:
        return f"{option} not given, where the first call gave one"
    if was is None:
        return f"{option} given, where the first call gave none"
    return f"{option}: another file than the first call's"


def recording_check(
    voltage: np.ndarray, sent: np.ndarray, floor: float, allowed: float | None = None
) -> dict[str, float]:
    """Whether a trial's recorded voltage is the commands sent, or those commands measured
    with noise.

    A DAQ logs the command written, or the voltage it measured: the commands plus
    white noise. The recording is the trial's own when every row is within
    ``floor`` (V) of its command, or when the difference is white noise: its lag-1
    autocorrelation within 4/sqrt(N) of 0 (four standard errors) and every row
    within 10x its noise level (:func:`~piezohyst.io.screening.noise_level`; the
    Gaussian range over 10^4-10^5 samples). Another trial's commands differ by
    what was learned, which follows the trajectory from sample to sample (lag-1
    autocorrelation 0.4-0.9 between the trials of a 5 Hz scan), so its recording
    is refused. ``allowed`` (V) replaces the rule: every row within it.

    Parameters
    ----------
    voltage, sent : ndarray
        The recorded voltage and the commands written (V), row for row.
    floor : float
        A difference (V) any recording may show (the DAQ's rounding).
    allowed : float, optional
        The allowed difference (V), overriding the rule.

    Returns
    -------
    dict
        ``noise_V``, ``lag1`` (the difference's lag-1 autocorrelation), ``allowed_V``,
        ``off_V`` (the largest difference) and ``worst_row`` (the 1-based row of the
        largest difference when the recording is refused, else -1).
    """
    diff = voltage - sent
    if not np.isfinite(diff).all():
        row = int(np.argmax(~np.isfinite(diff)))
        return {"noise_V": math.nan, "lag1": math.nan, "allowed_V": math.nan,
                "off_V": math.inf, "worst_row": float(row + 1)}  # fmt: skip
    off = np.abs(diff)
    worst = int(np.argmax(off)) if off.size else 0
    largest = float(off[worst]) if off.size else 0.0
    noise = noise_level(diff)
    lag1 = math.nan
    if diff.size > 2 and float(np.std(diff)) > 0.0:
        lag1 = float(np.corrcoef(diff[1:], diff[:-1])[0, 1])
    if allowed is not None:
        limit = float(allowed)
        ok = largest <= limit
    else:
        white = math.isfinite(lag1) and abs(lag1) <= 4.0 / math.sqrt(diff.size)
        limit = max(floor, NOISE_REACH * noise) if white else floor
        ok = largest <= limit
    return {"noise_V": noise, "lag1": lag1, "allowed_V": limit, "off_V": largest,
            "worst_row": -1.0 if ok else float(worst + 1)}  # fmt: skip
