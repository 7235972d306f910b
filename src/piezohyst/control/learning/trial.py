"""One trial of learning from repetition: the trajectory it repeats, and its commands
against the actuator's limits (voltage and slew), for :mod:`.learning`.

Every command a trial sends is inside ``[v_min, v_max]`` and within the slew limit of the one
before; where a limit holds commands, the learner says how many and which option sets it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..._kernels import signal as S
from ..._validation import as_signal
from ...errors import ParameterError, ShapeError
from ..compensator import Compensator

FloatArray = np.ndarray

__all__ = [
    "CoupledTrial",
    "Trial",
    "anti_windup",
    "at_limits",
    "centred_slew",
    "check_periodic",
    "count_saturated",
    "held_by_limits",
    "limits_said",
    "periodic_fill",
    "ramp_in",
    "trajectory",
]


@dataclass(frozen=True)
class Trial:
    """What one trial measured and what the learner did with it.

    Attributes
    ----------
    index : int
        0 for the first trial.
    error : float
        RMS error over the desired span (fraction), of the quantity learned
        from: offset-free for the charge (the leakage leaves its zero unknown),
        absolute for a sensor.
    width : float
        Loop width of the measured against the desired (fraction of the span).
    learned : int
        Samples learned from (readings that were NaN, and samples whose command
        was slew-limited into the trajectory, are not).
    gain : float
        The learning gain of the update made after this trial.
    rolled_back : bool
        The error grew over the trial before (that update was undone), or crept above the
        best trial's since (their updates were undone); the gain halved.
    skipped : bool
        Nothing learned: the lead-in (the first trial, see ``lead_in``), or too
        few readings (under half the trial).
    leakage_bound : float
        The charge error one trial's leakage uncertainty can build (2 standard
        errors of the calibrated current, over the trial), as a fraction of the
        span; NaN when the leakage is not calibrated, 0 for a sensor.
    saturated : int
        Commands at a voltage limit or moved by the whole slew limit (beyond 2 %
        of the trial, a ``LearningWarning``: the trajectory is out of reach).
    steered : int
        Harmonics learned through the loop's response measured between trials, where the
        model's would grow the error (:mod:`~piezohyst.control.learning.harmonics`).
    """

    index: int
    error: float
    width: float
    learned: int
    gain: float
    rolled_back: bool
    skipped: bool
    leakage_bound: float
    saturated: int = 0
    steered: int = 0


def periodic_fill(values: FloatArray, ok: FloatArray) -> FloatArray:
    """Values at the samples not ``ok`` interpolated linearly from the others, around the period."""
    if ok.all():
        return values
    n = values.size
    k = np.flatnonzero(ok)
    xs = np.concatenate([k - n, k, k + n])
    ys = np.tile(values[k], 3)
    out = values.copy()
    bad = np.flatnonzero(~ok)
    out[bad] = np.interp(bad, xs, ys)
    return out


def check_periodic(d: FloatArray) -> None:
    steps = np.abs(np.diff(d))
    jump = abs(float(d[0] - d[-1]))
    largest = float(steps.max()) if steps.size else 0.0
    if jump > 2.0 * largest + 1e-12 * float(np.ptp(d)):
        msg = (
            f"the desired trajectory is not periodic over the trial: it jumps {jump:.4g} from "
            f"its last sample to its first, where its largest step is {largest:.4g}; a trial "
            "must end where the next begins (send whole periods)"
        )
        raise ParameterError(msg)


def at_limits(u: FloatArray, comp: Compensator) -> tuple[FloatArray, FloatArray]:
    """Commands at the top and at the bottom limit."""
    top = u >= comp.v_max - 1e-9 * max(1.0, abs(comp.v_max))
    bottom = u <= comp.v_min + 1e-9 * max(1.0, abs(comp.v_min))
    return top, bottom


def held_by_limits(u: FloatArray, comp: Compensator) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Commands at the top limit, at the bottom one, and moved by the whole slew limit."""
    top, bottom = at_limits(u, comp)
    slewed = np.zeros(u.size, dtype=bool)
    if math.isfinite(comp.max_step):
        slewed[1:] = np.abs(np.diff(u)) >= comp.max_step * (1 - 1e-6)
    return top, bottom, slewed


def count_saturated(u: FloatArray, comp: Compensator) -> int:
    """Commands at a voltage limit or moved by the whole slew limit."""
    top, bottom, slewed = held_by_limits(u, comp)
    return int(np.count_nonzero(top | bottom | slewed))


@dataclass(frozen=True)
class CoupledTrial:
    """What one trial of the stage measured, per output and per actuator.

    Attributes
    ----------
    index : int
        0 for the first trial.
    error : ndarray, shape (outputs,)
        RMS of the desired minus the measured position over the trial, as a fraction of
        what the stage reaches along that output (the same measure for a moving and a held
        axis); NaN readings left out.
    width : ndarray, shape (outputs,)
        Loop width of the measured against the desired position (fraction of the measured
        span, as :func:`~piezohyst.metrics.hysteresis_width`); NaN for an output whose
        desired position does not move.
    actuators : tuple of (Trial or None)
        Each actuator's learner's own record of the trial (in what that actuator alone
        moved); None for an actuator held by its feedforward compensator.
    saturated : ndarray of int, shape (actuators,)
        Commands of the trial at a voltage limit or moved by the whole slew limit.
    skipped : bool
        Nothing learned (every learner's lead-in).
    """

    index: int
    error: FloatArray
    width: FloatArray
    actuators: tuple[Trial | None, ...]
    saturated: FloatArray
    skipped: bool


def limits_said(index: int, u: FloatArray, comp: Compensator, other_law: bool = False) -> str:
    """The warning of a trial whose commands the limits held: how many each limit held, and
    the option that sets it (and, with ``other_law``, where the slew limit held commands,
    the Jacobian law: the harmonic law was asked for where that one could learn)."""
    top, bottom, slewed = held_by_limits(u, comp)
    parts = []
    if slewed.any():
        rate = f"{comp.max_step * comp.sample_rate:.4g} V/s" if comp.sample_rate else "its"
        parts.append(f"{np.count_nonzero(slewed)} moved by the whole slew limit ({rate}; "
                     "--slew-rate, slew_rate)")  # fmt: skip
    if top.any() or bottom.any():
        parts.append(f"{np.count_nonzero(top)} at v_max {comp.v_max:g} V and "
                     f"{np.count_nonzero(bottom)} at v_min {comp.v_min:g} V "
                     "(--v-max, --v-min)")  # fmt: skip
    held = int(np.count_nonzero(top | bottom | slewed))
    return (
        f"trial {index}: the limits held {held} of {u.size} commands ({'; '.join(parts)}): "
        "the trajectory asks for more than the actuator and amplifier give, and learning "
        "cannot remove the error that leaves"
        + (
            " (if the output runs on past its reversals, report's run-on row: law='jacobian', "
            "--law jacobian, learns without asking the amplifier for those steps)"
            if slewed.any() and other_law
            else ""
        )
    )


def centred_slew(u: FloatArray, step: float) -> FloatArray:
    """A trial's commands within the slew limit, a cut move spread evenly around its sample.

    The midpoint of the smallest sequence within the limit at or above the commands and the
    largest at or below (both over the periodic trial): within the limit (the mean of two
    sequences that are), inside the range the commands span, equal to them wherever they
    keep to the limit, and never further from them than any sequence within the limit can
    be (half the hulls' largest gap). A causal limiter starts every cut move late; a trial
    is known before it is sent, so half of the move can come before its sample.
    """
    n = u.size
    tiled = np.tile(u, 3)  # the trial runs after itself: its hulls are periodic
    upper, lower = np.empty_like(tiled), np.empty_like(tiled)
    S.slew_hull(tiled, step, True, upper)
    S.slew_hull(tiled, step, False, lower)
    return np.asarray(0.5 * (upper + lower)[n : 2 * n])


def anti_windup(e: FloatArray, u: FloatArray, comp: Compensator, sign: float) -> FloatArray:
    """No learning outward where a command sat at a limit (the error there is out of reach);
    ``sign``: -1 when the desired falls as the voltage rises (a negative gain)."""
    top, bottom = at_limits(u, comp)
    out = e.copy()
    out[top & (sign * e > 0)] = 0.0
    out[bottom & (sign * e < 0)] = 0.0
    return out


def ramp_in(u: FloatArray, last: float, step: float, d: FloatArray) -> FloatArray:
    """Bring ``u`` into the trajectory from the ``last`` command at the slew limit (in place);
    the samples whose history differs from the trajectory's (the ramp, and until its
    extremes wipe the actuator's memory out) as a mask."""
    clamped = np.zeros(u.size, dtype=bool)
    prev = last
    for k in range(u.size):
        if abs(u[k] - prev) <= step * (1 + 1e-12):
            break
        u[k] = prev + math.copysign(step, u[k] - prev)
        clamped[k] = True
        prev = float(u[k])
    if clamped.any():
        after = np.arange(d.size) > int(np.flatnonzero(clamped)[-1])
        near = 0.01 * float(np.ptp(d))  # within 1 % of an extreme: the memory is wiped
        hi = np.flatnonzero(after & (d >= d.max() - near))
        lo = np.flatnonzero(after & (d <= d.min() + near))
        wiped = max(int(hi[0]) if hi.size else d.size, int(lo[0]) if lo.size else d.size)
        clamped[: wiped + 1] = True
    return clamped


def trajectory(desired: ArrayLike) -> FloatArray:
    """``desired`` checked as one period of a trajectory to learn (a law's own limit on its
    length: :meth:`~.laws.Law.check_samples`)."""
    d = as_signal(desired, "desired")
    if d.size < 8:
        msg = f"'desired' must hold at least 8 samples (one trial). Got {d.size}."
        raise ShapeError(msg)
    if not np.ptp(d) > 0:
        msg = "'desired' must move: a constant trajectory has nothing to learn."
        raise ParameterError(msg)
    check_periodic(d)
    return d
